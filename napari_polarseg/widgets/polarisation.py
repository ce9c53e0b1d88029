"""The "Polarisation image" widget: Î, ρ, φ, zenith θ, the HSV view and Stokes of a stack."""

from __future__ import annotations

from collections.abc import Generator
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import ComboBox, FloatSpinBox

from ..engine import (
    PolarsegError,
    polarisation_image,
    zenith_from_dop,
)
from ..engine.analysis.views import CompositeParams, aolp_dolp_composite, auto_dolp_max
from ..engine.params import SegmentParams
from ..engine.physics.stokes import stokes_components
from ._base import StackWidget
from ._layers import find_output, show_output, source_key
from .param_controls import param_controls

if TYPE_CHECKING:
    import napari

#: Output roles of this widget, in the order their layers are added.
OUTPUTS = ("intensity", "dop", "phase", "zenith")
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


def polarisation_job(
    data: Any, angles_rad: np.ndarray, refractive_index: float, model: str, branch: str
) -> Generator[tuple[str, int, int], None, dict[str, Any]]:
    """Worker job: the engine's polarisation image, then zenith from ρ (radians)."""
    pol = polarisation_image(np.asarray(data), angles_rad)
    yield "polarisation", 1, 2
    est = zenith_from_dop(pol.dop, refractive_index, model, branch)
    s0, s1, s2 = stokes_components(pol.intensity, pol.dop, pol.phase)
    yield "zenith", 2, 2
    return {
        "intensity": pol.intensity,
        "dop": pol.dop,
        "phase": pol.phase,
        "zenith": est.zenith,
        "s0": s0,
        "s1": s1,
        "s2": s2,
        "n_clamped": est.n_clamped,
        "n_invalid": int(np.count_nonzero(pol.invalid)),
    }


class PolarisationWidget(StackWidget):
    """Compute the polarisation image of an angle stack and show it as four layers.

    Adds (or, on a rerun, updates in place) the layers ``Î intensity``,
    ``ρ degree of polarisation``, ``φ phase`` (radians, 0..π) and ``θ zenith`` (radians,
    from ρ with the chosen Fresnel model and refractive index), then the Stokes components
    ``S0/S1/S2 Stokes`` (hidden) and the RGB ``AoLP/DoLP HSV`` composite (hue = φ,
    saturation = ρ / the *DoLP maximum*, value = Î; the *HSV view* menu offers the light
    and dark variants of :data:`VIEW_MODES`, "dark" meaning full saturation with the value
    from ρ: black where unpolarised). Changing the DoLP maximum or the view redraws only
    the composite. The work runs in a napari worker thread; the widget only calls
    the engine.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers the widget reads and writes.
    """

    run_text = "Compute"
    run_tooltip = (
        "Fit the polarisation image (Î, ρ, φ) and the zenith θ of the chosen stack and "
        "add them as layers, with the AoLP/DoLP view and the Stokes components"
    )
    progress_desc = "Polarisation image"

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(viewer)
        # the controls of the Fresnel parameters, from the parameter table
        controls = param_controls(
            SegmentParams().to_dict(), names=("refractive_index", "model", "specular_branch")
        )
        self.refractive_index = controls["refractive_index"]
        self.model = controls["model"]
        self.specular_branch = controls["specular_branch"]
        self.specular_branch.visible = False
        self.dolp_max = FloatSpinBox(
            label="DoLP maximum",
            value=0.0,
            min=0.0,
            max=1.0,
            step=0.01,
            tooltip="ρ shown at full colour in the AoLP/DoLP HSV layer; auto (0): the 99th "
            "percentile of ρ rounded up to 0.05. Redraws only that layer",
        )
        self.dolp_max.native.setSpecialValueText("auto")
        self.view_mode = view_mode_box()
        #: Î, ρ, φ of the last result per stack layer (source key): the composite's input
        self._views_input: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.model.changed.connect(self._on_model_changed)
        self.dolp_max.changed.connect(self._on_view_changed)
        self.view_mode.changed.connect(self._on_view_changed)
        self._add_parameters(
            [self.refractive_index, self.model, self.specular_branch, self.dolp_max, self.view_mode]
        )

    def _on_model_changed(self, model: str) -> None:
        self.specular_branch.visible = model == "specular"

    def show_composite(self, layer: Any) -> Any:
        """Draw (or redraw) the HSV layer of ``layer`` from its last Î, ρ, φ; None if none."""
        arrays = self._views_input.get(source_key(layer))
        if arrays is None:
            return None
        mode = str(self.view_mode.value)
        return show_views(
            self._viewer, layer, arrays, float(self.dolp_max.value), mode, stokes=False
        )[-1]

    def _on_view_changed(self, _value: float) -> None:
        layer = self.stack_layer.value
        if layer is None or find_output(self._viewer, "hsv", layer) is None:
            return
        self.show_composite(layer)

    def snapshot(self) -> tuple[Any, ...]:
        """Everything a result depends on (results for another snapshot are dropped)."""
        layer = self.stack_layer.value
        return (
            None if layer is None else source_key(layer),
            self.angles.value,
            float(self.refractive_index.value),
            self.model.value,
            self.specular_branch.value,
        )

    def run(self, *_: Any) -> None:
        """Start computing in a worker thread; returns at once."""
        try:
            layer, angles_deg = self.current_stack()
        except PolarsegError as exc:
            self._fail(exc)
            return
        snap = self.snapshot()
        args = (
            layer.data,
            np.deg2rad(angles_deg),
            float(self.refractive_index.value),
            self.model.value,
            self.specular_branch.value,
        )

        def on_result(run_id: int, out: dict[str, Any]) -> None:
            if snap != self.snapshot() or layer not in self._viewer.layers:
                self._set_status("result dropped: the parameters changed while it was computed")
                return
            meta = {
                "angles_deg": [float(a) for a in angles_deg],
                "refractive_index": args[2],
                "model": args[3],
                "specular_branch": args[4],
            }
            for role in OUTPUTS + VIEW_OUTPUTS[:-1]:
                show_output(self._viewer, role, out[role], layer, {"polarseg_params": meta})
            present = {source_key(x) for x in self._viewer.layers}
            self._views_input = {k: v for k, v in self._views_input.items() if k in present}
            self._views_input[source_key(layer)] = (out["intensity"], out["dop"], out["phase"])
            self.show_composite(layer)
            extra = f", {out['n_clamped']} pixels above the diffuse ρ ceiling" * (
                out["n_clamped"] > 0 and args[3] == "diffuse"
            )
            self._done(f"polarisation image of {layer.name!r}{extra}")

        self._submit(polarisation_job, args, 2, on_result)
