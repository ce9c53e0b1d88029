"""Plugin controls made from the parameter tables: the shared one
(:data:`~napari_polarseg.engine.params.PARAM_SPECS`) and each registered method's own
(:func:`method_controls`).

Every :class:`~napari_polarseg.engine.params.ParamSpec` with a ``label`` becomes one
control: a menu (its ``choices``, or the registered methods, shown with
:meth:`ParamSpec.menu` names), a float box (the spec has ``decimals``) or an integer
box, with the spec's range and step; the tooltip says what the control does to the
result (the spec's ``effect``), then the spec's help and the default.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, asdict
from typing import Any

from magicgui.widgets import ComboBox, FloatSpinBox, SpinBox
from magicgui.widgets.bases import ValueWidget

from ..engine.method_params import params_class
from ..engine.param_spec import defaults_of
from ..engine.params import PARAM_SPECS, ParamSpec, SegmentParams, all_param_specs

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
    "object_size",
)

#: The default of every shared SegmentParams field (the dataclass defaults; a method's
#: own parameters: the defaults of its ``params_class``).
SHARED_DEFAULTS: dict[str, Any] = defaults_of(SegmentParams)


def float_box(decimals: int, **kwargs: Any) -> FloatSpinBox:
    """A FloatSpinBox showing ``decimals`` decimals (Qt's default, 2, would round the
    range and the values, e.g. a minimum of 0.001 to 0)."""
    box = FloatSpinBox(**kwargs)
    box.native.setDecimals(decimals)
    for name in ("min", "max", "value"):
        if name in kwargs:
            setattr(box, name, kwargs[name])
    return box


def control_tooltip(name: str, spec: ParamSpec, default: Any = MISSING) -> str:
    """What the control does to the result (the spec's ``effect``), then the spec's help
    and the parameter's default (``default``; missing: a shared field's, from
    :data:`SHARED_DEFAULTS`)."""
    details = spec.help
    default = SHARED_DEFAULTS.get(name, MISSING) if default is MISSING else default
    if default is not MISSING:
        shown = f"{default:g}" if isinstance(default, float) else str(default)
        details = f"{details} (default: {shown})"
    return details if spec.effect is None else f"{spec.effect}.\n\nDetails: {details}"


def control_label(name: str, spec: ParamSpec, words: bool = True) -> str:
    """The control's label: the spec's (or the name), followed, with ``words``, by the
    values that stand for a word, as the command line takes them ("segments (0 =
    auto)"): a number box cannot show the word itself (magicgui's integer box, superqt's
    ``QLargeIntSpinBox``, has no special-value text)."""
    label = spec.label or name
    if not (words and spec.words):
        return label
    return f"{label} ({', '.join(f'{v} = {w}' for w, v in spec.words.items())})"


def param_control(
    name: str, spec: ParamSpec, value: Any, default: Any = MISSING, **kwargs: Any
) -> ValueWidget:
    """The control of parameter ``name`` described by ``spec``, showing ``value``.

    A menu when the spec has ``choices``, a float box with ``decimals`` when it has
    them, else an integer box; the tooltip names ``default`` (see
    :func:`control_tooltip`); ``kwargs`` go to the widget (e.g. ``visible``).
    """
    common: dict[str, Any] = {
        "label": control_label(name, spec),
        "value": value,
        "tooltip": control_tooltip(name, spec, default),
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
    defaults: Mapping[str, Any] | None = None,
) -> dict[str, ValueWidget]:
    """One control per labelled spec (or per name of ``names``), by name, in
    :func:`controlled_names` order, each showing ``values[name]`` (e.g.
    ``SegmentParams.to_dict()``), or the spec's minimum or first choice for a name
    ``values`` lacks; the tooltips name ``defaults[name]`` (default: the shared
    fields' defaults)."""
    controls = {}
    for name in controlled_names(specs) if names is None else names:
        spec = specs[name]
        options = spec.options()
        fallback = options[0] if options else spec.minimum
        default = MISSING if defaults is None else defaults.get(name, MISSING)
        controls[name] = param_control(name, spec, values.get(name, fallback), default)
    return controls


def every_param_spec() -> dict[str, ParamSpec]:
    """The shared parameter table, then each registered method's own (a name two
    tables hold: the first's), by parameter name."""
    specs = dict(PARAM_SPECS)
    for method_specs in all_param_specs().values():
        specs.update({n: s for n, s in method_specs.items() if n not in specs})
    return specs


def method_controls(params: SegmentParams) -> dict[str, tuple[str, ValueWidget]]:
    """One control per labelled parameter of every registered method's own table
    (:func:`~napari_polarseg.engine.params.all_param_specs`), by name: (the method,
    the control showing ``params.params_of(method)``'s value); a name two methods
    declare has one control, the first's. The plugin shows a method's controls only
    while it is chosen (:class:`~napari_polarseg.widgets.segment_params.ParameterControls`)."""
    out: dict[str, tuple[str, ValueWidget]] = {}
    for method, specs in all_param_specs().items():
        values = asdict(params.params_of(method))
        defaults = defaults_of(params_class(method))
        names = tuple(n for n in controlled_names(specs) if n not in out)
        for name, control in param_controls(values, specs, names, defaults).items():
            out[name] = (method, control)
    return out
