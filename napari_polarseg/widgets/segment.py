"""The "Segment by material" widget: the cached engine pipeline, run in a worker thread.

Thin: the jobs, pipelines and result texts are the session layer
(:mod:`napari_polarseg.widgets.session`). One state holds what the dock knows
(:attr:`SegmentWidget.state`, a
:class:`~napari_polarseg.widgets.session.state.SegmentState`: parameters, inputs,
results shown, loaded classifier, exports); the widget's parts read and write it and
listen to its signals, none reaches another through the widget:
:attr:`SegmentWidget.controls` (the parameters), :attr:`SegmentWidget.inputs` (mask,
scribbles, materials, the :class:`Snapshot` of a request), :attr:`SegmentWidget.layers`
(the output layers), :attr:`SegmentWidget.classifier_files`,
:attr:`SegmentWidget.export` and :attr:`SegmentWidget.assist`. The public members
scripts and tests use are :class:`~napari_polarseg.widgets.segment_members.SegmentMembers`.
This module builds the widget and runs it.
"""

from __future__ import annotations

import contextlib
import functools
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import CheckBox, Container
from qtpy.QtCore import QTimer

from ..engine import PolarsegError, SegmentationResult
from ..engine.params import PRESETS, ParamSpec
from ._base import SEGMENT_DOCK_NAME, StackWidget
from ._layers import find_output, source_key
from .dock_layout import release_dock_minimum
from .docks import SegmentDock
from .param_controls import controlled_names, every_param_spec
from .raw_mosaic import MosaicInput
from .segment_assist import ScribbleAssist
from .segment_files import ClassifierFiles, ResultExport
from .segment_inputs import NO_MASK, NO_SCRIBBLES, SegmentInputs, Snapshot
from .segment_layers import SegmentLayers, WithContrast, result_on_screen, with_contrast
from .segment_members import SegmentMembers
from .segment_params import CUT_ONLY, ParameterControls
from .session import (
    FEATURES_JOB_STAGES,
    ClassifierOutput,
    Delivery,
    LoadedClassifier,
    PipelineStore,
    colour_stack_of,
    features_job,
    input_info,
    scribble_problem,
    segment_request,
)
from .session.state import SegmentState, ShownEntry

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

# Names importers take from this module (tests, benchmarks): defined beside the parts.
__all__ = [
    "CONTROLLED",
    "CUT_ONLY",
    "FIRST_CONTROLS",
    "LIVE_DELAY_MS",
    "STROKE_DELAY_MS",
    "NO_MASK",
    "NO_SCRIBBLES",
    "PRESETS",
    "SegmentWidget",
    "Snapshot",
]

#: Milliseconds the live update waits after the last change of a control before it
#: reruns (a slider dragged or a number typed: a burst of changes runs once).
LIVE_DELAY_MS = 150

#: Milliseconds the live update waits after a stroke (or new data) in the chosen mask or
#: scribbles layer: napari reports a brush stroke once, at the mouse release, so the
#: rerun starts in the next event-loop turn (the stroke's events of that turn run once).
STROKE_DELAY_MS = 0

#: Parameters with a control in the widget (labelled specs of the shared table and of
#: the methods registered when this module is imported); the others: from the preset.
CONTROLLED = controlled_names(every_param_spec())

#: Parameter controls shown above the collapsed *advanced settings* section.
FIRST_CONTROLS = ("n_segments",)


