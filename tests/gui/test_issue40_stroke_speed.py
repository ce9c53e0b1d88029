"""Issue 40, point 12: a painted stroke retrains at once (no control debounce), a
control's change still waits for the debounce, and moving the progress bar repaints
nothing at once (a synchronous repaint composes the whole software-rendered window)."""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import wait_idle

from napari_polarseg.engine.synthetic.scenes import scribble_strokes
from napari_polarseg.widgets.segment import LIVE_DELAY_MS, STROKE_DELAY_MS

pytestmark = pytest.mark.gui

#: Fast parameters (the synthetic samples are 120 x 130 pixels).
FAST = {"window": 10, "degree": 4, "n_segments": 3}


def test_a_stroke_reruns_without_the_debounce(viewer, open_sample, add_widget, qtbot):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    strokes = scribble_strokes(truth - 1, seed=0)
    scribbles = widget.new_scribbles_layer()
    widget.live.value = True
    scribbles.data = np.where(strokes <= 2, strokes, 0).astype(np.int32)
    wait_idle(qtbot, widget)
    runs = widget._slot.run_id

    # a brush stroke (napari's paint event, as at a mouse release): the rerun is due in
    # the next event-loop turn
    rows, cols = np.nonzero(strokes == 1)
    scribbles.brush_size = 3
    scribbles.paint((int(rows[0]), int(cols[0])), 2)
    assert STROKE_DELAY_MS < LIVE_DELAY_MS
    assert widget._timer.isActive() and widget._timer.interval() == STROKE_DELAY_MS
    qtbot.waitUntil(lambda: widget._slot.run_id > runs, timeout=LIVE_DELAY_MS // 2)
    wait_idle(qtbot, widget)

    # a control's change keeps the debounce (a slider dragged runs once)
    widget.set_params(n_segments=4)
    assert widget._timer.isActive() and widget._timer.interval() == LIVE_DELAY_MS
    wait_idle(qtbot, widget)


def test_the_progress_bar_repaints_with_the_window(viewer, open_sample, add_widget, qtbot):
    from qtpy.QtCore import QEvent, QObject

    open_sample("leaves")
    widget = add_widget("Segment by material")
    viewer.window._qt_window.show()  # napari's private main window: painted for real
    bar = widget.progress.native
    qtbot.waitUntil(bar.isVisible, timeout=2000)
    qtbot.wait(100)
    painted: list[float] = []

    class Paints(QObject):
        def eventFilter(self, obj: QObject, event: QEvent) -> bool:  # noqa: N802
            if event.type() == QEvent.Type.Paint:
                painted.append(1.0)
            return False

    paints = Paints()
    bar.installEventFilter(paints)
    widget._set_progress(1, 4)
    assert painted == []  # nothing painted synchronously
    assert bar.updatesEnabled() and widget.progress.value == 100
    qtbot.waitUntil(lambda: bool(painted), timeout=2000)  # painted with the next repaint
    bar.removeEventFilter(paints)
