"""Issue 40, point 14: what the Segment dock and its layers look like.

Hovering the segments names the material; the material menu shows whole names; a
segment that survives a change of the number of segments keeps its colour; the docks'
tabs read distinct short titles; *advanced settings* keeps the dock's width bounded; the
status line uses the dock's width, left-aligned.
"""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import PLUGIN_DOCKS as DOCKS
from _gui_helpers import engine_result, error_messages, run_and_wait, wait_idle
from qtpy.QtWidgets import QApplication, QTabBar

from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.synthetic.scenes import scribble_strokes
from napari_polarseg.widgets._base import _dock_of
from napari_polarseg.widgets.dock_layout import MAX_DOCK_WIDTH

pytestmark = pytest.mark.gui


def _show(viewer, qtbot) -> None:
    window = viewer.window._qt_window
    window.resize(1600, 1000)
    window.show()
    qtbot.wait(50)


def _settle(qtbot) -> None:
    for _ in range(5):
        QApplication.processEvents()
        qtbot.wait(20)


def test_hover_names_the_material_and_the_menu_shows_whole_names(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    _show(viewer, qtbot)
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    scribbles = widget.new_scribbles_layer()
    scribbles.data = scribble_strokes(truth - 1, seed=0).astype(np.int32)
    widget.materials.rename(1, "leaf")
    widget.materials.rename(3, "banana split")
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    segments = widget.output("segments", stack)
    rows, cols = np.nonzero(segments.data == 3)
    status = segments.get_status((rows[0], cols[0]))["value"]
    assert status.startswith("3") and "material: banana split" in status
    rows, cols = np.nonzero(segments.data == 2)
    assert "material: material 2" in segments.get_status((rows[0], cols[0]))["value"]
    widget.materials.rename(2, "plastic")  # a rename after the run: hover follows
    assert "material: plastic" in segments.get_status((rows[0], cols[0]))["value"]

    # the material menu shows "3: banana split" whole, not "3: banan"
    widget.materials.material.value = 3
    _settle(qtbot)
    combo = widget.materials.material.native
    text = combo.currentText()
    assert text == "3: banana split"
    assert combo.width() >= combo.fontMetrics().horizontalAdvance(text) + 20

    # an unsupervised run afterwards: no material names on hover
    widget.scribbles_layer.value = None
    widget.set_params(window=10, degree=4, n_segments=3)
    run_and_wait(qtbot, widget)
    assert "material" not in segments.get_status((rows[0], cols[0]))["value"]


def test_a_surviving_segment_keeps_its_colour_when_k_changes(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)  # auto: superpixels
    widget.n_segments.value = 3
    run_and_wait(qtbot, widget)
    segments = widget.output("segments", stack)
    before = segments.data.copy()
    # the method numbers anew: segment 2 of k = 3 comes back as another number at k = 4
    fresh = engine_result(stack, PRESETS["auto"].replace(n_segments=4)).labels + 1
    moved = [v for v in (1, 2, 3) if np.bincount(fresh[before == v]).argmax() != v]
    assert moved  # without the dock's renumbering these would change colour

    widget.n_segments.value = 4
    run_and_wait(qtbot, widget)
    after = segments.data
    assert len(np.unique(after)) == 4
    kept = []
    for v in (1, 2, 3):  # an old segment's main new part, when it lies mostly in it
        inside = after[before == v]
        main = int(np.bincount(inside).argmax())
        if 2 * np.count_nonzero(inside == main) > np.count_nonzero(after == main):
            assert main == v, (v, main)  # keeps its number, hence its colour
            kept.append(v)
    assert set(kept) & set(moved)  # one the method had renumbered
    # the result behind them (plots, export) is numbered as shown
    np.testing.assert_array_equal(widget.shown_result(stack).labels + 1, after)
    assert sorted(np.unique(after)) == [1, 2, 3, 4]


def test_dock_tabs_read_distinct_short_titles(viewer, open_sample, add_widget, qtbot):
    open_sample("leaves")
    widgets = [add_widget(name) for name in DOCKS]
    _show(viewer, qtbot)
    _settle(qtbot)
    window = viewer.window._qt_window
    titles = [_dock_of(w.native).windowTitle() for w in widgets]
    assert titles == ["Segment", "Polarisation", "Plots", "Sweep", "Batch", "Time series"]
    bars = [b for b in window.findChildren(QTabBar) if b.count() == len(DOCKS)]
    assert bars, "the docks are not tabbed together"
    bar = bars[0]
    shown = [bar.tabText(i) for i in range(bar.count())]
    assert sorted(shown) == sorted(titles)
    for i in range(bar.count()):  # whole, not "Polari…"
        assert bar.tabRect(i).width() >= bar.fontMetrics().horizontalAdvance(bar.tabText(i))


def test_advanced_settings_keep_the_dock_narrow_and_the_status_wide(
    viewer, open_sample, add_widget, qtbot
):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    _show(viewer, qtbot)
    _settle(qtbot)
    dock = _dock_of(widget.native)
    narrow = dock.width()
    widget.show_advanced.value = True
    _settle(qtbot)
    assert dock.width() <= MAX_DOCK_WIDTH + 20  # it was 756 px
    widget.show_advanced.value = False
    _settle(qtbot)
    assert dock.minimumWidth() <= narrow  # it can be narrowed again

    # the status line: left-aligned over the footer's whole width
    widget.status.value = (
        "paint strokes into 'leaves scribbles': label 1 on one material, 2 on another, … "
        "(at least 2), then Run (or tick live update)"
    )
    _settle(qtbot)
    status, footer = widget.status.native, widget.footer.native
    origin = status.mapTo(footer, status.rect().topLeft())
    assert origin.x() <= 12
    assert status.width() >= footer.width() - 30
    assert status.alignment() & status.alignment().AlignLeft
    wait_idle(qtbot, widget)
