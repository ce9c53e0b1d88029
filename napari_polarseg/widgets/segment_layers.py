"""The Segment widget's output layers: what a result adds to the viewer (segments,
error map, diagnostics, class probability and uncertainty, the HSV and Stokes views),
and which result a stack's segments show (:func:`result_on_screen`)."""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import CheckBox

from ..engine.physics.stokes import stokes_components
from ._layers import (
    Contrast,
    contrasts_of,
    find_output,
    name_labels,
    remove_output,
    show_output,
    source_key,
)
from .layer_queue import LayerQueue
from .session import ClassifierOutput, Result, ShownResult, shown_result
from .session.stable_labels import keep_numbers
from .session.state import Prediction, SegmentState, ShownEntry
from .views import VIEW_OUTPUTS, composite_for, view_mode_box

if TYPE_CHECKING:
    from napari.layers import Layer

    from ..engine import SegmentationResult


def result_on_screen(state: SegmentState, viewer: Any, layer: Layer) -> ShownEntry | None:
    """The state's entry for the result ``layer``'s ``segments`` layer shows (None: no
    result of this dock, or another widget has written the layer since)."""
    entry = state.shown.get(source_key(layer))
    segments = find_output(viewer, "segments", layer)
    if entry is None or segments is None:
        return None
    if segments.metadata.get("polarseg_inputs") != entry.inputs:
        return None  # another widget has written the layer since
    return entry


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
    what a result adds to the viewer, and the *HSV and Stokes layers* option with its
    *HSV view* menu.

    It writes to the dock's state which result each stack shows
    (``SegmentState.show`` once a run completes, ``show_partial`` for the segments
    shown before) and the classifier's prediction; once the runs have ended, a stack
    whose segments show a run that never completed shows its last completed result
    again (:meth:`settle`): every layer then comes from one set of parameters.

    Parameters
    ----------
    state : SegmentState
        The dock's state (the chosen stack, the results shown).
    viewer : napari.viewer.Viewer
    later : LayerQueue
        The widget's queue of layers added one per event-loop turn.
    set_status, done : callable
        The widget's status line (``done``: a run's last word).
    """

    def __init__(
        self,
        state: SegmentState,
        viewer: Any,
        later: LayerQueue,
        set_status: Callable[[str], None],
        done: Callable[[str], None],
    ) -> None:
        self._state, self._viewer, self._later = state, viewer, later
        self._set_status, self._done = set_status, done
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
        snapshot of the controls the run was requested with. A classifier's output comes
        with its materials named (``SegmentInputs.named``).
        """
        shown = shown_result(result, angles_deg, inputs, partial)
        if not shown.partial:
            self._show_complete(layer, shown, contrast or {})
        self._show_prediction(layer, shown, shown.meta)
        self._show_segments(layer, shown.labels, shown.meta, shown.result.materials)
        if shown.partial:
            self._state.show_partial(source_key(layer))
            self._set_status(shown.status(seconds))
            return
        self._state.show(source_key(layer), ShownEntry(layer, angles_deg, shown, snap))
        self._done(shown.status(seconds))

    def keep_colours(self, layer: Layer, result: Any) -> Any:
        """``result`` with its segments renumbered after those ``layer``'s segments
        layer shows, so that a segment that survives a rerun keeps its number and colour
        (:func:`~.session.stable_labels.keep_numbers`; a classifier's output as it is)."""
        if isinstance(result, ClassifierOutput):
            return result
        segments = find_output(self._viewer, "segments", layer)
        return keep_numbers(result, None if segments is None else np.asarray(segments.data))

    def _show_segments(
        self, layer: Layer, labels: np.ndarray, meta: dict[str, Any], materials: Any = None
    ) -> None:
        """``labels`` in ``layer``'s segments layer (its data kept when equal), with the
        names of a classifier's ``materials`` shown on hover (:func:`~._layers.name_labels`)."""
        segments = find_output(self._viewer, "segments", layer)
        if segments is not None and np.array_equal(segments.data, labels):
            # e.g. the partial result already shows these labels: keep the data (no redraw)
            segments.metadata = {**segments.metadata, **meta}
        else:
            segments = show_output(self._viewer, "segments", labels, layer, meta)
        names = (
            {} if materials is None else dict(zip(materials.values, materials.names, strict=True))
        )
        name_labels(segments, names)

    def _show_prediction(self, layer: Layer, shown: ShownResult, meta: dict[str, Any]) -> None:
        """The classifier's class probability and uncertainty layers (queued), or their
        removal after an unsupervised run; the state's prediction follows."""
        out = shown.out
        if out is not None and out.preview:
            return  # the grid's labels: the probability and uncertainty maps follow
        if out is None:
            for role in ("probability", "uncertainty"):  # they would be stale
                self._queue(role, layer, lambda role=role: remove_output(self._viewer, role, layer))
            self._state.set_prediction(Prediction())
            return
        prediction = out.prediction
        # hidden maps with fixed limits: added in later turns, after the segments
        maps = (("probability", shown.confidence), ("uncertainty", prediction.uncertainty))
        for role, data in maps:
            self._queue(
                role,
                layer,
                lambda role=role, data=data: self._show_below_segments(role, data, layer, meta),
            )
        self._state.set_prediction(
            Prediction(prediction.probabilities, prediction.classes, prediction.uncertainty)
        )

    def settle(self) -> None:
        """The runs have ended: every stack whose segments show a run that never
        completed (cancelled, failed, or its result dropped) shows its last completed
        result again, so its segments, error map and other layers come from one set of
        parameters (without a completed result, the segments stay: the only layer)."""
        viewer = self._viewer
        for key in self._state.take_partial():
            entry = self._state.shown.get(key)
            if entry is None or entry.layer not in viewer.layers:
                continue
            if find_output(viewer, "segments", entry.layer) is None:
                continue  # removed by the user: not brought back
            meta = entry.metadata
            self._show_prediction(entry.layer, entry.shown, meta)
            self._show_segments(entry.layer, entry.shown.labels, meta, entry.result.materials)

    def prepare_segments(self, live: bool) -> None:
        """With ``live`` update on and a scribbles layer chosen, add the chosen stack's
        segments layer, empty (all 0: transparent), if it has none: made while the first
        strokes are painted, the first labels then only replace its data (napari takes
        about 0.3 s to add a Labels layer to a camera frame's viewer)."""
        viewer, inputs = self._viewer, self._state.inputs
        layer = inputs.stack
        if not live or inputs.scribbles is None or layer is None:
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
        layer = self._state.inputs.stack
        shown = None if layer is None else self._state.shown.get(source_key(layer))
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
