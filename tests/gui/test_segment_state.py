"""The Segment dock's one state (issue 38, point 5): a closed dock stops listening to the
viewer, and a cancelled run leaves every shown layer from one parameter set."""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import click, engine_result, error_messages, run_and_wait, wait_idle

from napari_polarseg.engine.synthetic.scenes import scribble_strokes
from napari_polarseg.widgets.segment import LIVE_DELAY_MS

pytestmark = pytest.mark.gui

#: Fast parameters (the synthetic samples are 120 x 130 pixels).
FAST = {"window": 10, "degree": 4, "n_segments": 3}


def _window(layer) -> int:
    """The thesis window recorded in an output layer's parameters."""
    return layer.metadata["polarseg_params"]["method_params"]["thesis"]["window"]


def _live_scribbles(viewer, widget, qtbot):
    """A scribbles layer with strokes of the three materials, trained on live."""
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    strokes = scribble_strokes(truth - 1, seed=0)
    scribbles = widget.new_scribbles_layer()
    widget.live.value = True
    scribbles.data = np.where(strokes <= 2, strokes, 0).astype(np.int32)
    wait_idle(qtbot, widget)
    assert error_messages() == []
    assert widget.output("segments") is not None and widget.classes.tolist() == [1, 2]
    return scribbles, strokes


@pytest.mark.parametrize("how", ["x", "close"])
def test_a_closed_dock_no_longer_retrains_on_strokes(viewer, open_sample, add_widget, qtbot, how):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    scribbles, strokes = _live_scribbles(viewer, widget, qtbot)
    runs, layers = widget._slot.run_id, [layer.name for layer in viewer.layers]
    segments = widget.output("segments")
    shown = segments.data.copy()

    if how == "x":  # the ✕ of napari's dock title bar
        widget.native.parent().destroyOnClose()
    else:
        widget.close()
    qtbot.wait(10)
    assert widget.closed and widget.state.is_closed
    if how == "x":
        assert widget not in viewer.window.dock_widgets.values()
    assert widget.materials.layer is None  # the material list let go of the layer too

    # more strokes: new data (the data event) and a brush stroke (the paint event)
    scribbles.data = strokes
    scribbles.events.set_data()
    rows, cols = np.nonzero(strokes == 1)
    scribbles.brush_size = 3
    scribbles.paint((int(rows[0]), int(cols[0])), 2)
    qtbot.wait(LIVE_DELAY_MS * 4)
    assert not widget._timer.isActive() and not widget.busy
    assert widget._slot.run_id == runs  # no classifier job ran
    assert [layer.name for layer in viewer.layers] == layers  # no new layer
    np.testing.assert_array_equal(segments.data, shown)
    # nor does it follow the layer list any more
    viewer.add_labels(np.zeros(scribbles.data.shape, np.int32), name="after closing")
    qtbot.wait(50)
    assert "after closing" not in [c for c in widget.mask_layer.choices if c is not None]
    assert widget._slot.run_id == runs


def test_a_cancelled_run_leaves_the_layers_of_one_parameter_set(
    viewer, open_sample, add_widget, qtbot, gate
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")  # thesis: the error map always
    widget.set_params(**{**FAST, "window": 12})
    run_and_wait(qtbot, widget)
    segments, error = widget.output("segments"), widget.output("error")
    want = engine_result(stack, widget.params())
    np.testing.assert_array_equal(segments.data, want.labels + 1)
    error_12 = error.data.copy()
    assert _window(segments) == 12 and _window(error) == 12

    # w = 10: its segments are shown before the error map, which Cancel stops
    widget.window.value = 10
    other = engine_result(stack, widget.params()).labels + 1
    assert not np.array_equal(other, want.labels + 1)  # the two sets differ on screen
    gate = gate("reconstruct_intensity")
    gate.arm()
    click(qtbot, widget.run_button)
    qtbot.waitUntil(gate.entered.is_set, timeout=60_000)
    qtbot.waitUntil(lambda: _window(segments) == 10, timeout=10_000)
    np.testing.assert_array_equal(segments.data, other)
    click(qtbot, widget.cancel_button)
    gate.release.set()
    wait_idle(qtbot, widget)

    assert widget.status.value == "cancelled" and error_messages() == []
    assert widget.output("segments") is segments and widget.output("error") is error
    # both from w = 12: the segments came back, the error map stayed
    np.testing.assert_array_equal(segments.data, want.labels + 1)
    np.testing.assert_array_equal(error.data, error_12)
    assert _window(segments) == 12 and _window(error) == 12
    assert widget.shown_result(stack).params.params_of("thesis").window == 12

    # the next run of w = 10 completes: both from w = 10
    gate.release.set()
    run_and_wait(qtbot, widget)
    np.testing.assert_array_equal(segments.data, other)
    assert _window(segments) == 10 and _window(widget.output("error")) == 10
