"""The "Segment by material" widget: the cached engine pipeline, run in a worker thread.

Thin: the jobs, pipelines and result texts are the session layer
(:mod:`napari_polarseg.widgets.session`); the widget's parts are mixins, one module each:
:mod:`~napari_polarseg.widgets.segment_params` (the parameter controls and files),
:mod:`~napari_polarseg.widgets.segment_inputs` (mask, scribbles, snapshot),
:mod:`~napari_polarseg.widgets.segment_files` (classifier files, *Export results…*) and
:mod:`~napari_polarseg.widgets.segment_layers` (the output layers). This module builds
the widget and runs it.
"""

from __future__ import annotations

import functools
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import CheckBox, Container
from qtpy.QtCore import QTimer

from ..engine import Pipeline, PolarsegError, SegmentationResult
from ..engine.params import PARAM_SPECS, PRESETS, ParamSpec
from ._base import StackWidget
from ._layers import find_output, source_key
from .param_controls import controlled_names
from .segment_files import ClassifierFiles, ResultExport
from .segment_inputs import CUT_ONLY, NO_MASK, NO_SCRIBBLES, MaskAndScribbles
from .segment_layers import ResultLayers
from .segment_params import ParameterControls
from .session import (
    ClassifierOutput,
    Delivery,
    PipelineStore,
    colour_stack_of,
    input_info,
    scribble_problem,
    segment_request,
)

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

# Names importers take from this module (tests, benchmarks): defined beside the mixins.
__all__ = [
    "CONTROLLED",
    "CUT_ONLY",
    "FIRST_CONTROLS",
    "LIVE_DELAY_MS",
    "NO_MASK",
    "NO_SCRIBBLES",
    "PRESETS",
    "SegmentWidget",
]

#: Milliseconds the live update waits after the last change before it reruns.
LIVE_DELAY_MS = 150

#: SegmentParams fields that have a control in the widget (the labelled specs of the
#: table, :func:`~napari_polarseg.widgets.param_controls.controlled_names`); the others
#: come from the preset.
CONTROLLED = controlled_names(PARAM_SPECS)

#: Parameter controls shown above the collapsed *advanced settings* section.
FIRST_CONTROLS = ("n_segments",)


