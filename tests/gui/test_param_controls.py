"""The plugin's parameter controls are made from the parameter table (PARAM_SPECS)."""

from __future__ import annotations

from napari_polarseg.engine.params import PARAM_SPECS, ParamSpec
from napari_polarseg.widgets.segment import SegmentWidget


def test_a_field_added_to_the_table_gets_a_control(viewer):
    specs = {
        **PARAM_SPECS,
        "new_knob": ParamSpec(
            help="a new knob", flag="--new-knob", label="new knob", minimum=2, maximum=9
        ),
    }
    widget = SegmentWidget(viewer, specs=specs)
    viewer.window.add_dock_widget(widget, name="Segment with a new knob")
    knob = widget.new_knob
    assert widget.controlled[-1] == "new_knob"
    assert knob.label == "new knob" and (knob.min, knob.max, knob.value) == (2, 9, 2)
    assert knob.tooltip.startswith("a new knob")
    assert knob in widget.advanced  # every parameter but the first few is "advanced"


def test_the_controls_show_the_table(add_widget):
    widget = add_widget("Segment by material", preset=None)
    for name in widget.controlled:
        spec, control = PARAM_SPECS[name], getattr(widget, name)
        # what the control does, then the spec's help (issue 25); a number that stands
        # for a word (the CLI's --segments auto) is named after the label
        words = "".join(f" ({v} = {w})" for w, v in (spec.words or {}).items())
        assert control.label == spec.label + words and spec.help in control.tooltip
        if spec.options() is not None:  # a menu: its choices, or the registered methods
            assert [v for _, v in spec.menu()] == list(control.choices)
        else:
            assert (control.min, control.max) == (spec.minimum, spec.maximum)
    assert widget.n_segments.label == "segments (0 = auto)"
    assert widget.fit.native.currentText() == "least squares"
    assert widget.refractive_index.native.decimals() == 3
