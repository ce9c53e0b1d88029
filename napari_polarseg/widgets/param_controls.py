"""Plugin controls made from the parameter table
(:data:`~napari_polarseg.engine.params.PARAM_SPECS`).

Every :class:`~napari_polarseg.engine.params.ParamSpec` with a ``label`` becomes one
control: a menu (its ``choices``, or the registered methods, shown with
:meth:`ParamSpec.menu` names), a float box (the spec has ``decimals``) or an integer
box, with the spec's range and step; the tooltip says what the control does to the
result (:data:`EFFECTS`), then the spec's help and the thesis default.
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
    "object_size",
)

#: What each parameter control does to the result, in plain words: the first line of its
#: tooltip (the spec's technical help follows it). One entry per labelled spec.
EFFECTS: dict[str, str] = {
    "method": "Which algorithm splits the image into materials: the superpixel methods "
    "follow object edges and are fastest; thesis works on a grid of square blocks",
    "window": "Size of the square blocks the image is cut into: larger gives smoother, "
    "blockier segments and a faster run; smaller follows finer detail but is noisier",
    "degree": "How much detail of each block's shading is compared: higher tells similar "
    "materials apart better, but runs slower and can pick up noise",
    "refractive_index": "The material's assumed refractive index (glass and most plastics "
    "about 1.5), used to turn polarisation into surface angle; moves the segments little",
    "fit": "How each pixel's polarisation is measured from the frames: robust ignores a "
    "frame that is off at a pixel (a glint, a moving edge) and takes longer",
    "model": "Whether surfaces are taken as matte (diffuse) or shiny (specular) when "
    "polarisation is turned into surface angle",
    "specular_branch": "Shiny surfaces only: which of the two surface angles that give the "
    "same polarisation to take",
    "coefficients": "How each block's shading is summarised: the thesis estimate, or a "
    "fit that is steadier on small or partly masked blocks",
    "features": "What is compared between blocks: the whole shading description, the part "
    "that does not change when the object turns, or polarisation statistics; changes "
    "which materials look alike",
    "variance": "How much of the block description is kept: lower runs faster and merges "
    "materials that differ only slightly",
    "scale": "How different two blocks must be to end up apart: smaller splits more "
    "readily, larger groups more",
    "scale_mode": "absolute: the scale as given; median: the scale adapts to the image, "
    "steadier from one image to the next",
    "clustering": "How the segments are cut apart: one split at a time (thesis) or all at "
    "once (k-way, often more even segments)",
    "min_segment_blocks": "The smallest segment allowed, in blocks: raise it to stop tiny "
    "specks becoming segments of their own",
    "n_segments": "How many segments (materials) the result has; 0 lets a method that can "
    "choose the number itself",
    "object_size": "How large one object is, in pixels across; 0 estimates it from the "
    "image. Smaller sizes give finer superpixels that do not blur small objects together",
}

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
    """What the control does to the result (:data:`EFFECTS`), then the spec's help and,
    for a SegmentParams field, its thesis default."""
    details = spec.help
    if name in THESIS_DEFAULTS:
        default = THESIS_DEFAULTS[name]
        shown = f"{default:g}" if isinstance(default, float) else str(default)
        details = f"{details} (thesis: {shown})"
    effect = EFFECTS.get(name)
    return details if effect is None else f"{effect}.\n\nDetails: {details}"


def control_label(name: str, spec: ParamSpec, words: bool = True) -> str:
    """The control's label: the spec's (or the name), followed, with ``words``, by the
    values that stand for a word, as the command line takes them ("segments (0 =
    auto)"): a number box cannot show the word itself (magicgui's integer box, superqt's
    ``QLargeIntSpinBox``, has no special-value text)."""
    label = spec.label or name
    if not (words and spec.words):
        return label
    return f"{label} ({', '.join(f'{v} = {w}' for w, v in spec.words.items())})"


def param_control(name: str, spec: ParamSpec, value: Any, **kwargs: Any) -> ValueWidget:
    """The control of parameter ``name`` described by ``spec``, showing ``value``.

    A menu when the spec has ``choices``, a float box with ``decimals`` when it has
    them, else an integer box; ``kwargs`` go to the widget (e.g. ``visible``).
    """
    common: dict[str, Any] = {
        "label": control_label(name, spec),
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
