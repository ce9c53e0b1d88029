"""The Segment widget's output layers: what a result adds to the viewer (segments,
error map, diagnostics, class probability and uncertainty, the HSV and Stokes views)."""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import CheckBox

from ..engine.physics.stokes import stokes_components
from ._layers import Contrast, contrasts_of, find_output, remove_output, show_output, source_key
from .layer_queue import LayerQueue
from .session import ClassifierOutput, Result, ShownResult, named_output, shown_result
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


@dataclass(frozen=True)
class WithContrast:
    """A job's result and the contrast of its image maps, computed in the worker
    (:func:`with_contrast`): showing it runs no percentile on the GUI thread."""

    value: Any
    contrast: dict[str, Contrast] = field(default_factory=dict)


#: Per role, the last map :func:`result_contrast` measured and its contrast: a rerun that
#: keeps the map (e.g. only the number of segments changed) reuses it.
ContrastMemo = dict[str, tuple[np.ndarray, Contrast]]


def result_contrast(value: Any, memo: ContrastMemo | None = None) -> WithContrast:
    """``value`` (a SegmentationResult or a ClassifierOutput) with the contrast of its
    error map and fit residual (:func:`~._layers.contrast_of`; from ``memo`` for the
    very array measured last time); none for a classifier output that reports a problem
    (it has no result)."""
    if getattr(value, "problem", None) is not None:
        return WithContrast(value)
    result = getattr(value, "result", value)
    arrays = {
        "error": getattr(result, "reconstruction_error", None),
        "residual": getattr(result, "residual", None),
    }
    memo = {} if memo is None else memo
    contrast = {}
    for role, data in arrays.items():
        if data is None:
            continue
        kept = memo.get(role)
        if kept is None or kept[0] is not data:
            kept = memo[role] = (data, contrasts_of({role: data})[role])
        contrast[role] = kept[1]
    return WithContrast(value, contrast)


def with_contrast(
    job: Callable[..., Generator[Any, Any, Any]], memo: ContrastMemo | None = None
) -> Callable[..., Any]:
    """The worker ``job`` whose result (returned, or yielded as a
    :class:`~.session.Result` before idle-time work) comes as a :class:`WithContrast`
    (``memo``: see :func:`result_contrast`); its stages and partial results pass as they
    are."""

    def wrapped(*args: Any, **kwargs: Any) -> Generator[Any, Any, Any]:
        gen = job(*args, **kwargs)
        sent: Any = None
        try:
            while True:
                try:
                    item = gen.send(sent)
                except StopIteration as stop:
                    return result_contrast(stop.value, memo)
                if isinstance(item, Result):
                    item = Result(result_contrast(item.value, memo))
                sent = yield item
        finally:
            gen.close()

    return wrapped


