"""Naming, styling and in-place replacement of the layers the plugin adds.

Every layer the plugin adds carries a tag in its metadata,
``layer.metadata["napari_polarseg"] = {"role": ..., "source": ...}``, where ``role`` is one
of :data:`ROLES` and ``source`` the ``unique_id`` of the angle-stack layer it was computed
from. A rerun looks the layer up by that tag (not by name, which the user may change or
reuse for a layer of their own) and replaces its data in place; a layer without the tag is
never touched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from napari.layers import Image, Labels
from napari.utils.colormaps import CyclicLabelColormap

from ..palette import segment_rgba

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

#: Metadata key of the plugin's tag on its own layers.
TAG = "napari_polarseg"

#: Metadata key holding the polariser angles (degrees) of an angle-stack layer.
ANGLES_KEY = "angles_deg"


@dataclass(frozen=True)
class LayerStyle:
    """Name, type and display of one kind of output layer.

    ``limits`` is either a fixed ``(low, high)`` contrast range or ``None`` for a range
    fitted to the data between the ``percentiles``.
    """

    name: str
    layer_type: str = "image"
    colormap: str | None = None
    limits: tuple[float, float] | None = None
    percentiles: tuple[float, float] = (1.0, 99.0)
    extra: dict[str, Any] = field(default_factory=dict)


#: ``LayerStyle.colormap`` of a Labels layer drawn with :func:`label_colormap`.
SEGMENT_PALETTE = "segment palette"


def label_colormap() -> CyclicLabelColormap:
    """The labels colormap of segments and scribbles: label 0 transparent, labels 1, 2, …
    the bright, pairwise distinct colours of :data:`napari_polarseg.palette.SEGMENT_COLOURS`
    (cycled after the tenth)."""
    colours = np.concatenate([np.zeros((1, 4)), segment_rgba()])
    return CyclicLabelColormap(colors=colours, background_value=0)


#: Output layers by role.
ROLES: dict[str, LayerStyle] = {
    # of the four maps only ρ starts visible: stacked, the top one hides the others, and
    # ρ tells the materials apart best (the HSV view, when added, sits above it)
    "intensity": LayerStyle(
        "Î intensity", colormap="gray", percentiles=(0.5, 99.5), extra={"visible": False}
    ),
    "dop": LayerStyle("ρ degree of polarisation", colormap="viridis"),
    "phase": LayerStyle(
        "φ phase", colormap="twilight", limits=(0.0, math.pi), extra={"visible": False}
    ),
    "zenith": LayerStyle("θ zenith", colormap="magma", extra={"visible": False}),
    "segments": LayerStyle(
        "segments", layer_type="labels", colormap=SEGMENT_PALETTE, extra={"opacity": 0.6}
    ),
    "error": LayerStyle("reconstruction error", colormap="inferno", extra={"visible": False}),
    # 1 where a pixel was left out of the fit and the features (mask, saturated, black, …)
    "masked": LayerStyle(
        "masked pixels", layer_type="labels", extra={"visible": False, "opacity": 0.7}
    ),
    "residual": LayerStyle("fit residual", colormap="magma", extra={"visible": False}),
    # scribble mode: probability of the class the classifier chose (1/K .. 1)
    "probability": LayerStyle(
        "class probability", colormap="cividis", limits=(0.0, 1.0), extra={"visible": False}
    ),
    # scribble mode: the pixel classifier's uncertainty 1 - (p1 - p2), 0 sure .. 1 a tie;
    # bright where another stroke would help most
    "uncertainty": LayerStyle(
        "uncertainty", colormap="inferno", limits=(0.0, 1.0), extra={"visible": False}
    ),
    # the AoLP/DoLP HSV composite (engine.views): an RGB uint8 image
    "hsv": LayerStyle("AoLP/DoLP HSV", limits=(0.0, 255.0), extra={"rgb": True}),
    # linear Stokes components (engine.stokes), input units
    "s0": LayerStyle("S0 Stokes", colormap="gray", extra={"visible": False}),
    "s1": LayerStyle("S1 Stokes", colormap="bwr", extra={"visible": False}),
    "s2": LayerStyle("S2 Stokes", colormap="bwr", extra={"visible": False}),
}


def source_key(layer: Layer) -> str:
    """Stable identifier of an input layer for the tags of its outputs."""
    return str(layer.unique_id)


def output_name(role: str, source: Layer) -> str:
    """Name of a new ``role`` layer computed from ``source``: the role's name and the
    source layer's, e.g. ``"segments (leaves)"``, so outputs of several stacks tell
    which stack they came from (napari would number them ``segments [1]``, …)."""
    return f"{ROLES[role].name} ({source.name})"


def layer_tag(layer: Layer) -> dict[str, Any] | None:
    """The plugin's tag of ``layer``, or None for a layer the plugin did not add."""
    tag = layer.metadata.get(TAG) if isinstance(layer.metadata, dict) else None
    return tag if isinstance(tag, dict) and "role" in tag else None


