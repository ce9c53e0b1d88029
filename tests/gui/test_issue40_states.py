"""Issue 40, point 11: odd states of the Segment dock.

- ticking *live update* before any Run arms the live update and runs nothing;
- *New scribbles layer* clicked while a run computes ends with that run's result and
  the pixel features computed, not on "result dropped";
- the angle label beside the slider keeps the frame's angle after a live rerun.
"""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import click, error_messages, wait_idle

from napari_polarseg.widgets.segment import LIVE_DELAY_MS

pytestmark = pytest.mark.gui

#: Fast parameters (the synthetic samples are 120 x 130 pixels).
FAST = {"window": 10, "degree": 4, "n_segments": 3}


def test_ticking_live_update_before_a_run_runs_nothing(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    runs = widget._slot.run_id
    widget.live.value = True
    qtbot.wait(LIVE_DELAY_MS * 4)
    wait_idle(qtbot, widget)
    assert widget._slot.run_id == runs  # no run the user did not ask for
    assert widget.output("segments", stack) is None
    assert "live update" in widget.status.value and "Run" in widget.status.value
    # armed: a change of value now reruns
    widget.controls.controls["n_segments"].value = 2
    qtbot.waitUntil(lambda: widget._slot.run_id > runs, timeout=10_000)
    wait_idle(qtbot, widget)
    assert widget.output("segments", stack) is not None
    assert error_messages() == []


def test_new_scribbles_during_a_run_ends_with_its_result_and_the_features(
    viewer, open_sample, add_widget, qtbot, gate
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    widget.live.value = True
    blocked = gate("block_coefficients")
    blocked.arm()
    click(qtbot, widget.run_button)
    qtbot.waitUntil(blocked.entered.is_set, timeout=60_000)
    click(qtbot, widget.new_scribbles_button)  # while the run computes
    qtbot.wait(LIVE_DELAY_MS * 3)  # the live update sees the new (empty) scribbles
    blocked.release.set()
    wait_idle(qtbot, widget)
    qtbot.waitUntil(lambda: "pixel features ready" in widget.status.value, timeout=60_000)
    wait_idle(qtbot, widget)
    assert "dropped" not in widget.status.value
    segments = widget.output("segments", stack)
    assert segments is not None and len(np.unique(segments.data)) == 3
    assert widget.shown_result(stack) is not None
    key = str(stack.unique_id)
    assert widget.store.session(key).cached_features is not None
    assert error_messages() == []


def test_the_angle_label_keeps_its_angle_after_a_live_rerun(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    angles = stack.metadata["angles_deg"]
    viewer.dims.set_current_step(0, 1)
    label = f"angle {angles[1]:g}°"
    assert viewer.dims.axis_labels[0] == label
    widget.live.value = True
    click(qtbot, widget.run_button)
    wait_idle(qtbot, widget)
    assert viewer.dims.axis_labels[0] == label
    runs, shown = widget._slot.run_id, widget.output("segments").data
    widget.controls.controls["n_segments"].value = 2  # a live rerun
    qtbot.waitUntil(lambda: widget._slot.run_id > runs, timeout=5_000)
    wait_idle(qtbot, widget)
    assert not np.array_equal(widget.output("segments").data, shown)  # new data shown
    qtbot.wait(50)
    assert viewer.dims.axis_labels[0] == label
    slider = viewer.window._qt_viewer.dims.slider_widgets[0]
    assert slider.axis_label.text() == label