class SegmentLayers:
    """The Segment widget's output layers, a part the widget holds (``widget.layers``):
    what a result adds to the viewer, the results shown per stack (:attr:`shown`), and
    the *HSV and Stokes layers* option with its *HSV view* menu.

    Parameters
    ----------
    owner : SegmentWidget
        What the part reads of the widget, by its public members: the ``stack_layer``
        chooser, the ``inputs`` part (the named materials), and the
        ``classifier_files`` and ``export`` parts (told of every result shown).
    viewer : napari.viewer.Viewer
    later : LayerQueue
        The widget's queue of layers added one per event-loop turn.
    set_status, done : callable
        The widget's status line (``done``: a run's last word).
    """

    def __init__(
        self,
        owner: Any,
        viewer: Any,
        later: LayerQueue,
        set_status: Callable[[str], None],
        done: Callable[[str], None],
    ) -> None:
        self._owner, self._viewer, self._later = owner, viewer, later
        self._set_status, self._done = set_status, done
        #: Per stack key: the result behind the stack's ``segments`` layer.
        self.shown: dict[str, ShownEntry] = {}
        #: Class probabilities (K, H, W) of the last scribble run shown, and the
        #: scribble label of each class (None after an unsupervised run).
        self.probabilities: np.ndarray | None = None
        self.classes: np.ndarray | None = None
        #: Uncertainty (H, W) of the last scribble run shown (None after an unsupervised run).
        self.uncertainty: np.ndarray | None = None
        #: Per stack key: the fit residual the diagnostics layers show (the cached
        #: polarisation image's array: the same object while the image is unchanged).
        self._diagnostics: dict[str, Any] = {}
        #: The contrast of the maps the last worker measured (only workers touch it; one
        #: runs at a time), reused while a map is the same array.
        self.contrast_memo: ContrastMemo = {}
        self.views = CheckBox(
            text="HSV and Stokes layers",
            value=False,
            tooltip="Also add the AoLP/DoLP HSV view and the S0, S1, S2 Stokes layers "
            "(hidden) of each result, as the Polarisation image widget does",
        )
        self.view_mode = view_mode_box()
        self.views.changed.connect(self.on_views_changed)
        self.view_mode.changed.connect(self.on_views_changed)

    def show(
        self,
        layer: Layer,
        angles_deg: np.ndarray,
        result: SegmentationResult | ClassifierOutput,
        seconds: float,
        inputs: dict[str, Any] | None = None,
        partial: bool = False,
        snap: Any = None,
        contrast: dict[str, Contrast] | None = None,
    ) -> None:
        """Show a run's layers and summary.

        The segments are shown at once; the other layers (class probability and
        uncertainty, and those of a complete result) are added one per event-loop turn
        (``_later``), with the contrast the worker computed (``contrast``,
        :func:`with_contrast`).

        A ``partial`` result (no reconstruction yet: the worker yielded it before its last
        stage) updates the segments (and class probability, uncertainty) layers and the
        status line only; the complete result that follows updates the rest. Labels equal
        to those already shown only update the segments' metadata. ``snap``: the
        snapshot of the controls the run was requested with.
        """
        if isinstance(result, ClassifierOutput) and result.segmentation is not None:
            # a loaded classifier's names name the strokes' materials that have none; the
            # list's names name the result (its plots, export, saved classifier)
            inputs_part = self._owner.inputs
            inputs_part.materials.adopt(dict(zip(*_values_names(result), strict=True)))
            result = named_output(result, inputs_part.material_names())
        shown = shown_result(result, angles_deg, inputs, partial)
        meta, out = shown.meta, shown.out
        if not shown.partial:
            self._show_complete(layer, shown, contrast or {})
        if out is not None and out.preview:
            pass  # the grid's labels: the probability and uncertainty maps follow
        elif out is not None:
            prediction = out.prediction
            # hidden maps with fixed limits: added in later turns, after the segments
            for role, data in (
                ("probability", shown.confidence),
                ("uncertainty", prediction.uncertainty),
            ):
                self._queue(
                    role,
                    layer,
                    lambda role=role, data=data: self._show_below_segments(role, data, layer, meta),
                )
            self.probabilities, self.classes = prediction.probabilities, prediction.classes
            self.uncertainty = prediction.uncertainty
        else:
            for role in ("probability", "uncertainty"):  # they would be stale
                self._queue(role, layer, lambda role=role: remove_output(self._viewer, role, layer))
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
        self.shown[source_key(layer)] = ShownEntry(shown.result, shown.inputs, snap)
        self._owner.classifier_files.record(layer, None if out is None else out.classifier)
        self._owner.export.record(layer, angles_deg, shown)
        self._done(shown.status(seconds))

    def prepare_segments(self, *_: Any) -> None:
        """With live update on and a scribbles layer chosen, add the chosen stack's
        segments layer, empty (all 0: transparent), if it has none: made while the first
        strokes are painted, the first labels then only replace its data (napari takes
        about 0.3 s to add a Labels layer to a camera frame's viewer)."""
        owner, viewer = self._owner, self._viewer
        layer = owner.stack_layer.value
        if not owner.live.value or owner.scribbles_layer.value is None or layer is None:
            return
        if layer in viewer.layers and find_output(viewer, "segments", layer) is None:
            show_output(viewer, "segments", np.zeros(layer.data.shape[-2:], np.int32), layer)

    def _queue(self, role: str, layer: Layer, action: Callable[[], Any]) -> None:
        """Run ``action`` (which adds or updates ``layer``'s ``role`` layer) in a later
        event-loop turn, if ``layer`` is still in the viewer then; it replaces an action
        of the same role and stack still pending (an older result's)."""
        viewer = self._viewer

        def when_present() -> None:
            if layer in viewer.layers:
                action()

        self._later.put((role, source_key(layer)), when_present)

    def _show_complete(
        self, layer: Layer, shown: ShownResult, contrast: dict[str, Contrast]
    ) -> None:
        """The layers of a complete result below the segments, one per event-loop turn:
        the error map, the diagnostics (masked pixels, fit residual) and the HSV and
        Stokes views."""
        result, meta = shown.result, shown.meta
        if result.reconstruction_error is None:
            # a run without the thesis maps: an error map of earlier parameters would
            # pass for this result's
            self._queue("error", layer, lambda: remove_output(self._viewer, "error", layer))
        else:
            # the error map (added hidden) goes below the segments, which overlay the stack
            error = np.asarray(result.reconstruction_error)
            self._queue(
                "error",
                layer,
                lambda: self._show_below_segments(
                    "error", error, layer, meta, contrast.get("error")
                ),
            )
        masked = shown.masked()
        if self._shows_diagnostics(layer, result, masked):
            self._show_diagnostics(layer, result, masked, meta, contrast.get("residual"))
        if self.views.value:
            self._show_views(layer, result, meta)

    def _show_below_segments(
        self,
        role: str,
        data: np.ndarray,
        layer: Layer,
        meta: dict,
        contrast: Contrast | None = None,
    ) -> None:
        """Add/update the ``role`` layer; a new one goes just below the segments (which a
        partial result may have shown first), an existing one keeps its place."""
        new = find_output(self._viewer, role, layer) is None
        shown = show_output(self._viewer, role, data, layer, meta, contrast)
        segments = find_output(self._viewer, "segments", layer)
        if new and segments is not None:
            layers = self._viewer.layers
            below = layers.index(segments)
            if layers.index(shown) > below:
                layers.move(layers.index(shown), below)

    def _show_diagnostics(
        self,
        layer: Layer,
        result: Any,
        masked: np.ndarray,
        meta: dict[str, Any],
        contrast: Contrast | None = None,
    ) -> None:
        """Add/update ``fit residual`` and ``masked pixels`` (queued, one per turn);
        when both show the same polarisation image already (a rerun that changed e.g.
        only the number of segments), only their metadata follow."""
        key, roles = source_key(layer), ("residual", "masked")
        found = [find_output(self._viewer, role, layer) for role in roles]
        if self._diagnostics.get(key) is result.residual and all(found):
            for shown in found:
                shown.metadata = {**shown.metadata, **meta}
            return
        residual = np.asarray(result.residual)
        self._queue(
            "residual",
            layer,
            lambda: self._show_below_segments("residual", residual, layer, meta, contrast),
        )
        self._queue(
            "masked", layer, lambda: self._show_below_segments("masked", masked, layer, meta)
        )
        self._diagnostics[key] = result.residual

    def _shows_diagnostics(self, layer: Layer, result: Any, masked: np.ndarray) -> bool:
        """Whether to add/update ``masked pixels`` and ``fit residual`` for this result.

        From the first run that leaves a pixel out or fits robustly on; once they exist
        they are updated on every run (so they never show a stale mask).
        """
        if result.params.fit != "lsq" or bool(masked.any()):
            return True
        return any(find_output(self._viewer, r, layer) is not None for r in ("masked", "residual"))

    def on_views_changed(self, *_: Any) -> None:
        """Draw the views of the chosen stack's shown result at once (no rerun)."""
        layer = self._owner.stack_layer.value
        shown = None if layer is None else self.shown.get(source_key(layer))
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
            self._queue(
                role,
                layer,
                lambda role=role, data=data: self._show_below_segments(role, data, layer, meta),
            )
        mode = str(self.view_mode.value)

        def composite() -> None:
            rgb, rho_max = composite_for(*arrays, 0.0, mode)
            how = {"polarseg_composite": {"dolp_max": rho_max, "mode": mode}}
            self._show_below_segments("hsv", rgb, layer, {**meta, **how})

        self._queue("hsv", layer, composite)


def _values_names(out: ClassifierOutput) -> tuple[tuple[int, ...], tuple[str, ...]]:
    """The scribble values and names of a classifier output's materials."""
    materials = out.classifier.materials()
    return materials.values, materials.names
