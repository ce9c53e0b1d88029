"""The plugin's docks fit a 1600 x 1000 screen (issue 14, item 6): each scrolls its
controls, and *Segment by material* shows the few a user touches first."""

from __future__ import annotations

from _gui_helpers import PLUGIN_DOCKS as DOCKS
from qtpy.QtWidgets import QScrollArea

from napari_polarseg.widgets._base import _dock_of
from napari_polarseg.widgets.segment import CONTROLLED, FIRST_CONTROLS

SCREEN = (1600, 1000)


def test_all_docks_fit_the_screen(viewer, add_widget, open_sample, qtbot):
    open_sample("leaves")
    widgets = []
    for name in DOCKS:  # one by one, as from the Plugins menu: each opens as a tab
        widgets.append(add_widget(name))
        qtbot.wait(10)
    window = viewer.window._qt_window
    for name, widget in zip(DOCKS, widgets, strict=True):
        area = widget.scroll_area
        assert isinstance(area, QScrollArea), name
        assert area.widget() is widget.content, name  # the controls are inside the scroll area
        assert area.parent() is widget.native, name  # napari docks the frame around it
    window.resize(*SCREEN)
    window.show()
    qtbot.wait(50)  # the docks are tabified on the next event-loop turn
    hint = window.minimumSizeHint()
    assert hint.height() <= SCREEN[1] and hint.width() <= SCREEN[0]
    assert window.height() <= SCREEN[1] and window.width() <= SCREEN[0]
    # the docks open as tabs of the Segment dock instead of sharing its height
    segment = _dock_of(widgets[0].native)
    tabbed = set(window.tabifiedDockWidgets(segment))
    assert {_dock_of(w.native) for w in widgets[1:]} <= tabbed


def test_segment_widget_hides_advanced_controls_until_asked(viewer, add_widget, qtbot):
    widget = add_widget("Segment by material")
    first = [widget.stack_layer, widget.preset, widget.n_segments, widget.scribbles_layer]
    assert all(w in list(widget) for w in first)
    footer = [widget.run_button, widget.cancel_button, widget.progress, widget.status]
    assert all(w in list(widget.footer) for w in footer)  # below the scroll area
    advanced = [getattr(widget, name) for name in CONTROLLED if name not in FIRST_CONTROLS]
    advanced += [widget.mask_layer, widget.params_file, widget.classifier_file]
    assert all(w in list(widget.advanced) for w in advanced)
    short = widget.content.minimumSizeHint().height()
    assert not widget.show_advanced.value and widget.advanced.native.isHidden()
    widget.show_advanced.value = True
    assert not widget.advanced.native.isHidden()
    assert widget.content.minimumSizeHint().height() > short + 200  # ~14 more rows
    widget.window.value = 7  # every control stays reachable through its attribute
    assert widget.params().window == 7
    widget.show_advanced.value = False
    assert widget.advanced.native.isHidden() and widget.params().window == 7
