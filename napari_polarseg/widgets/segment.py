"""The "Segment by material" widget: the cached engine pipeline, run in a worker thread."""

from __future__ import annotations

import hashlib
import time
from collections.abc import Generator
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, FloatSpinBox, SpinBox
from napari.layers import Labels
from qtpy.QtCore import QTimer

from ..engine import STAGES, Pipeline, PolarsegError, SegmentParams
from ..engine.params import (
    COEFFICIENT_METHODS,
    FEATURE_KINDS,
    FIT_METHODS,
    MAX_DEGREE,
    MODELS,
    RECOMMENDED,
    SCALE_MODES,
    SPECULAR_BRANCHES,
)
from ._base import StackWidget
from ._layers import find_output, layer_tag, show_output, source_key
from ._runner import PipelineStore

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

#: Milliseconds the live update waits after the last change before it reruns.
LIVE_DELAY_MS = 150

#: Starting points offered by the "preset" menu.
PRESETS: dict[str, SegmentParams] = {"thesis": SegmentParams(), "recommended": RECOMMENDED}

#: Text shown for each sinusoid-fit method of the "fit" menu.
FIT_NAMES = {"lsq": "least squares", "robust": "robust"}

#: Text of the "mask" menu entry that segments every pixel.
NO_MASK = "none"

#: Words of the status line for the masked-pixel counts of ``result.mask_counts``.
MASK_REASONS = (
    ("saturated_pixels", "saturated"),
    ("dark_pixels", "black"),
    ("nonfinite_pixels", "not finite"),
    ("outside_region_pixels", "outside the mask"),
)

#: SegmentParams fields that have a control in the widget (the others come from the preset).
CONTROLLED = (
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
    "min_segment_blocks",
    "n_segments",
)


def segment_job(
    store: PipelineStore,
    key: str,
    data: Any,
    angles_rad: np.ndarray,
    params: SegmentParams,
    region: np.ndarray | None = None,
    mask_key: str | None = None,
) -> Generator[tuple[str, int, int], None, Any]:
    """Worker job: run the stale stages of the layer's cached pipeline, then assemble.

    ``region`` (H, W bool, True = use) restricts the segmentation; saturated and black
    samples are left out in any case (:meth:`PipelineStore.obtain`). Yields ``(stage,
    index, total)`` after every stage; stopping the worker between two yields cancels the
    run and leaves the stages computed so far cached.
    """
    pipe = store.obtain(key, data, angles_rad, params, region=region, mask_key=mask_key)
    yield from pipe.run_iter(reconstruction=True)
    return pipe.result(reconstruction=True, params=params)


def mask_text(counts: dict[str, Any]) -> str:
    """``"masked: 120 saturated, 3 black"`` from ``result.mask_counts`` ("" if none)."""
    parts = [f"{int(counts[k])} {word}" for k, word in MASK_REASONS if counts.get(k)]
    return f"masked: {', '.join(parts)}" if parts else ""


def region_digest(region: np.ndarray | None) -> str | None:
    """A short fingerprint of a region's content (None for no region)."""
    if region is None:
        return None
    bits = np.packbits(np.asarray(region, dtype=bool))
    return f"{region.shape}:{hashlib.blake2b(bits.tobytes(), digest_size=16).hexdigest()}"


