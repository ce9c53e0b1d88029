"""The "Parameter sweep" widget in a real napari viewer (run under Xvfb)."""

from __future__ import annotations

import json

import numpy as np
from _gui_helpers import click, error_messages, run_and_wait, wait_idle

from napari_polarseg.engine import SegmentParams
from napari_polarseg.engine.analysis.sweep import sweep
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.widgets.segment import SegmentWidget
from napari_polarseg.widgets.sweep import SweepWidget


def _truth_layer(viewer):
    return viewer.layers["leaves ground truth"]


def test_sweep_widget_runs_draws_and_uses_the_best_cell(
    viewer, open_sample, add_widget, qtbot, tmp_path
):
    stack = open_sample("leaves")
    widget = add_widget("Parameter sweep")
    assert isinstance(widget, SweepWidget)
    assert widget.stack_layer.value is stack
    assert widget.angles.value  # from the layer's metadata
    truth = _truth_layer(viewer)
    assert truth in widget.ground_truth.choices
    widget.windows.value = "8, 12"
    widget.degrees.value = "4,8"
    widget.ground_truth.value = truth
    widget.score.value = "ari"
    assert not widget.use_button.enabled
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    result = widget.result
    assert result is not None and len(result.cells) == 4
    assert "best by ari" in widget.status.value

    # the same numbers as the engine on the same stack
    angles = np.deg2rad(stack.metadata["angles_deg"])
    ref = sweep(
        np.asarray(stack.data), angles, RECOMMENDED, [8, 12], [4, 8], ground_truth=truth.data
    )
    np.testing.assert_allclose(result.grid("ari"), ref.grid("ari"))
    np.testing.assert_allclose(result.grid("stability"), ref.grid("stability"))
    assert result.best("ari") == ref.best("ari")

    table = widget.table.to_dict("list")
    assert table["w"] == [8, 8, 12, 12] and table["L"] == [4, 8, 4, 8]
    assert table["best"].count("★") == 1
    best_row = table["best"].index("★")
    assert (table["w"][best_row], table["L"][best_row]) == (
        result.best().window,
        result.best().degree,
    )

    # heatmaps: one panel per n (one here) plus its colour bar; the metric menu redraws
    assert len(widget.figure.axes) == 2
    widget.metric.value = "ari"
    assert "ARI" in widget.figure.axes[0].get_title()
    widget.metric.value = "silhouette"
    assert "silhouette" in widget.figure.axes[0].get_title()

    # Save best…: SegmentParams JSON, as polarseg segment --params reads it
    path = widget.save_best(tmp_path / "best_params.json")
    assert SegmentParams.from_json(path.read_text()) == result.best()
    assert json.loads(path.read_text())["method_params"]["thesis"]["window"] == result.best().window

    # Use best: docks the Segment widget, sets it and runs it
    assert not any(isinstance(w, SegmentWidget) for w in viewer.window.dock_widgets.values())
    click(qtbot, widget.use_button)
    seg = widget.segment_widget()
    assert isinstance(seg, SegmentWidget)
    wait_idle(qtbot, seg)
    assert error_messages() == []
    assert seg.params() == result.best()
    segments = seg.output("segments", stack)
    assert segments is not None
    thesis = segments.metadata["polarseg_params"]["method_params"]["thesis"]
    assert thesis["window"] == result.best().window
    # a second click reuses the docked widget
    n_docks = len(viewer.window.dock_widgets)
    click(qtbot, widget.use_button)
    wait_idle(qtbot, seg)
    assert len(viewer.window.dock_widgets) == n_docks


def test_sweep_widget_cancel_and_errors(viewer, open_sample, add_widget, qtbot):
    open_sample("leaves")
    widget = add_widget("Parameter sweep")
    widget.windows.value = "a, b"
    click(qtbot, widget.run_button)
    assert not widget.busy
    assert any("window sizes must be whole numbers" in m for m in error_messages())
    widget.windows.value = "0"
    click(qtbot, widget.run_button)
    assert "window must be a positive integer" in widget.status.value
    widget.windows.value = "8"
    widget.score.value = "ari"  # no ground truth chosen
    click(qtbot, widget.run_button)
    assert "needs a ground-truth" in widget.status.value
    assert widget.result is None and not widget.busy

    # a long grid, cancelled at once: stops after the running cell, no result
    widget.score.value = "stability"
    widget.windows.value = "4,5,6,7,8,9,10,11,12"
    widget.degrees.value = "4,8,12,16"
    click(qtbot, widget.run_button)
    assert widget.busy
    click(qtbot, widget.cancel_button)
    wait_idle(qtbot, widget)
    assert widget.status.value == "cancelled"
    assert widget.result is None

    # a window too large for the image is a failed cell, not an error
    widget.windows.value = "8,500"
    widget.degrees.value = "4"
    run_and_wait(qtbot, widget)
    assert widget.result is not None
    table = widget.table.to_dict("list")
    assert "larger than the image" in table["error"][1]
    assert "1 failed" in widget.status.value