class SegmentWidget(
    ResultLayers,
    ClassifierFiles,
    ResultExport,
    MaskAndScribbles,
    ParameterControls,
    StackWidget,
):
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
    computes only the stages a change made stale (changing the number of segments
    recomputes only the labels). Beside it a
    :class:`~napari_polarseg.engine.analysis.pixel_segmentation.PixelSegmenter` keeps the stack's
    pixel features, so a painted stroke only retrains the pixel classifier and predicts
    again; a new stroke (or any change) during a retraining stops its prediction between
    chunks and starts the newest request. A loaded classifier is applied to the chosen
    stack without retraining until the strokes change or it is cleared. The
    mask is read at every run: choosing another one, or painting the chosen Labels
    layer, builds a new pipeline at the next run. At most one worker runs at a time; a
    change during a run stops it at the next stage boundary and starts the newest
    request.

    Output layers (replaced in place on a rerun): ``segments`` (Labels, one label per
    segment over every pixel; segment k of the engine is label k + 1 because napari
    draws label 0 as transparent background; with scribbles, each pixel gets the label
    of the scribbled material the classifier chose, so segments and strokes share their
    colours) and ``reconstruction error`` (Image, per-pixel |Î rebuilt from the block
    harmonics − Î|, added hidden below the segments; its mean is in the status line).
    Once a run leaves pixels out (mask, saturated, black) or uses the robust fit, also
    ``masked pixels`` (Labels, 1 where a pixel was left out of the fit and the features)
    and ``fit residual`` (Image, RMS residual of the per-pixel sinusoid fit), both added
    hidden and updated on every later run. With scribbles (or a loaded classifier), also
    ``class probability`` (Image, hidden: the classifier's probability of the chosen
    class, 1/K … 1, low where it hesitates between materials) and ``uncertainty``
    (Image, hidden: 1 − (p1 − p2), one minus the margin between the two most probable
    classes, 0 sure … 1 a tie: where another stroke helps most); the probabilities of
    every class are :attr:`probabilities` (K, H, W) with their labels in
    :attr:`classes`, the uncertainty is :attr:`uncertainty`. With *HSV and Stokes layers*
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

    run_text = "Run"
    run_tooltip = (
        "Segment the chosen stack by material with the parameters below (or the "
        "scribbles) and add the segments and the reconstruction-error map as layers"
    )
    progress_desc = "Segment by material"

    def __init__(
        self, viewer: napari.viewer.Viewer, specs: dict[str, ParamSpec] | None = None
    ) -> None:
        super().__init__(viewer)
        self.store = PipelineStore()
        #: Per stack key: (result, inputs) behind the stack's ``segments`` layer.
        self._shown: dict[str, tuple[SegmentationResult, dict[str, Any]]] = {}
        self._requested: tuple[Any, ...] | None = None  # snapshot of the last request
        self._force = False  # a control changed: the next live run is not skipped
        self._live_run = False  # run() was called by the live update
        self._build_classifier_controls()
        self._build_export_controls()
        self._build_parameter_controls(specs)
        self.live = CheckBox(
            text="live update",
            value=False,
            tooltip="Rerun (only the stale stages) whenever a value changes or a stroke is "
            "painted into the chosen mask or scribbles layer",
        )
        self._build_input_controls()
        self._build_view_controls()
        self._lay_out()
        self._timer = QTimer(self.native)  # deleted with the widget: never fires after it
        self._timer.setSingleShot(True)
        self._timer.setInterval(LIVE_DELAY_MS)
        self._timer.timeout.connect(self._on_timer)
        self._connect()
        self._unwatch_when_closed()

    def _lay_out(self) -> None:
        """The first controls, then the collapsed *advanced settings*; Export after Run."""
        # the few controls a user touches first stay in view; the rest (every parameter
        # the preset sets, the mask, the files) sit in the collapsed "advanced" section
        self.advanced = Container(
            widgets=[
                self.params_file,
                *(getattr(self, name) for name in self.controlled if name not in FIRST_CONTROLS),
                self.mask_layer,
                self.classifier_file,
                self.views,
                self.view_mode,
            ],
            labels=True,
            label="",
            visible=False,
        )
        self.advanced.margins = (0, 0, 0, 0)
        self.show_advanced = CheckBox(
            text="advanced settings",
            value=False,
            tooltip="Show every parameter of the pipeline (the preset sets them), the mask, "
            "and the parameter and classifier files",
        )
        self._add_parameters(
            [
                self.preset,
                *(getattr(self, name) for name in FIRST_CONTROLS),
                self.scribbles_layer,
                self.new_scribbles_button,
                self.live,
                self.show_advanced,
                self.advanced,
            ]
        )
        self.insert(self.index(self.progress), self.export_button)  # after Run and Cancel

    def _connect(self) -> None:
        """Connect the controls to their handlers (the order of the original widget)."""
        self.show_advanced.changed.connect(self._on_show_advanced)
        self.views.changed.connect(self._on_views_changed)
        self.view_mode.changed.connect(self._on_views_changed)
        self.stack_layer.changed.connect(self.mask_layer.reset_choices)
        self.stack_layer.changed.connect(self.scribbles_layer.reset_choices)
        watched = [self.stack_layer, self.angles, self.mask_layer, self.scribbles_layer]
        for w in [*self.parameter_widgets, *watched]:
            w.changed.connect(self._on_value_changed)
        self.live.changed.connect(self._on_value_changed)
        self.model.changed.connect(self._on_model_changed)
        self.preset.changed.connect(self._on_preset_changed)
        self.mask_layer.changed.connect(self._sync_watches)
        self.scribbles_layer.changed.connect(self._sync_watches)
        self.scribbles_layer.changed.connect(self._on_scribbles_changed)
        self.new_scribbles_button.changed.connect(self.new_scribbles_layer)
        self.load_button.changed.connect(self._on_load_clicked)
        self.save_button.changed.connect(self._on_save_clicked)
        self.export_button.changed.connect(self._on_export_clicked)
        self.load_classifier_button.changed.connect(self._on_load_classifier_clicked)
        self.save_classifier_button.changed.connect(self._on_save_classifier_clicked)
        self.clear_classifier_button.changed.connect(self.clear_classifier)
        self.stack_layer.changed.connect(self._update_classifier_buttons)
        self.stack_layer.changed.connect(self._update_export_button)

    # -- sections -----------------------------------------------------------------------
    def _on_show_advanced(self, shown: bool) -> None:
        self.advanced.visible = bool(shown)

    # -- stacks, pipelines and results ------------------------------------------------
    def _refresh_stacks(self) -> None:
        super()._refresh_stacks()
        for name in ("mask_layer", "scribbles_layer"):
            chooser = getattr(self, name, None)  # None while the base class initialises
            if chooser is not None:
                chooser.reset_choices()
        if getattr(self, "scribbles_layer", None) is not None:
            self._sync_watches()
            self._on_scribbles_changed()

    @property
    def pipeline(self) -> Pipeline | None:
        """The cached pipeline of the chosen stack layer (None before its first run)."""
        layer = self.stack_layer.value
        return None if layer is None else self.store.get(source_key(layer))

    def pipeline_for(self, layer: Layer) -> Pipeline | None:
        """The cached pipeline of ``layer`` (None before its first run)."""
        return self.store.get(source_key(layer))

    def shown_result(self, layer: Layer) -> SegmentationResult | None:
        """The result behind ``layer``'s ``segments`` layer, if this widget made it."""
        entry = self._shown.get(source_key(layer))
        segments = find_output(self._viewer, "segments", layer)
        if entry is None or segments is None:
            return None
        result, inputs = entry
        if segments.metadata.get("polarseg_inputs") != inputs:
            return None  # another widget has written the layer since
        return result

    def _forget(self, keep: set[str]) -> None:
        store = getattr(self, "store", None)  # None while the base class initialises
        if store is not None:
            store.discard(keep)
        updates = {
            "_shown": None,
            "_exports": self._update_export_button,
            "_classifiers": self._update_classifier_buttons,
        }
        for name, update in updates.items():
            kept = getattr(self, name, None)  # None while the widget is built
            if kept is None:
                continue
            for key in set(kept) - keep:
                del kept[key]
            if update is not None:
                update()

    def _on_value_changed(self, *_: Any) -> None:
        if self.live.value:
            self._force = True
            self._timer.start()  # restarts the delay: a burst of changes runs once

    def _on_timer(self) -> None:
        force, self._force = self._force, False
        if not force and self.snapshot() == self._requested:
            return  # a layer event that changed nothing (e.g. a redraw)
        self._live_run = True
        try:
            self.run()
        finally:
            self._live_run = False

    def _waiting(self) -> bool:
        return self._timer.isActive() or self._export_slot.busy or self._classifier_slot.busy

    # -- running ----------------------------------------------------------------------
    def run(self, *_: Any) -> None:
        """Start (or queue) a run with the current values in a worker; returns at once.

        With a scribbles layer chosen, the pixel classifier trained on its strokes
        replaces the normalized cut; strokes of fewer than two materials are reported in
        the status line and nothing runs. A loaded classifier is applied instead of
        training while the strokes are as they were when it was loaded; once they have
        changed, it is dropped and the strokes train the classifier again.
        """
        self._timer.stop()
        self._force = False
        try:
            layer, angles_deg = self.current_stack()
            params = self.params()
            mask_key, region = self.current_mask()
            scribble_key, scribbles = self.current_scribbles()
        except PolarsegError as exc:
            self._requested = self.snapshot()
            self._fail(exc)
            return
        snap = self._snapshot_of(params, mask_key, region, scribble_key, scribbles)
        self._requested = snap
        loaded = self._applied(scribble_key, snap[6])
        if self.loaded is not None and loaded is None:  # painted since: train again
            self.loaded = None
            self._update_classifier_buttons()
            self._on_scribbles_changed()
        if scribbles is not None and loaded is None:
            problem = scribble_problem(scribbles)
            if problem is not None:
                self._set_status(f"scribbles: {problem}")
                return
        inputs = {
            "mask": input_info(self.mask_layer.value, mask_key, snap[4]),
            "scribbles": None
            if loaded is not None
            else input_info(self.scribbles_layer.value, scribble_key, snap[6]),
            "classifier": None if loaded is None else str(loaded.path),
        }
        delivery = Delivery(layer, angles_deg, snap, inputs, time.perf_counter())
        angles_rad = np.deg2rad(angles_deg)
        classifier = None if loaded is None else loaded.classifier
        strokes = None if loaded is not None else scribbles
        request = segment_request(
            self.store,
            source_key(layer),
            layer.data,
            angles_rad,
            params,
            region,
            mask_key,
            strokes,
            classifier,
            colour_stack_of(layer),
        )
        # a new stroke or request stops the prediction, or the cut's eigensolver, at once;
        # the cut reports progress within the harmonics and reconstruction
        on_result = functools.partial(self._on_result, delivery)
        on_partial = functools.partial(self._on_partial, delivery)
        job, args, total = request.job, request.args, request.total
        self._submit(job, args, total, on_result, on_partial, self._live_run, True, request.reports)

    def _on_result(self, run: Delivery, run_id: int, result: Any) -> None:
        """A run's result (GUI thread): shown unless the inputs changed meanwhile."""
        if run.snap != self.snapshot() or run.layer not in self._viewer.layers:
            self._set_status("result dropped: the parameters changed while it was computed")
            return
        if isinstance(result, ClassifierOutput) and result.problem is not None:
            where = "scribbles" if result.trained else "classifier"
            self._set_status(f"{where}: {result.problem}")
            return
        self._show(run.layer, run.angles_deg, result, run.seconds(), run.inputs)

    def _on_partial(self, run: Delivery, run_id: int, result: Any) -> None:
        """The segments (or classes) before the error map; dropped like a result."""
        if run.snap == self.snapshot() and run.layer in self._viewer.layers:
            self._show(run.layer, run.angles_deg, result, run.seconds(), run.inputs)