def find_output(viewer: napari.Viewer, role: str, source: Layer) -> Layer | None:
    """The plugin's ``role`` layer computed from ``source`` in ``viewer``, if any."""
    key = source_key(source)
    for layer in viewer.layers:
        tag = layer_tag(layer)
        if tag is not None and tag.get("role") == role and tag.get("source") == key:
            return layer
    return None


def fitted_limits(data: np.ndarray, percentiles: tuple[float, float]) -> tuple[float, float]:
    """Contrast limits between two percentiles of the finite values (never empty)."""
    values = np.asarray(data, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(values, percentiles))
    if not hi > lo:
        lo, hi = float(values.min()), float(values.max())
    if not hi > lo:
        hi = lo + (abs(lo) * 1e-6 or 1.0)
    return lo, hi


def contrast_for(role: str, data: np.ndarray) -> tuple[float, float]:
    """Contrast limits the ``role`` layer gets for ``data``."""
    style = ROLES[role]
    return style.limits if style.limits is not None else fitted_limits(data, style.percentiles)


@dataclass(frozen=True)
class Contrast:
    """The contrast limits of an image layer and the range its slider offers (the
    limits and the finite data's minimum and maximum): what :func:`contrast_of`
    computes in a worker so that showing a result runs no percentile, nor a scan of the
    data, on the GUI thread."""

    limits: tuple[float, float]
    range: tuple[float, float]


def contrast_of(role: str, data: np.ndarray) -> Contrast:
    """The :class:`Contrast` of the ``role`` layer for ``data`` (any thread: numpy only)."""
    lo, hi = contrast_for(role, data)
    values = np.asarray(data, dtype=float)
    finite = values[np.isfinite(values)]
    dmin, dmax = (float(finite.min()), float(finite.max())) if finite.size else (lo, hi)
    return Contrast((lo, hi), (min(lo, dmin), max(hi, dmax)))


def contrasts_of(arrays: dict[str, np.ndarray | None]) -> dict[str, Contrast]:
    """:func:`contrast_of` of every image role of ``arrays`` (role → data; None and
    Labels roles skipped): a worker's part of showing its result."""
    return {
        role: contrast_of(role, data)
        for role, data in arrays.items()
        if data is not None and ROLES[role].layer_type == "image"
    }


def _image_style(role: str, data: np.ndarray, contrast: Contrast | None) -> dict[str, Any]:
    style = ROLES[role]
    colormap = {} if style.colormap is None else {"colormap": style.colormap}
    limits = contrast_for(role, data) if contrast is None else contrast.limits
    return {**colormap, "contrast_limits": limits, **style.extra}


