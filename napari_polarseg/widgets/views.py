"""The polarisation views both the *Polarisation image* and the *Segment by material*
widgets add: the AoLP/DoLP HSV composite (in one of :data:`VIEW_MODES`) and the Stokes
S0, S1, S2 layers."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import ComboBox

from ..engine.analysis.views import CompositeParams, aolp_dolp_composite, auto_dolp_max
from ..engine.physics.stokes import stokes_components
from ._layers import show_output

if TYPE_CHECKING:
    import napari

#: The polarisation views added after them: Stokes S0, S1, S2 (hidden) and the HSV composite.
VIEW_OUTPUTS = ("s0", "s1", "s2", "hsv")


#: Text shown for each variant of the HSV view (``CompositeParams.mode``): hue is always
#: the AoLP φ. "with intensity": saturation from ρ, value from Î (the scene's shading
#: shows); "light": saturation from ρ on a white ground (value 1: unpolarised pixels are
#: white); "dark": full saturation, value from ρ, so unpolarised pixels are black and only
#: polarised ones show colour, brighter the more polarised (polanalyser's
#: ``applyColorToAoLP`` light and dark variants).
VIEW_MODES = {"with intensity": "intensity", "light": "light", "dark": "dark"}

#: Tooltip of the HSV view menus (Polarisation image, Segment by material).
VIEW_MODE_TOOLTIP = (
    "Colouring of the AoLP/DoLP HSV layer (hue = AoLP φ): with intensity: saturation ρ, "
    "value Î; light: saturation ρ on white (unpolarised = white); dark: value ρ on black "
    "(unpolarised = black, colour only where polarised). Redraws only that layer"
)


def composite_for(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    dolp_max: float,
    mode: str = "intensity",
) -> tuple[np.ndarray, float]:
    """The HSV composite with ρ_max = ``dolp_max``, or automatic (0), in the ``mode`` of
    :data:`VIEW_MODES` (:func:`~napari_polarseg.engine.analysis.views.aolp_dolp_composite`; "dark":
    value from ρ on black): (RGB, ρ_max used)."""
    rho_max = auto_dolp_max(dop) if dolp_max <= 0 else float(dolp_max)
    params = CompositeParams(dolp_max=rho_max, mode=mode)
    return aolp_dolp_composite(intensity, dop, phase, params), rho_max


def view_mode_box(**kwargs: Any) -> ComboBox:
    """The "HSV view" menu of :data:`VIEW_MODES`."""
    return ComboBox(
        label="HSV view",
        choices=list(VIEW_MODES.items()),
        value="intensity",
        tooltip=VIEW_MODE_TOOLTIP,
        **kwargs,
    )


def show_views(
    viewer: napari.viewer.Viewer,
    source: Any,
    arrays: tuple[np.ndarray, np.ndarray, np.ndarray],
    dolp_max: float,
    mode: str,
    metadata: dict[str, Any] | None = None,
    stokes: bool = True,
) -> list[Any]:
    """Add or update the S0, S1, S2 Stokes layers (hidden; with ``stokes``) and the HSV
    composite of ``source`` from its Î, ρ, φ ``arrays`` (the layers both widgets share:
    whichever computed last shows). Returns the layers, the composite last."""
    intensity, dop, phase = arrays
    shown = []
    if stokes:
        components = stokes_components(intensity, dop, phase)
        for role, data in zip(VIEW_OUTPUTS[:-1], components, strict=True):
            shown.append(show_output(viewer, role, data, source, metadata))
    rgb, rho_max = composite_for(intensity, dop, phase, dolp_max, mode)
    meta = {**(metadata or {}), "polarseg_composite": {"dolp_max": rho_max, "mode": mode}}
    shown.append(show_output(viewer, "hsv", rgb, source, meta))
    return shown