class SegmentWidget(StackWidget):
    """Segment an angle stack by material (thesis section 4.5) with live parameters.

    Controls: a preset (thesis values or the recommended ones), window size w, harmonic
    degree L, refractive index n, Fresnel model (and specular branch), coefficient
    estimator, block features, PCA variance share, affinity scale s and its mode, minimum
    segment size, number of segments, the sinusoid fit (least squares or robust) and a
    mask (none, or a Labels layer of the stack's height x width: non-zero = segment the
    pixel); Run and Cancel; a live-update toggle that reruns after every change.
    Saturated samples (at the integer dtype's maximum) and black ones (at or below 0)
    are always left out of the fit and counted in the status line.

    One :class:`~napari_polarseg.engine.Pipeline` is kept per stack layer, so a rerun
    computes only the stages a change made stale (changing the number of segments
    recomputes only the labels). The mask is read at every run: choosing another one,
    or painting the chosen Labels layer, builds a new pipeline at the next run. At most
    one worker runs at a time; a change during a run stops it at the next stage boundary
    and starts the newest request.

    Output layers (replaced in place on a rerun): ``segments`` (Labels, one label per
    segment over every pixel; segment k of the engine is label k + 1 because napari
    draws label 0 as transparent background) and ``reconstruction error`` (Image,
    per-pixel |Î rebuilt from the block harmonics − Î|, added hidden below the segments;
    its mean is in the status line). Once a run leaves pixels out (mask, saturated, black)
    or uses the robust fit, also ``masked pixels`` (Labels, 1 where a pixel was left out
    of the fit and the features) and ``fit residual`` (Image, RMS residual of the
    per-pixel sinusoid fit), both added hidden and updated on every later run.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers the widget reads and writes.
    """

    run_text = "Run"
    progress_desc = "Segment by material"

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(viewer)
        d = PRESETS["thesis"]
        self._base = d  # values of the fields without a control
        self.store = PipelineStore()
        self.preset = ComboBox(
            label="preset",
            choices=list(PRESETS),
            value="thesis",
            tooltip="Start from the thesis values or from the values that score best on "
            "the bundled synthetic scenes (README, 'Segmentation quality')",
        )
        self.window = SpinBox(
            label="window size",
            value=d.window,
            min=2,
            max=4096,
            tooltip="Side w of the square pixel blocks (thesis: 10)",
        )
        self.degree = SpinBox(
            label="harmonic degree",
            value=d.degree,
            min=0,
            max=MAX_DEGREE,
            tooltip="Highest spherical-harmonic degree L: (L+1)² coefficients (thesis: 12)",
        )
        self.refractive_index = FloatSpinBox(
            label="refractive index",
            value=d.refractive_index,
            min=1.01,
            max=3.0,
            step=0.01,
            tooltip="Assumed refractive index n for zenith from ρ (thesis: 1.45)",
        )
        self.fit = ComboBox(
            label="fit",
            choices=[(FIT_NAMES.get(m, m), m) for m in FIT_METHODS],
            value=d.fit,
            tooltip="Per-pixel sinusoid fit: least squares, or robust (Tukey-weighted; "
            "resists one outlying frame, needs at least 5 distinct angles)",
        )
        self.model = ComboBox(
            label="model",
            choices=list(MODELS),
            value=d.model,
            tooltip="Fresnel model for the zenith: diffuse (eq. 3.13) or specular (eq. 3.11)",
        )
        self.specular_branch = ComboBox(
            label="specular branch",
            choices=list(SPECULAR_BRANCHES),
            value=d.specular_branch,
            visible=False,
            tooltip="Specular ρ takes each value twice: zenith below or above Brewster's angle",
        )
        self.coefficients = ComboBox(
            label="coefficients",
            choices=list(COEFFICIENT_METHODS),
            value=d.coefficients,
            tooltip="Block coefficients: thesis mean estimator (eq. 4.21) or ridge least squares",
        )
        self.features = ComboBox(
            label="features",
            choices=list(FEATURE_KINDS),
            value=d.features,
            tooltip="Block features for the PCA: every coefficient (thesis), the "
            "azimuth-invariant m = 0 coefficients (zonal), or the energy per degree",
        )
        self.variance = FloatSpinBox(
            label="PCA variance",
            value=d.variance,
            min=0.05,
            max=1.0,
            step=0.01,
            tooltip="Share of the variance the PCA keeps (thesis: 0.95)",
        )
        self.scale = FloatSpinBox(
            label="affinity scale",
            value=d.scale,
            min=0.001,
            max=1e6,
            step=0.1,
            tooltip="s in the affinity S = exp(-D / s) (thesis: 1)",
        )
        self.scale_mode = ComboBox(
            label="scale mode",
            choices=list(SCALE_MODES),
            value=d.scale_mode,
            tooltip="absolute: s as given (thesis); median: s relative to the median "
            "squared Mahalanobis distance between blocks",
        )
        self.min_segment_blocks = SpinBox(
            label="min segment (blocks)",
            value=d.min_segment_blocks,
            min=1,
            max=100_000,
            tooltip="Smallest segment, in blocks, a cut may produce",
        )
        self.n_segments = SpinBox(
            label="segments",
            value=d.n_segments,
            min=1,
            max=256,
            tooltip="Number of segments the recursive normalized cut stops at",
        )
        self.live = CheckBox(
            text="live update",
            value=False,
            tooltip="Rerun (only the stale stages) whenever a value changes",
        )
        self.mask_layer = ComboBox(
            label="mask",
            choices=self._mask_choices,
            nullable=True,
            tooltip="Segment only where this Labels layer is non-zero (same height x width "
            "as the stack); saturated and black samples are left out in any case",
        )
        self.mask_layer.null_string = NO_MASK
        self.mask_layer.reset_choices()
        self.mask_layer.value = None
        self.parameter_widgets = [getattr(self, name) for name in CONTROLLED]
        self._add_parameters([self.preset, *self.parameter_widgets, self.mask_layer, self.live])
        self._timer = QTimer(self.native)  # deleted with the widget: never fires after it
        self._timer.setSingleShot(True)
        self._timer.setInterval(LIVE_DELAY_MS)
        self._timer.timeout.connect(self.run)
        self.stack_layer.changed.connect(self.mask_layer.reset_choices)
        for w in [*self.parameter_widgets, self.stack_layer, self.angles, self.mask_layer]:
            w.changed.connect(self._on_value_changed)
        self.live.changed.connect(self._on_value_changed)
        self.model.changed.connect(self._on_model_changed)
        self.preset.changed.connect(self._on_preset_changed)

    # -- parameters -------------------------------------------------------------------
    def params(self) -> SegmentParams:
        """The engine parameters the widget's values describe (raises PolarsegError).

        Fields without a control (``ridge``, ``spatial_radius``, ``spatial_sigma``,
        ``ncut_threshold``) come from the chosen preset or the last :meth:`set_params`.
        """
        values = {name: getattr(self, name).value for name in CONTROLLED}
        values["fit"] = str(values["fit"])
        for name in ("window", "degree", "min_segment_blocks", "n_segments"):
            values[name] = int(values[name])
        for name in ("refractive_index", "variance", "scale"):
            values[name] = float(values[name])
        return self._base.replace(**values)

    def set_params(self, params: SegmentParams | None = None, **changes: Any) -> None:
        """Set the controls from ``params`` and/or keyword changes (SegmentParams names).

        Validated first (raises PolarsegError); with live update on, the burst of
        changes triggers one run.
        """
        values = (params or self.params()).replace(**changes)
        self._base = values
        for name in CONTROLLED:
            getattr(self, name).value = getattr(values, name)

    def _on_preset_changed(self, name: str) -> None:
        self.set_params(PRESETS[name])

    # -- mask -------------------------------------------------------------------------
    def _mask_choices(self, _widget: Any = None) -> list[tuple[str, Layer]]:
        """The user's 2-D Labels layers with the chosen stack's height x width."""
        stack = getattr(self, "stack_layer", None)
        stack = None if stack is None else stack.value
        if stack is None:
            return []
        size = tuple(stack.data.shape[-2:])
        return [
            (layer.name, layer)
            for layer in self._viewer.layers
            if isinstance(layer, Labels)
            and layer_tag(layer) is None
            and not layer.multiscale
            and layer.ndim == 2
            and tuple(layer.data.shape) == size
        ]

    def _refresh_stacks(self) -> None:
        super()._refresh_stacks()
        mask = getattr(self, "mask_layer", None)  # None while the base class initialises
        if mask is not None:
            mask.reset_choices()

    def current_mask(self) -> tuple[str | None, np.ndarray | None]:
        """Key and (H, W) bool region (a copy; True = use) of the chosen mask, or Nones."""
        layer = self.mask_layer.value
        if layer is None:
            return None, None
        if layer not in self._viewer.layers:
            raise PolarsegError(f"the mask layer {layer.name!r} is no longer in the viewer")
        return source_key(layer), np.asarray(layer.data) != 0

    def snapshot(self) -> tuple[Any, ...] | None:
        """Everything a result depends on, or None if the values are invalid."""
        layer = self.stack_layer.value
        try:
            params = self.params()
            mask_key, region = self.current_mask()
        except PolarsegError:
            return None
        key = None if layer is None else source_key(layer)
        return (key, self.angles.value, params, mask_key, region_digest(region))

    @property
    def pipeline(self) -> Pipeline | None:
        """The cached pipeline of the chosen stack layer (None before its first run)."""
        layer = self.stack_layer.value
        return None if layer is None else self.store.get(source_key(layer))

    def pipeline_for(self, layer: Layer) -> Pipeline | None:
        """The cached pipeline of ``layer`` (None before its first run)."""
        return self.store.get(source_key(layer))

    def _forget(self, keep: set[str]) -> None:
        store = getattr(self, "store", None)  # None while the base class initialises
        if store is not None:
            store.discard(keep)

    def _on_model_changed(self, model: str) -> None:
        self.specular_branch.visible = model == "specular"

    def _on_value_changed(self, *_: Any) -> None:
        if self.live.value:
            self._timer.start()  # restarts the delay: a burst of changes runs once

    def _waiting(self) -> bool:
        return self._timer.isActive()

    # -- running ----------------------------------------------------------------------
    def run(self, *_: Any) -> None:
        """Start (or queue) a run with the current values in a worker; returns at once."""
        self._timer.stop()
        try:
            layer, angles_deg = self.current_stack()
            params = self.params()
            mask_key, region = self.current_mask()
        except PolarsegError as exc:
            self._fail(exc)
            return
        key = source_key(layer)
        snap = (key, self.angles.value, params, mask_key, region_digest(region))
        t0 = time.perf_counter()
        angles_rad = np.deg2rad(angles_deg)
        args = (self.store, key, layer.data, angles_rad, params, region, mask_key)

        def on_result(run_id: int, result: Any) -> None:
            if snap != self.snapshot() or layer not in self._viewer.layers:
                self._set_status("result dropped: the parameters changed while it was computed")
                return
            self._show(layer, angles_deg, result, time.perf_counter() - t0)

        self._submit(segment_job, args, len(STAGES), on_result)

    def _show(self, layer: Layer, angles_deg: np.ndarray, result: Any, seconds: float) -> None:
        summary = result.summary()
        meta = {
            "polarseg_params": {**result.params.to_dict(), "angles_deg": angles_deg.tolist()},
            "polarseg_summary": summary,
        }
        labels = np.asarray(result.labels, dtype=np.int32) + 1  # a copy: painting is safe
        # the error map (added hidden) goes below the segments, which overlay the stack
        show_output(self._viewer, "error", np.array(result.reconstruction_error), layer, meta)
        masked = np.zeros(labels.shape, dtype=np.uint8)
        if result.valid is not None:
            masked = (~np.asarray(result.valid, dtype=bool)).astype(np.uint8)
        if self._shows_diagnostics(layer, result, masked):
            show_output(self._viewer, "residual", np.array(result.residual), layer, meta)
            show_output(self._viewer, "masked", masked, layer, meta)
        show_output(self._viewer, "segments", labels, layer, meta)
        parts = [
            f"{summary['n_segments']} segments",
            f"{summary['n_components']} PCA components "
            f"({summary['explained_variance']:.0%} variance)",
            f"mean reconstruction error {summary['mean_reconstruction_error']:.3g}",
        ]
        masked_text = mask_text(result.mask_counts)
        if masked_text:
            parts.append(masked_text)
        parts.append(f"{seconds:.2f} s")
        self._done(" · ".join(parts))

    def _shows_diagnostics(self, layer: Layer, result: Any, masked: np.ndarray) -> bool:
        """Whether to add/update ``masked pixels`` and ``fit residual`` for this result.

        From the first run that leaves a pixel out or fits robustly on; once they exist
        they are updated on every run (so they never show a stale mask).
        """
        if result.params.fit != "lsq" or bool(masked.any()):
            return True
        return any(find_output(self._viewer, r, layer) is not None for r in ("masked", "residual"))
