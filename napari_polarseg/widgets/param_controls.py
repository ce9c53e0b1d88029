"""Plugin controls made from the parameter table
(:data:`~napari_polarseg.engine.params.PARAM_SPECS`).

Every :class:`~napari_polarseg.engine.params.ParamSpec` with a ``label`` becomes one
control: a menu (its ``choices``, or the registered methods, shown with
:meth:`ParamSpec.menu` names), a float box (the spec has ``decimals``) or an integer
box, with the spec's range and step; the tooltip is the spec's help and the thesis
default.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, fields
from typing import Any

from magicgui.widgets import ComboBox, FloatSpinBox, SpinBox
from magicgui.widgets.bases import ValueWidget

from ..engine.params import PARAM_SPECS, ParamSpec, SegmentParams

#: Order of the controls in the Segment widget; labelled specs not listed follow, in
#: table order (layout only: what each control is comes from the table).
CONTROL_ORDER = (
    "method",
    "window",
    "degree",
    "refractive_index",
    "fit",
    "model",
    "specular_branch",
    "coefficients",
    "features",
    "variance",
    "scale",
    "scale_mode",
    "clustering",
    "min_segment_blocks",
    "n_segments",
)

#: The thesis default of every SegmentParams field (the dataclass defaults).
THESIS_DEFAULTS: dict[str, Any] = {
    f.name: f.default for f in fields(SegmentParams) if f.default is not MISSING
}


def float_box(decimals: int, **kwargs: Any) -> FloatSpinBox:
    """A FloatSpinBox showing ``decimals`` decimals (Qt's default, 2, would round the
    range and the values, e.g. a minimum of 0.001 to 0)."""
    box = FloatSpinBox(**kwargs)
    box.native.setDecimals(decimals)
    for name in ("min", "max", "value"):
        if name in kwargs:
            setattr(box, name, kwargs[name])
    return box


def control_tooltip(name: str, spec: ParamSpec) -> str:
    """The spec's help and, for a SegmentParams field, its thesis default."""
    if name not in THESIS_DEFAULTS:
        return spec.help
    default = THESIS_DEFAULTS[name]
    shown = f"{default:g}" if isinstance(default, float) else str(default)
    return f"{spec.help} (thesis: {shown})"


def param_control(name: str, spec: ParamSpec, value: Any, **kwargs: Any) -> ValueWidget:
    """The control of parameter ``name`` described by ``spec``, showing ``value``.

    A menu when the spec has ``choices``, a float box with ``decimals`` when it has
    them, else an integer box; ``kwargs`` go to the widget (e.g. ``visible``).
    """
    common: dict[str, Any] = {
        "label": spec.label or name,
        "value": value,
        "tooltip": control_tooltip(name, spec),
        **kwargs,
    }
    if spec.options() is not None:
        return ComboBox(choices=spec.menu(), **common)
    limits = {
        key: bound
        for key, bound in (("min", spec.minimum), ("max", spec.maximum), ("step", spec.step))
        if bound is not None
    }
    if spec.decimals is not None:
        return float_box(spec.decimals, **limits, **common)
    return SpinBox(**{k: int(v) for k, v in limits.items()}, **common)


def controlled_names(specs: Mapping[str, ParamSpec] = PARAM_SPECS) -> tuple[str, ...]:
    """Names of the specs that have a control (a label), in :data:`CONTROL_ORDER`."""
    labelled = [name for name, spec in specs.items() if spec.label]
    first = [name for name in CONTROL_ORDER if name in labelled]
    return (*first, *(name for name in labelled if name not in first))


def param_controls(
    values: Mapping[str, Any],
    specs: Mapping[str, ParamSpec] = PARAM_SPECS,
    names: tuple[str, ...] | None = None,
) -> dict[str, ValueWidget]:
    """One control per labelled spec (or per name of ``names``), by name, in
    :func:`controlled_names` order, each showing ``values[name]`` (e.g.
    ``SegmentParams.to_dict()``), or the spec's minimum or first choice for a name
    ``values`` lacks."""
    controls = {}
    for name in controlled_names(specs) if names is None else names:
        spec = specs[name]
        options = spec.options()
        fallback = options[0] if options else spec.minimum
        controls[name] = param_control(name, spec, values.get(name, fallback))
    return controls
