"""The "Polarisation image" widget: Î, ρ, φ, zenith θ, the HSV view and Stokes of a stack."""

from __future__ import annotations

import functools
from collections.abc import Generator
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import FloatSpinBox

from ..engine import (
    PolarsegError,
    polarisation_image,
    zenith_from_dop,
)
from ..engine.params import SegmentParams
from ..engine.physics.stokes import stokes_components
from ._base import StackWidget
from ._layers import contrasts_of, find_output, show_output, source_key
from .param_controls import param_controls
from .views import VIEW_OUTPUTS, composite_for, show_views, view_mode_box

if TYPE_CHECKING:
    import napari

#: Output roles of this widget, in the order their layers are added.
OUTPUTS = ("intensity", "dop", "phase", "zenith")


def polarisation_status(name: str, n_clamped: int, model: str) -> str:
    """The status line after *Compute*: the stack, and in words the pixels whose ρ no
    diffuse surface gives (their zenith was set to 90°)."""
    text = f"polarisation image of {name!r}"
    if n_clamped > 0 and model == "diffuse":
        text += (
            f"; ρ is above what a diffuse surface can give on {n_clamped:,} pixels "
            "(glints or specular reflection): their zenith is set to 90°"
        )
    return text


def polarisation_job(
    data: Any,
    angles_rad: np.ndarray,
    refractive_index: float,
    model: str,
    branch: str,
    dolp_max: float = 0.0,
    mode: str = "intensity",
) -> Generator[tuple[str, int, int], None, dict[str, Any]]:
    """Worker job: the engine's polarisation image, then zenith from ρ (radians), the
    Stokes components, the HSV composite (ρ_max ``dolp_max``, 0 = automatic, in view
    ``mode``) and the contrast of every image (``"contrast"``: role →
    :class:`~._layers.Contrast`), so that showing them computes nothing on the GUI
    thread."""
    pol = polarisation_image(np.asarray(data), angles_rad)
    yield "polarisation", 1, 3
    est = zenith_from_dop(pol.dop, refractive_index, model, branch)
    s0, s1, s2 = stokes_components(pol.intensity, pol.dop, pol.phase)
    yield "zenith", 2, 3
    out = {
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
    rgb, rho_max = composite_for(pol.intensity, pol.dop, pol.phase, dolp_max, mode)
    out["hsv"] = rgb
    out["composite"] = {"dolp_max": dolp_max, "mode": mode, "rho_max": rho_max}
    out["contrast"] = contrasts_of({role: out[role] for role in OUTPUTS + VIEW_OUTPUTS})
    yield "contrast", 3, 3
    return out


class PolarisationWidget(StackWidget):
    """Compute the polarisation image of an angle stack and show it as four layers.

    Adds (or, on a rerun, updates in place) the layers ``Î intensity``,
    ``ρ degree of polarisation``, ``φ phase`` (radians, 0..π) and ``θ zenith`` (radians,
    from ρ with the chosen Fresnel model and refractive index), then the Stokes components
    ``S0/S1/S2 Stokes`` (hidden) and the RGB ``AoLP/DoLP HSV`` composite (hue = φ,
    saturation = ρ / the *DoLP maximum*, value = Î; the *HSV view* menu offers the light
    and dark variants of :data:`~napari_polarseg.widgets.views.VIEW_MODES`, "dark"
    meaning full saturation with the value from ρ: black where unpolarised).
    Changing the DoLP maximum or the view redraws only the composite. The work runs in
    a napari worker thread; the widget only calls the engine.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers the widget reads and writes.
    """

    dock_title = "Polarisation"
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
            float(self.dolp_max.value),
            str(self.view_mode.value),
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
            present = {source_key(x) for x in self._viewer.layers}
            self._views_input = {k: v for k, v in self._views_input.items() if k in present}
            self._views_input[source_key(layer)] = (out["intensity"], out["dop"], out["phase"])
            # one layer per event-loop turn, with the worker's contrast limits
            for role in OUTPUTS + VIEW_OUTPUTS[:-1]:
                self._later.put(
                    (role, source_key(layer)),
                    functools.partial(self._show_role, layer, role, out, meta),
                )
            self._later.put(
                ("hsv", source_key(layer)), functools.partial(self._show_hsv, layer, out, meta)
            )
            self._done(polarisation_status(layer.name, out["n_clamped"], args[3]))

        self._submit(polarisation_job, args, 3, on_result)

    def _show_role(self, layer: Any, role: str, out: dict[str, Any], meta: dict) -> None:
        """Add/update the ``role`` layer of a result (if its stack is still there)."""
        if layer in self._viewer.layers:
            metadata = {"polarseg_params": meta}
            contrast = out["contrast"].get(role)
            show_output(self._viewer, role, out[role], layer, metadata, contrast)

    def _show_hsv(self, layer: Any, out: dict[str, Any], meta: dict) -> None:
        """The HSV layer of a result: the worker's composite while the *DoLP maximum* and
        the *HSV view* are as the run had them, else drawn again."""
        if layer not in self._viewer.layers:
            return
        made = out["composite"]
        if (made["dolp_max"], made["mode"]) != (
            float(self.dolp_max.value),
            str(self.view_mode.value),
        ):
            self.show_composite(layer)
            return
        how = {"polarseg_composite": {"dolp_max": made["rho_max"], "mode": made["mode"]}}
        metadata = {"polarseg_params": meta, **how}
        show_output(self._viewer, "hsv", out["hsv"], layer, metadata, out["contrast"]["hsv"])
