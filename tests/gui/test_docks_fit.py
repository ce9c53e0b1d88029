"""The plugin's docks fit a 1600 x 1000 screen (issue 14, item 6): each scrolls its
controls, and *Segment by material* shows the few a user touches first."""

from __future__ import annotations

from qtpy.QtWidgets import QScrollArea

from napari_polarseg.widgets.segment import CONTROLLED, FIRST_CONTROLS

#: Every dock widget of the plugin's manifest.
DOCKS = (
    "Segment by material",
    "Polarisation image",
    "Polarisation plots",
    "Parameter sweep",
    "Batch over a folder",
    "Time series change map",
)
SCREEN = (1600, 1000)


def test_all_docks_fit_the_screen(viewer, add_widget, open_sample):
    open_sample("leaves")
    widgets = [add_widget(name) for name in DOCKS]
    window = viewer.window._qt_window
    hint = window.minimumSizeHint()
    assert hint.height() <= SCREEN[1] and hint.width() <= SCREEN[0]
    for name, widget in zip(DOCKS, widgets, strict=True):
        area = widget.native
        assert isinstance(area, QScrollArea), name
        assert area.widget() is widget.content, name  # the controls are inside the scroll area
    window.resize(*SCREEN)
    window.show()
    assert window.height() <= SCREEN[1] and window.width() <= SCREEN[0]
    # the docks share the height: the tall ones scroll instead of growing the window
    sweep = widgets[DOCKS.index("Parameter sweep")].native
    assert sweep.height() < sweep.widget().minimumSizeHint().height()
    assert sweep.verticalScrollBar().maximum() > 0


def test_segment_widget_hides_advanced_controls_until_asked(viewer, add_widget, qtbot):
    widget = add_widget("Segment by material")
    first = [widget.stack_layer, widget.preset, widget.n_segments, widget.scribbles_layer]
    first += [widget.run_button, widget.cancel_button, widget.status]
    assert all(w in list(widget) for w in first)
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
