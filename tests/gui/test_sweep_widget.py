"""The "Parameter sweep" widget in a real napari viewer (run under Xvfb)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _gui_helpers import click, engine_result, error_messages, run_and_wait, wait_idle

from napari_polarseg.engine import SegmentParams, validity_mask
from napari_polarseg.engine.analysis.evaluation import adjusted_rand_index
from napari_polarseg.engine.analysis.param_sweep import ParamSweepResult, param_sweep, sweepable
from napari_polarseg.engine.analysis.sweep import sweep
from napari_polarseg.engine.params import AUTO, RECOMMENDED
from napari_polarseg.widgets.segment import SegmentWidget
from napari_polarseg.widgets.sweep import SweepWidget


def shown(control) -> bool:
    """The control is in the dock's layout (not hidden; whether or not the dock is on
    screen)."""
    return not control.native.isHidden()


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


def test_sweep_widget_sweeps_the_parameters_of_a_method_without_blocks(
    viewer, open_sample, add_widget, qtbot
):
    """Preset auto (a method that does not cut blocks): the dock offers the method's
    declared parameters instead of w, L and n, and its cells are param_sweep's."""
    stack = open_sample("fruit")
    widget = add_widget("Parameter sweep")
    # the thesis grid for the default source (recommended)
    assert shown(widget.windows) and shown(widget.degrees)
    assert widget.method_axes.edits == {}
    widget.source.value = "auto"
    assert not shown(widget.windows) and not shown(widget.degrees)
    edits = widget.method_axes.edits
    assert set(edits) == set(sweepable(AUTO)) and {"object_size", "n_segments"} <= set(edits)
    click(qtbot, widget.run_button)  # nothing typed: told what to type, nothing runs
    assert "type the values of at least one parameter" in widget.status.value
    assert widget.result is None and not widget.busy
    told = len(error_messages())
    edits["object_size"].value = "16, 32"
    run_and_wait(qtbot, widget)
    assert error_messages()[told:] == []
    result = widget.result
    assert isinstance(result, ParamSweepResult) and result.base.method == AUTO.method
    assert [c.values for c in result.cells] == [{"object_size": 16.0}, {"object_size": 32.0}]
    assert all(c.ok and c.n_segments == AUTO.n_segments for c in result.cells)
    # the labels of each cell are the engine's: the stability is the ARI of the two
    angles = np.deg2rad(stack.metadata["angles_deg"])
    data = np.asarray(stack.data)
    a, b = (engine_result(stack, AUTO.replace(object_size=s)).labels for s in (16, 32))
    assert result.cells[0].stability == pytest.approx(adjusted_rand_index(a, b))
    ref = param_sweep(data, angles, AUTO, {"object_size": [16, 32]}, mask=validity_mask(data))
    assert [c.n_segments for c in ref.cells] == [c.n_segments for c in result.cells]

    table = widget.table.to_dict("list")
    assert table["object_size"] == [16.0, 32.0] and table["best"].count("★") == 1
    assert "w" not in table
    assert "best by stability: object_size = " in widget.status.value
    best = widget.best_params()  # what Use best and Save best… hand on
    assert best == AUTO.replace(object_size=result.best_cell().values["object_size"])
    assert "per cell" in widget.figure.axes[0].get_title()  # one bar per cell
    assert len(widget.figure.axes[0].patches) == 2
    # a score of the block grid is refused for such a sweep
    widget.score.value = "silhouette"
    click(qtbot, widget.run_button)
    assert "picks its best cell by stability or ari" in widget.status.value
    # back to the thesis method: its grid again, the method's fields gone
    widget.source.value = "thesis"
    assert shown(widget.windows) and widget.method_axes.edits == {}
