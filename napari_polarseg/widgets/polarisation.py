"""The "Polarisation image" widget: Î, ρ, φ and zenith θ of an angle stack."""

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
from ..engine.params import MODELS, SPECULAR_BRANCHES
from ._base import StackWidget
from ._layers import show_output, source_key

if TYPE_CHECKING:
    import napari

#: Output roles of this widget, in the order their layers are added.
OUTPUTS = ("intensity", "dop", "phase", "zenith")


def polarisation_job(
    data: Any, angles_rad: np.ndarray, refractive_index: float, model: str, branch: str
) -> Generator[tuple[str, int, int], None, dict[str, Any]]:
    """Worker job: the engine's polarisation image, then zenith from ρ (radians)."""
    pol = polarisation_image(np.asarray(data), angles_rad)
    yield "polarisation", 1, 2
    est = zenith_from_dop(pol.dop, refractive_index, model, branch)
    yield "zenith", 2, 2
    return {
        "intensity": pol.intensity,
        "dop": pol.dop,
        "phase": pol.phase,
        "zenith": est.zenith,
        "n_clamped": est.n_clamped,
        "n_invalid": int(np.count_nonzero(pol.invalid)),
    }


class PolarisationWidget(StackWidget):
    """Compute the polarisation image of an angle stack and show it as four layers.

    Adds (or, on a rerun, updates in place) the layers ``Î intensity``,
    ``ρ degree of polarisation``, ``φ phase`` (radians, 0..π) and ``θ zenith`` (radians,
    from ρ with the chosen Fresnel model and refractive index). The work runs in a napari
    worker thread; the widget only calls the engine.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers the widget reads and writes.
    """

    run_text = "Compute"
    progress_desc = "Polarisation image"

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(viewer)
        self.refractive_index = FloatSpinBox(
            label="refractive index",
            value=1.45,
            min=1.01,
            max=3.0,
            step=0.01,
            tooltip="Assumed refractive index n for zenith from ρ (thesis: 1.45)",
        )
        self.model = ComboBox(
            label="model",
            choices=list(MODELS),
            value="diffuse",
            tooltip="Fresnel model for the zenith: diffuse (eq. 3.13) or specular (eq. 3.11)",
        )
        self.specular_branch = ComboBox(
            label="specular branch",
            choices=list(SPECULAR_BRANCHES),
            value="below-brewster",
            visible=False,
            tooltip="Specular ρ takes each value twice: zenith below or above Brewster's angle",
        )
        self.model.changed.connect(self._on_model_changed)
        self._add_parameters([self.refractive_index, self.model, self.specular_branch])

    def _on_model_changed(self, model: str) -> None:
        self.specular_branch.visible = model == "specular"

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
            for role in OUTPUTS:
                show_output(self._viewer, role, out[role], layer, {"polarseg_params": meta})
            extra = f", {out['n_clamped']} pixels above the diffuse ρ ceiling" * (
                out["n_clamped"] > 0 and args[3] == "diffuse"
            )
            self._done(f"polarisation image of {layer.name!r}{extra}")

        self._submit(polarisation_job, args, 2, on_result)