class SegmentWidget(SegmentMembers, StackWidget, SegmentDock):
    """Segment an angle stack by material (thesis section 4.5) with live parameters.

    Controls: a preset (thesis values or the recommended ones), *Load parameters…* and
    *Save parameters…* (the JSON of ``polarseg segment --params``), window size w,
    harmonic degree L, refractive index n, Fresnel model (and specular branch),
    coefficient estimator, block features, PCA variance share, affinity scale s and its
    mode, clustering (recursive two-way cuts or k-way spectral), minimum segment size,
    number of segments, the sinusoid fit (least squares or robust), a mask (none, or a
    Labels layer of the stack's height x width: non-zero = segment the pixel) and
    scribbles (none = unsupervised, or a Labels layer of strokes, 1, 2, … = materials:
    the pixel classifier trained on the strokes replaces the normalized cut);
    *New scribbles layer*; *Load classifier…*, *Save classifier…* and *Clear classifier*
    (:meth:`load_classifier`, :meth:`save_classifier`, :meth:`clear_classifier`: the
    ``.polarseg-clf`` files of ``polarseg segment --classifier / --save-classifier``);
    Run and Cancel; a live-update toggle that reruns after every change, including every
    stroke painted into the chosen mask or scribbles layer; *Export results…*
    (:meth:`export_results`: the chosen stack's last result as the folder ``polarseg
    segment --out`` writes). The stack, the angles, the preset, the number of segments,
    the scribbles, live update, Run and Cancel show at first; the *advanced settings*
    check box shows the rest (:attr:`advanced`, collapsed by default). The dock scrolls
    (:class:`~napari_polarseg.widgets._base.ScrollingContainer`).
    Saturated samples (at the integer dtype's maximum) and black ones (at or below 0)
    are always left out of the fit and counted in the status line.

    One :class:`~napari_polarseg.engine.Pipeline` is kept per stack layer, so a rerun
    computes only what a change made stale; beside it a
    :class:`~napari_polarseg.engine.ScribbleSession` keeps the stack's pixel features, so
    a stroke only retrains the classifier and predicts again (a newer request stops it
    between chunks). A loaded classifier applies until the strokes change or it is
    cleared. The mask is read at every run. At most one worker runs at a time.

    Output layers (replaced in place on a rerun): ``segments`` (Labels, one label per
    segment over every pixel; segment k of the engine is label k + 1 because napari
    draws label 0 as transparent background; with scribbles, each pixel gets the label
    of the scribbled material the classifier chose, so segments and strokes share their
    colours) and, when the run computes the thesis maps (the thesis method always, the
    others with *thesis maps and error map*, ``SegmentState.maps``), ``reconstruction
    error`` (Image, per-pixel |Î rebuilt from the block harmonics − Î|, added hidden
    below the segments; its mean is in the status line; removed by a run without them).
    Once a run leaves pixels out (mask, saturated, black) or uses the robust fit, also
    ``masked pixels`` (Labels, 1 where a pixel was left out of the fit and the features)
    and ``fit residual`` (Image, RMS residual of the per-pixel sinusoid fit), both added
    hidden and updated on every later run. With scribbles (or a loaded classifier), also
    ``class probability`` (Image, hidden: the classifier's probability of the chosen
    class, 1/K … 1, low where it hesitates between materials) and ``uncertainty``
    (Image, hidden: 1 − (p1 − p2), one minus the margin between the two most probable
    classes, 0 sure … 1 a tie: where another stroke helps most); the probabilities of
    every class are ``probabilities`` (K, H, W) with their labels in
    ``classes``, the uncertainty is ``uncertainty``. With *HSV and Stokes layers*
    (advanced) also ``S0/S1/S2 Stokes`` (hidden) and ``AoLP/DoLP HSV`` in the chosen *HSV
    view* (with intensity, light, or dark: value from ρ, black where unpolarised), the
    layers the *Polarisation image* widget shares; changing the view redraws them only.
    A docked *Polarisation plots* widget is handed every new classifier (its feature
    importances).

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers the widget reads and writes.
    """

    dock_title = "Segment"
    run_text = "Run"
    run_tooltip = (
        "Segment the chosen stack by material with the parameters below (or the "
        "scribbles) and add the segments (and, with the thesis maps, the "
        "reconstruction-error map) as layers"
    )
    progress_desc = "Segment by material"
    lists_raw_mosaics = True  # a raw camera frame is decoded first (``MosaicInput``)

    def __init__(
        self, viewer: napari.viewer.Viewer, specs: dict[str, ParamSpec] | None = None
    ) -> None:
        #: The dock's one state: what the parts read, write and listen to.
        self.state = state = SegmentState()
        super().__init__(viewer)
        self.store = PipelineStore()
        self._force = False  # a control changed: the next live run is not skipped
        self._live_run = False  # run() was called by the live update
        self._features_later = False  # pixel features put off while a run computes
        status, fail, parent = self._set_status, self._fail, lambda: self.native
        #: The parts: the parameters, the inputs beside the stack, the output layers,
        #: the classifier files, *Export results…* and the scribble helpers.
        self.controls = ParameterControls(specs, state, status, fail, parent)
        self.inputs = SegmentInputs(
            state, viewer, self.store, self._labels_box, status, fail, self.prefetch_features
        )
        self.layers = SegmentLayers(state, viewer, self._later, status, self._done)
        self.classifier_files = ClassifierFiles(
            state, viewer, parent, status, fail, self._on_value_changed, self.run
        )
        self.export = ResultExport(state, self.store, parent, status, fail)
        self.assist = ScribbleAssist(state, self.inputs, viewer, status, fail)
        self.mosaic = MosaicInput(viewer, self.stack_layer, self._submit, self.run, status)
        self.live = CheckBox(
            text="live update",
            value=False,
            tooltip="Rerun (only the stale stages) whenever a value changes or a stroke is "
            "painted into the chosen mask or scribbles layer",
        )
        self._lay_out()
        self.native.setObjectName(SEGMENT_DOCK_NAME)  # the others open as its tabs
        self._timer = QTimer(self.native)  # deleted with the widget: never fires after it
        self._timer.setSingleShot(True)
        self._timer.setInterval(LIVE_DELAY_MS)
        self._timer.timeout.connect(self._on_timer)
        self._connect()
        self._write_stack()

    def _lay_out(self) -> None:
        """The first controls, then the collapsed *advanced settings*; Export after Run."""
        # the few controls a user touches first stay in view; the rest (every parameter
        # the preset sets, the mask, the files) sit in the collapsed "advanced" section
        self.advanced = Container(
            widgets=[
                self.controls.params_file,
                *(self.controls.controls[n] for n in self.controlled if n not in FIRST_CONTROLS),
                self.controls.thesis_maps,
                self.inputs.mask_layer,
                self.classifier_files.classifier_file,
                self.inputs.classifier_controls,
                self.layers.views,
                self.layers.view_mode,
            ],
            labels=True,
            label="",
            visible=False,
        )
        self.advanced.margins = (0, 0, 0, 0)
        self.show_advanced = CheckBox(
            text="advanced settings",
            value=False,
            tooltip="Show every parameter of the pipeline (the preset sets them), the thesis "
            "maps option, the mask, and the parameter and classifier files",
        )
        inputs = self.inputs
        self._add_parameters(
            [
                self.mosaic.layout,
                self.controls.preset,
                *(self.controls.controls[name] for name in FIRST_CONTROLS),
                inputs.scribbles_layer,
                inputs.new_scribbles_button,
                inputs.materials,
                self.assist.buttons,
                self.live,
                self.show_advanced,
                self.advanced,
            ]
        )
        self.footer.insert(self.footer.index(self.progress), self.export.export_button)

    def _connect(self) -> None:
        """Connect the controls and the state's signals to the widget's handlers (the
        parts connect their own)."""
        inputs, state = self.inputs, self.state
        self.show_advanced.changed.connect(self._on_show_advanced)
        self.stack_layer.changed.connect(inputs.reset_choices)
        self.stack_layer.changed.connect(self._write_stack)
        self.angles.changed.connect(self._write_stack)
        watched = [self.stack_layer, self.angles, inputs.mask_layer, inputs.scribbles_layer]
        for w in [*self.controls.parameter_widgets, self.controls.thesis_maps, *watched]:
            w.changed.connect(self._on_value_changed)
        for w in inputs.classifier_controls.controls:
            w.changed.connect(self._on_value_changed)
        self.live.changed.connect(self._on_live_toggled)
        self.live.changed.connect(self._prepare_segments)
        inputs.scribbles_layer.changed.connect(self.prefetch_features)
        state.edited.connect(self.schedule_live_run)

    def _write_stack(self, *_: Any) -> None:
        """Write the chosen stack and the angles typed to the state."""
        self.state.set_inputs(stack=self.stack_layer.value, angles=self.angles.value)

    def _prepare_segments(self, *_: Any) -> None:
        """With live update on, an empty segments layer made ahead of the first strokes
        (``SegmentLayers.prepare_segments``)."""
        self.layers.prepare_segments(bool(self.live.value))

    # -- sections -----------------------------------------------------------------------
    def _on_show_advanced(self, shown: bool) -> None:
        """Show or hide the advanced section; hidden, the dock can be narrowed again."""
        self.advanced.visible = bool(shown)
        if not shown:
            QTimer.singleShot(0, functools.partial(release_dock_minimum, self.native))

    def _show(
        self,
        layer: Layer,
        angles_deg: np.ndarray,
        result: Any,
        seconds: float,
        inputs: dict[str, Any] | None = None,
        partial: bool = False,
        snap: Snapshot | None = None,
        contrast: dict[str, Any] | None = None,
    ) -> None:
        """Show a run's layers and summary: a classifier's output with the materials
        named (``SegmentInputs.named``), segments that survive keeping their numbers
        (``SegmentLayers.keep_colours``), then ``SegmentLayers.show``."""
        result = self.layers.keep_colours(layer, self.inputs.named(result))
        self.layers.show(layer, angles_deg, result, seconds, inputs, partial, snap, contrast)

    def schedule_live_run(self) -> None:
        """With live update on, rerun in the next event-loop turn (a stroke was painted:
        :data:`STROKE_DELAY_MS`; a control's pending change runs with it)."""
        if self.live.value and not self.closed:
            self._timer.start(STROKE_DELAY_MS)

    def on_closed(self) -> None:
        """The dock was closed: beside the base's, stop the live update and listening to
        the edits of the mask and scribbles layers (no stroke retrains any more); the
        state is closed."""
        if self.closed:
            return
        super().on_closed()
        self.state.close()
        self.inputs.unwatch()
        with contextlib.suppress(RuntimeError):  # the timer was deleted with the frame
            self._timer.stop()

    def _on_idle(self) -> None:
        super()._on_idle()
        self._settle()
        if getattr(self, "_features_later", False) and not self.closed:
            QTimer.singleShot(0, self._prefetch_later)

    def _prefetch_later(self) -> None:
        """The pixel features a busy worker put off, for the chosen scribbles layer,
        once the result's layers are added (no run waits)."""
        if not self._features_later or self.closed:
            return
        with contextlib.suppress(RuntimeError):  # the widget was deleted meanwhile
            if self.busy or self._waiting():
                QTimer.singleShot(LIVE_DELAY_MS, self._prefetch_later)
            else:
                self.prefetch_features()

    def _settle(self) -> None:
        """When no run is going, queued or scheduled by the live update: a stack whose
        segments show a run that never completed (cancelled, failed, dropped) shows its
        last completed result again (``SegmentLayers.settle``)."""
        layers = getattr(self, "layers", None)  # None while the base class initialises
        timer = getattr(self, "_timer", None)
        if layers is None or timer is None or self.busy:
            return
        with contextlib.suppress(RuntimeError):  # the timer was deleted with the frame
            if timer.isActive():
                return  # a live rerun comes: its segments replace these
            layers.settle()

    # -- stacks, pipelines and results ------------------------------------------------
    def _refresh_stacks(self) -> None:
        super()._refresh_stacks()
        inputs = getattr(self, "inputs", None)  # None while the base class initialises
        if inputs is not None:
            inputs.reset_choices()
            inputs.write_choices()
            self._write_stack()
            inputs.on_scribbles_changed()

    def shown_result(self, layer: Layer) -> SegmentationResult | None:
        """The result behind ``layer``'s ``segments`` layer, if this widget made it."""
        entry = result_on_screen(self.state, self._viewer, layer)
        return None if entry is None else entry.result

    def _forget(self, keep: set[str]) -> None:
        store = getattr(self, "store", None)  # None while the base class initialises
        if store is not None:
            store.discard(keep)
        self.state.forget(keep)

    def _on_value_changed(self, *_: Any) -> None:
        if self.live.value:
            self._force = True
            self._timer.start(LIVE_DELAY_MS)  # restarts the delay: a burst runs once

    def _on_live_toggled(self, on: bool) -> None:
        """Ticking *live update* arms it. It reruns at once only what was asked for
        before and has changed since (values changed after a Run, strokes painted, a
        classifier loaded); before any Run it starts nothing and says what it will do."""
        if not on:
            return
        if self.state.requested is None and not self._has_strokes():
            self._set_status(
                "live update on: press Run (or paint strokes) for a first result; "
                "every change after it reruns"
            )
            return
        # not forced: runs only if the values differ from the last run's
        self._timer.start(LIVE_DELAY_MS)

    def _has_strokes(self) -> bool:
        """Whether the chosen scribbles train a classifier, or a classifier is loaded."""
        try:
            scribbles = self.inputs.current_scribbles()[1]
        except PolarsegError:
            return False
        trains = scribbles is not None and scribble_problem(scribbles) is None
        return trains or self.state.loaded is not None

    def _on_timer(self) -> None:
        force, self._force = self._force, False
        if not force and self.inputs.snapshot() == self.state.requested:
            self._settle()  # nothing more comes: the shown layers settle
            return  # a layer event that changed nothing (e.g. a redraw)
        self._live_run = True
        try:
            self.run()
        finally:
            self._live_run = False

    def _waiting(self) -> bool:
        return (
            super()._waiting()
            or self._timer.isActive()
            or self.export.slot.busy
            or self.classifier_files.slot.busy
        )

    # -- running ----------------------------------------------------------------------
    def run(self, *_: Any) -> None:
        """Start (or queue) a run with the current values in a worker; returns at once.

        With a scribbles layer chosen, the pixel classifier trained on its strokes
        replaces the unsupervised method; strokes of fewer than two materials are
        reported in the status line and nothing runs. A loaded classifier is applied
        instead of training while the strokes are as they were when it was loaded; once
        they have changed, it is dropped and the strokes train the classifier again. A
        change of parameters the shown result's method does not read (and no thesis
        maps asked for) only shows that result again (:meth:`_reshow`).
        """
        self._timer.stop()
        self._force = False
        if self.mosaic.decode_first():
            return  # a raw mosaic frame: decoded into a stack layer first, which then runs
        try:
            self._request()
        finally:
            self._settle()  # when nothing was started (a bad value, a re-show)

    def _request(self) -> None:
        """The body of :meth:`run`: read the values, then re-show or start the job."""
        try:
            layer, angles_deg = self.current_stack()
            params = self.params()
            mask_key, region = self.inputs.current_mask()
            scribble_key, scribbles = self.inputs.current_scribbles()
            if scribbles is not None:
                self.inputs.classifier_controls.settings()  # a bad value: said before a run
        except PolarsegError as exc:
            self.state.requested = self.inputs.snapshot()
            self._fail(exc)
            return
        snap = self.inputs.snapshot_of(params, mask_key, region, scribble_key, scribbles)
        self.state.requested = snap
        loaded = self.inputs.applied(scribble_key, snap.scribbles_digest)
        if self.state.loaded is not None and loaded is None:  # painted since: train again
            self.state.set_loaded(None)
        if scribbles is not None and loaded is None:
            problem = scribble_problem(scribbles)
            if problem is not None:
                self._set_status(f"scribbles: {problem}")
                return
        if scribbles is None and loaded is None and self._reshow(layer, snap):
            return
        chosen = self.state.inputs
        inputs = {
            "mask": input_info(chosen.mask, mask_key, snap.mask_digest),
            "scribbles": None
            if loaded is not None
            else input_info(chosen.scribbles, scribble_key, snap.scribbles_digest),
            "classifier": None if loaded is None else str(loaded.path),
        }
        self._start(layer, angles_deg, snap, inputs, region, loaded, scribbles)

    def _start(
        self,
        layer: Layer,
        angles_deg: np.ndarray,
        snap: Snapshot,
        inputs: dict[str, Any],
        region: np.ndarray | None,
        loaded: LoadedClassifier | None,
        scribbles: np.ndarray | None,
    ) -> None:
        """Submit the run's job (the method, or the pixel classifier) to the worker slot."""
        delivery = Delivery(layer, angles_deg, snap, inputs, time.perf_counter())
        request = segment_request(
            self.store,
            source_key(layer),
            layer.data,
            np.deg2rad(angles_deg),
            snap.params,
            region,
            snap.mask_key,
            None if loaded is not None else scribbles,
            None if loaded is None else loaded.classifier,
            colour_stack_of(layer),
            maps=snap.maps,
            settings=snap.classifier_settings,
        )
        # a new stroke or request stops the prediction, or the method's stage, at once
        on_result = functools.partial(self._on_result, delivery)
        on_partial = functools.partial(self._on_partial, delivery)
        # the contrast of the maps it adds is computed in the worker too
        job = with_contrast(request.job, self.layers.contrast_memo)
        args, total = request.args, request.total
        self._submit(job, args, total, on_result, on_partial, self._live_run, True, request.reports)

    def prefetch_features(self, *_: Any, force: bool = False) -> None:
        """Compute the pixel features in the worker while the first strokes are painted,
        once a scribbles layer is chosen (or ``force``), unless they train or a run waits."""
        if self.state.inputs.scribbles is None and not force:
            return
        if self.busy or self._waiting():
            self._features_later = True  # computed once the run ends (``_on_idle``)
            return
        self._features_later = False
        try:
            layer, angles_deg = self.current_stack()
            mask_key, region = self.inputs.current_mask()
            scribbles = self.inputs.current_scribbles()[1]
        except PolarsegError:
            return
        if scribbles is not None and scribble_problem(scribbles) is None:
            return  # strokes to train on: their run computes the features
        args = (self.store, source_key(layer), layer.data, np.deg2rad(angles_deg), self.params())
        args += (region, mask_key, colour_stack_of(layer))

        def ready(run_id: int, n_features: int) -> None:
            strokes = self.inputs.current_scribbles()[1]
            problem = scribble_problem(np.zeros(1) if strokes is None else strokes)
            self._set_status(f"pixel features ready ({n_features} features); {problem or ''}")
            self._prepare_segments()  # with live update on: the labels fill it

        self._submit(features_job, args, FEATURES_JOB_STAGES, ready, live=True)

    def _reshow(self, layer: Layer, snap: Snapshot) -> bool:
        """Show the stack's result again when only parameters its method does not read
        changed (e.g. the refractive index under the superpixel method) and no thesis
        maps are asked for: nothing is recomputed. True if it did."""
        key = source_key(layer)
        entry = self.state.shown.get(key)
        scene = self.store.scene(key)
        if entry is None or entry.snap is None or scene is None or snap.maps:
            return False
        changed = snap.differs_only_in_params(entry.snap)
        if changed is None or self.shown_result(layer) is None:
            return False
        old, new = entry.result.params, snap.params
        method = scene.method_for(new, None)
        if method.name != entry.result.method or scene.method_key(
            method, old, {}
        ) != scene.method_key(method, new, {}):
            return False
        segments = find_output(self._viewer, "segments", layer)
        assert segments is not None  # shown_result found it
        angles = segments.metadata.get("polarseg_params", {}).get("angles_deg")
        params_meta = {**new.to_dict(), "angles_deg": angles}
        meta = {**entry.metadata, "polarseg_params": params_meta}
        segments.metadata = {**segments.metadata, "polarseg_params": params_meta}
        # the export records the parameters shown (its maps are computed for them)
        self.state.show(key, ShownEntry(layer, entry.angles_deg, entry.shown, snap, meta))
        self._slot.drop()  # a run of other values still going is outdated: no word of it
        why = (
            f"the {method.name} method does not read {', '.join(changed)}"
            if changed
            else "no parameter changed"
        )
        self._set_status(f"{entry.result.n_segments} segments, unchanged: {why}")
        return True

    def _on_result(self, run: Delivery, run_id: int, result: Any) -> None:
        """A run's result (GUI thread): shown unless the inputs changed meanwhile."""
        contrast: dict[str, Any] = {}
        if isinstance(result, WithContrast):
            result, contrast = result.value, result.contrast
        if not self._still_wanted(run) or run.layer not in self._viewer.layers:
            self._set_status("result dropped: the parameters changed while it was computed")
            return
        if isinstance(result, ClassifierOutput) and result.problem is not None:
            where = "scribbles" if result.trained else "classifier"
            self._set_status(f"{where}: {result.problem}")
            return
        self._show(
            run.layer, run.angles_deg, result, run.seconds(), run.inputs, False, run.snap, contrast
        )

    def _still_wanted(self, run: Delivery) -> bool:
        """Whether ``run``'s result is what the controls ask for now: the same
        snapshot, or an unsupervised run while the only change since is a scribbles
        layer without strokes to train on (*New scribbles layer* clicked meanwhile), for
        which a new run would compute the same."""
        now = self.inputs.snapshot()
        if now is None or run.snap == now:
            return now is not None
        if run.snap.scribbles_key is not None or self._has_strokes():
            return False
        return replace(now, scribbles_key=None, scribbles_digest=None) == run.snap

    def _on_partial(self, run: Delivery, run_id: int, result: Any) -> None:
        """The segments (or classes) before the error map; dropped like a result."""
        if self._still_wanted(run) and run.layer in self._viewer.layers:
            self._show(run.layer, run.angles_deg, result, run.seconds(), run.inputs, True)
