"""The Segment widget's output layers: what a result adds to the viewer (segments,
error map, diagnostics, class probability and uncertainty, the HSV and Stokes views)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import CheckBox

from ..engine.physics.stokes import stokes_components
from ._base import WidgetPart
from ._layers import find_output, remove_output, show_output, source_key
from .session import ClassifierOutput, ShownResult, shown_result
from .views import VIEW_OUTPUTS, composite_for, view_mode_box

if TYPE_CHECKING:
    from napari.layers import Layer

    from ..engine import SegmentationResult


@dataclass(frozen=True)
class ShownEntry:
    """What a stack's ``segments`` layer shows: the result, the inputs it used (the
    layer's ``polarseg_inputs``) and the snapshot of the controls it was made with."""

    result: SegmentationResult
    inputs: dict[str, Any]
    snap: Any = None


class ResultLayers(WidgetPart):
    """Mixin of :class:`~napari_polarseg.widgets.segment.SegmentWidget`: the layers of
    its results and the *HSV and Stokes layers* option.

    Uses the widget's viewer, stack chooser, the shown results (``_shown``), its
    classifier and export parts (``classifier_files``, ``export``; their ``record``) and
    its status line.
    """

    _shown: dict[str, ShownEntry]
    classifier_files: Any
    export: Any

    def _build_view_controls(self) -> None:
        """*HSV and Stokes layers* and the *HSV view* menu; the last result's arrays."""
        #: Class probabilities (K, H, W) of the last scribble run shown, and the
        #: scribble label of each class (None after an unsupervised run).
        self.probabilities: np.ndarray | None = None
        self.classes: np.ndarray | None = None
        #: Uncertainty (H, W) of the last scribble run shown (None after an unsupervised run).
        self.uncertainty: np.ndarray | None = None
        #: Per stack key: the fit residual the diagnostics layers show (the cached
        #: polarisation image's array: the same object while the image is unchanged).
        self._diagnostics: dict[str, Any] = {}
        self.views = CheckBox(
            text="HSV and Stokes layers",
            value=False,
            tooltip="Also add the AoLP/DoLP HSV view and the S0, S1, S2 Stokes layers "
            "(hidden) of each result, as the Polarisation image widget does",
        )
        self.view_mode = view_mode_box()

    def _show(
        self,
        layer: Layer,
        angles_deg: np.ndarray,
        result: SegmentationResult | ClassifierOutput,
        seconds: float,
        inputs: dict[str, Any] | None = None,
        partial: bool = False,
        snap: Any = None,
    ) -> None:
        """Show a run's layers and summary.

        A ``partial`` result (no reconstruction yet: the worker yielded it before its last
        stage) updates the segments (and class probability, uncertainty) layers and the
        status line only; the complete result that follows updates the rest. Labels equal
        to those already shown only update the segments' metadata. ``snap``: the
        snapshot of the controls the run was requested with.
        """
        shown = shown_result(result, angles_deg, inputs, partial)
        meta, out = shown.meta, shown.out
        if not shown.partial:
            self._show_complete(layer, shown)
        if out is not None and out.preview:
            pass  # the grid's labels: the probability and uncertainty maps follow
        elif out is not None:
            prediction = out.prediction
            self._show_below_segments("probability", shown.confidence, layer, meta)
            self._show_below_segments("uncertainty", prediction.uncertainty, layer, meta)
            self.probabilities, self.classes = prediction.probabilities, prediction.classes
            self.uncertainty = prediction.uncertainty
        else:
            for role in ("probability", "uncertainty"):  # they would be stale
                remove_output(self._viewer, role, layer)
            self.probabilities, self.classes, self.uncertainty = None, None, None
        segments = find_output(self._viewer, "segments", layer)
        if segments is not None and np.array_equal(segments.data, shown.labels):
            # e.g. the partial result already shows these labels: keep the data (no redraw)
            segments.metadata = {**segments.metadata, **meta}
        else:
            show_output(self._viewer, "segments", shown.labels, layer, meta)
        if shown.partial:
            self._set_status(shown.status(seconds))
            return
        self._shown[source_key(layer)] = ShownEntry(shown.result, shown.inputs, snap)
        self.classifier_files.record(layer, None if out is None else out.classifier)
        self.export.record(layer, angles_deg, shown)
        self._done(shown.status(seconds))

    def _show_complete(self, layer: Layer, shown: ShownResult) -> None:
        """The layers of a complete result below the segments: the error map, the
        diagnostics (masked pixels, fit residual) and the HSV and Stokes views."""
        result, meta = shown.result, shown.meta
        if result.reconstruction_error is None:
            # a run without the thesis maps: an error map of earlier parameters would
            # pass for this result's
            remove_output(self._viewer, "error", layer)
        else:
            # the error map (added hidden) goes below the segments, which overlay the stack
            error = np.array(result.reconstruction_error)
            self._show_below_segments("error", error, layer, meta)
        masked = shown.masked()
        if self._shows_diagnostics(layer, result, masked):
            self._show_diagnostics(layer, result, masked, meta)
        if self.views.value:
            self._show_views(layer, result, meta)

    def _show_below_segments(self, role: str, data: np.ndarray, layer: Layer, meta: dict) -> None:
        """Add/update the ``role`` layer; a new one goes just below the segments (which a
        partial result may have shown first), an existing one keeps its place."""
        new = find_output(self._viewer, role, layer) is None
        shown = show_output(self._viewer, role, data, layer, meta)
        segments = find_output(self._viewer, "segments", layer)
        if new and segments is not None:
            layers = self._viewer.layers
            below = layers.index(segments)
            if layers.index(shown) > below:
                layers.move(layers.index(shown), below)

    def _show_diagnostics(
        self, layer: Layer, result: Any, masked: np.ndarray, meta: dict[str, Any]
    ) -> None:
        """Add/update ``fit residual`` and ``masked pixels``; when both show the same
        polarisation image already (a rerun that changed e.g. only the number of
        segments), only their metadata follow."""
        key, roles = source_key(layer), ("residual", "masked")
        found = [find_output(self._viewer, role, layer) for role in roles]
        if self._diagnostics.get(key) is result.residual and all(found):
            for shown in found:
                shown.metadata = {**shown.metadata, **meta}
            return
        self._show_below_segments("residual", np.array(result.residual), layer, meta)
        self._show_below_segments("masked", masked, layer, meta)
        self._diagnostics[key] = result.residual

    def _shows_diagnostics(self, layer: Layer, result: Any, masked: np.ndarray) -> bool:
        """Whether to add/update ``masked pixels`` and ``fit residual`` for this result.

        From the first run that leaves a pixel out or fits robustly on; once they exist
        they are updated on every run (so they never show a stale mask).
        """
        if result.params.fit != "lsq" or bool(masked.any()):
            return True
        return any(find_output(self._viewer, r, layer) is not None for r in ("masked", "residual"))

    def _on_views_changed(self, *_: Any) -> None:
        """Draw the views of the chosen stack's shown result at once (no rerun)."""
        layer = self.stack_layer.value
        shown = None if layer is None else self._shown.get(source_key(layer))
        if self.views.value and shown is not None and layer in self._viewer.layers:
            segments = find_output(self._viewer, "segments", layer)
            meta = (
                {}
                if segments is None
                else {"polarseg_params": segments.metadata.get("polarseg_params")}
            )
            self._show_views(layer, shown.result, meta)

    def _show_views(self, layer: Layer, result: SegmentationResult, meta: dict) -> None:
        """The S0, S1, S2 Stokes layers (hidden) and the AoLP/DoLP HSV view of ``result``
        in the chosen *HSV view* (:data:`~napari_polarseg.widgets.views.VIEW_MODES`),
        below the segments; the Polarisation image widget shares these layers."""
        arrays = (np.asarray(result.intensity), np.asarray(result.dop), np.asarray(result.phase))
        for role, data in zip(VIEW_OUTPUTS[:-1], stokes_components(*arrays), strict=True):
            self._show_below_segments(role, data, layer, meta)
        mode = str(self.view_mode.value)
        rgb, rho_max = composite_for(*arrays, 0.0, mode)
        composite = {"polarseg_composite": {"dolp_max": rho_max, "mode": mode}}
        self._show_below_segments("hsv", rgb, layer, {**meta, **composite})
