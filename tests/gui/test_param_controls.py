"""The plugin's parameter controls are made from the parameter tables (PARAM_SPECS, and
each method's own, shown while that method is chosen)."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest

from napari_polarseg.engine.methods import MethodOutput, register_method, unregister_method
from napari_polarseg.engine.param_spec import param_field
from napari_polarseg.engine.params import PARAM_SPECS, ParamSpec, all_param_specs
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
        spec, control = widget.param_specs[name], getattr(widget, name)
        assert spec is PARAM_SPECS.get(name) or spec is all_param_specs()["thesis"][name]
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


@dataclass(frozen=True)
class ToyParams:
    """The toy method's one parameter."""

    share: float = param_field(
        0.5,
        help="Share of the pixels, darkest first, in the first segment, in (0, 1)",
        flag="--toy-share",
        label="toy share",
        minimum=0.05,
        maximum=0.95,
        step=0.05,
        decimals=2,
        effect="How much of the frame the toy's first segment takes",
    )


class IntensityShare:
    """A toy method registered from outside the package: the darkest share, the rest."""

    name, title, reads, inputs = "toy_share", "toy: darkest share", ("fit",), ()
    params_class = ToyParams

    def stages(self, params):
        return ("split",)

    def segment(self, scene, params, inputs, run):
        run.begin("split")
        intensity = scene.polarisation(params).intensity
        share = params.params_of(self.name).share
        return MethodOutput((intensity > np.quantile(intensity, share)).astype(np.int32))


@pytest.fixture
def toy():
    register_method(IntensityShare())
    yield IntensityShare.name
    unregister_method(IntensityShare.name)


def test_the_controls_of_the_chosen_method_only(viewer, toy, tmp_path):
    """A registered method's parameter gets a control, shown while that method is
    chosen; its value reaches the parameters and a parameters file."""
    widget = SegmentWidget(viewer)
    viewer.window.add_dock_widget(widget, name="Segment with a toy method")
    control = widget.share
    assert control.label == "toy share" and (control.min, control.max) == (0.05, 0.95)
    assert control.native.toolTip().startswith("How much of the frame the toy's first")
    shown = widget.controls.shown_method_controls
    widget.method.value = toy
    assert "share" in shown() and "window" not in shown()
    widget.share.value = 0.3
    params = widget.params()
    assert params.method == toy and params.params_of(toy).share == 0.3
    widget.method.value = "thesis"
    assert "window" in shown() and "degree" in shown() and "share" not in shown()
    widget.method.value = "surface_superpixels"  # no parameters of its own
    assert shown() == ()
    widget.thesis_maps.value = True  # the maps read the thesis method's parameters
    assert "window" in shown() and "share" not in shown()
    # the toy's value is kept while another method is chosen, and saved with the toy
    widget.method.value = toy
    path = tmp_path / "toy.json"
    assert widget.save_params(path)
    assert json.loads(path.read_text())["method_params"][toy] == {"share": 0.3}
    widget.share.value = 0.8
    assert widget.load_params(path) and widget.share.value == 0.3