def show_output(
    viewer: napari.Viewer,
    role: str,
    data: np.ndarray,
    source: Layer,
    metadata: dict[str, Any] | None = None,
    contrast: Contrast | None = None,
) -> Layer:
    """Add the ``role`` layer for ``source``, or replace the data of the existing one.

    ``contrast``: the image's contrast limits and slider range computed in the worker
    (:func:`contrast_of`); without it they are computed here. Given the very array the
    layer shows already, only the metadata change (nothing is drawn again).

    A new layer is named after its role and its source (:func:`output_name`).
    The layer takes the scale and translation of the last two axes of ``source`` so it
    overlays the stack; the layer selection stays as the user left it. On a rerun only
    the data, the contrast limits (for images) and the plugin's metadata change; the
    user's other settings (visibility, opacity, colormap, name, position in the layer
    list) are kept. A new image layer goes below the Labels layers above ``source``
    (:func:`below_labels`), so it hides neither segments nor scribbles.
    """
    style = ROLES[role]
    tag = {"role": role, "source": source_key(source)}
    meta = {TAG: tag, **(metadata or {})}
    layer = find_output(viewer, role, source)
    wanted = Labels if style.layer_type == "labels" else Image
    if layer is not None and isinstance(layer, wanted) and layer.data is data:
        # the very array shown (a rerun that kept this map): no redraw, no new limits
        layer.metadata = {**layer.metadata, **meta}
        return layer
    if layer is not None and isinstance(layer, wanted):
        layer.data = data
        if style.layer_type == "image":
            contrast = contrast or contrast_of(role, data)
            layer.contrast_limits_range = contrast.range
            layer.contrast_limits = contrast.limits
        layer.metadata = {**layer.metadata, **meta}
        return layer
    if layer is not None:  # same tag but another type (should not happen): replace it
        viewer.layers.remove(layer)
    placement = {"scale": tuple(source.scale[-2:]), "translate": tuple(source.translate[-2:])}
    # napari selects every layer it adds; the user's selection (e.g. the scribbles layer
    # being painted) is kept instead
    name = output_name(role, source)
    selection = viewer.layers.selection
    selected, active = set(selection), selection.active
    if style.layer_type == "labels":
        palette = {"colormap": label_colormap()} if style.colormap == SEGMENT_PALETTE else {}
        layer = viewer.add_labels(
            data, name=name, metadata=meta, **placement, **palette, **style.extra
        )
    else:
        layer = viewer.add_image(
            data, name=name, metadata=meta, **placement, **_image_style(role, data, contrast)
        )
    if style.layer_type == "image":
        below_labels(viewer, layer, source)
    selection.clear()
    selection.update(selected)
    if active is not None:
        selection.active = active
    return layer


#: Column of a segments layer's ``features`` that napari's status bar shows on hover.
MATERIAL_COLUMN = "material"


def name_labels(layer: Layer, names: dict[int, str]) -> None:
    """Show ``names`` (label value → name) on hover over the Labels ``layer``: its
    ``features`` table gets an ``index`` column (the label values, which napari looks a
    hovered value up in) and a ``material`` column, so the status bar reads e.g.
    ``3; material: banana``. Without names the table is emptied (nothing extra shown);
    a table already holding these names is left as it is."""
    import pandas as pd

    if not names:
        if layer.features.shape[1]:
            layer.features = pd.DataFrame()
        return
    values = sorted(int(v) for v in names)
    table = pd.DataFrame({"index": values, MATERIAL_COLUMN: [names[v] for v in values]})
    current = layer.features
    if list(current.columns) == list(table.columns) and current.reset_index(drop=True).equals(
        table
    ):
        return
    layer.features = table


def below_labels(viewer: napari.Viewer, layer: Layer, source: Layer) -> None:
    """Move the new image ``layer`` below the lowest Labels layer above ``source``.

    The plugin's derived maps (ρ, the HSV view, …) are opaque: added on top they would
    hide the segments and the scribbles being painted. A Labels layer below the stack
    (hidden by it anyway) does not count.
    """
    layers = viewer.layers
    start = layers.index(source) + 1 if source in layers else 0
    index = layers.index(layer)
    for i in range(start, index):
        if isinstance(layers[i], Labels):
            layers.move(index, i)
            return


def remove_output(viewer: napari.Viewer, role: str, source: Layer) -> bool:
    """Remove the plugin's ``role`` layer of ``source`` (True if there was one)."""
    layer = find_output(viewer, role, source)
    if layer is None:
        return False
    viewer.layers.remove(layer)
    return True


def own_layers(viewer: napari.Viewer, source: Layer | None = None) -> list[Layer]:
    """All layers the plugin added to ``viewer`` (for ``source`` only, if given)."""
    key = None if source is None else source_key(source)
    out = []
    for layer in viewer.layers:
        tag = layer_tag(layer)
        if tag is not None and (key is None or tag.get("source") == key):
            out.append(layer)
    return out
