"""The "Segment by material" widget: the cached engine pipeline, run in a worker thread."""

from __future__ import annotations

import contextlib
import functools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Container, PushButton
from napari.layers import Labels
from qtpy.QtCore import QTimer

from ..engine import Pipeline, PolarsegError, SegmentationResult, SegmentParams
from ..engine.params import PARAM_SPECS, PRESET_HELP, PRESETS, ParamSpec
from ..engine.physics.stokes import stokes_components
from ..io import read_params_file
from ._base import ClassifierListener, StackWidget
from ._layers import find_output, label_colormap, remove_output, show_output, source_key
from ._runner import WorkerSlot
from .param_controls import controlled_names, param_controls
from .polarisation import VIEW_OUTPUTS, composite_for, view_mode_box
from .session import (
    ClassifierOutput,
    ExportRecord,
    LoadedClassifier,
    PipelineStore,
    ShownResult,
    classifier_text,
    colour_stack_of,
    content_digest,
    export_job,
    input_info,
    read_classifier_job,
    region_digest,
    scribble_problem,
    segment_request,
    shown_result,
    write_classifier_job,
)

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

    from ..engine.analysis.pixel_classifier import PixelClassifier

#: Milliseconds the live update waits after the last change before it reruns.
LIVE_DELAY_MS = 150


#: Text of the "mask" menu entry that segments every pixel.
NO_MASK = "none"

#: Text of the "scribbles" menu entry that segments without supervision (normalized cut).
NO_SCRIBBLES = "none (unsupervised)"

#: Layer events that mean the user edited a Labels layer: a brush, fill or eraser stroke
#: (``paint``), new data (``data``), undo/redo and other refreshes (``set_data``).
EDIT_EVENTS = ("paint", "data", "set_data")


#: SegmentParams fields that have a control in the widget (the labelled specs of the
#: table, :func:`~napari_polarseg.widgets.param_controls.controlled_names`); the others
#: come from the preset.
CONTROLLED = controlled_names(PARAM_SPECS)

#: Parameter controls shown above the collapsed *advanced settings* section.
FIRST_CONTROLS = ("n_segments",)

#: Controls of the normalized cut only: disabled while scribbles replace the cut.
CUT_ONLY = ("scale", "scale_mode", "clustering", "min_segment_blocks", "n_segments")



@dataclass(frozen=True)
class Delivery:
    """What a run's result is checked against and shown with: the stack layer, its
    angles, the snapshot of the inputs when it was requested, the mask, scribbles and
    classifier file used, and its start time (``time.perf_counter``)."""

    layer: Any
    angles_deg: np.ndarray
    snap: tuple[Any, ...]
    inputs: dict[str, Any]
    t0: float

    def seconds(self) -> float:
        """Seconds since the run was requested."""
        return time.perf_counter() - self.t0


class SegmentWidget(StackWidget):
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
        d = PRESETS["auto"]
        self._base = d  # values of the fields without a control
        self.store = PipelineStore()
        #: Per stack key: (result, inputs) behind the stack's ``segments`` layer.
        self._shown: dict[str, tuple[SegmentationResult, dict[str, Any]]] = {}
        #: Class probabilities (K, H, W) of the last scribble run shown, and the
        #: scribble label of each class (None after an unsupervised run).
        self.probabilities: np.ndarray | None = None
        self.classes: np.ndarray | None = None
        #: Uncertainty (H, W) of the last scribble run shown (None after an unsupervised run).
        self.uncertainty: np.ndarray | None = None
        #: Per stack key: the pixel classifier behind the stack's ``segments`` layer.
        self._classifiers: dict[str, PixelClassifier] = {}
        #: The classifier *Load classifier…* read, while it is applied.
        self.loaded: LoadedClassifier | None = None
        self._loads = 0  # serial number of the last load
        self._classifier_dir = Path.home()
        self._classifier_slot = WorkerSlot("Classifier file", on_status=self._set_status)
        self._requested: tuple[Any, ...] | None = None  # snapshot of the last request
        self._force = False  # a control changed: the next live run is not skipped
        self._watched: dict[str, Any] = {"mask": None, "scribbles": None}
        self._params_dir = Path.home()
        self._live_run = False  # run() was called by the live update
        #: Per stack key: what *Export results…* writes (the last result shown).
        self._exports: dict[str, ExportRecord] = {}
        self._export_dir = Path.home()
        self._export_slot = WorkerSlot("Export results", on_status=self._set_status)
        self.preset = ComboBox(
            label="preset",
            choices=list(PRESETS),
            value="auto",
            tooltip="; ".join(f"{name}: {text}" for name, text in PRESET_HELP.items()),
        )
        self.load_button = PushButton(
            text="Load parameters…",
            tooltip="Set every control from a parameters JSON file (as written by 'Save "
            "parameters…', or a params.json from polarseg segment)",
        )
        self.save_button = PushButton(
            text="Save parameters…",
            tooltip="Write the parameters as JSON, the format of polarseg segment --params",
        )
        self.params_file = Container(
            layout="horizontal",
            widgets=[self.load_button, self.save_button],
            labels=False,
            label="",
        )
        self.params_file.margins = (0, 0, 0, 0)
        #: The parameter table the controls are made from (one control per labelled spec).
        self.param_specs = dict(specs or PARAM_SPECS)
        self.controlled = controlled_names(self.param_specs)
        for name, control in param_controls(d.to_dict(), self.param_specs).items():
            setattr(self, name, control)
        self.specular_branch.visible = False
        self.live = CheckBox(
            text="live update",
            value=False,
            tooltip="Rerun (only the stale stages) whenever a value changes or a stroke is "
            "painted into the chosen mask or scribbles layer",
        )
        self.mask_layer = ComboBox(
            label="mask",
            choices=self._labels_choices,
            nullable=True,
            tooltip="Segment only where this Labels layer is non-zero (same height x width "
            "as the stack); saturated and black samples are left out in any case",
        )
        self.mask_layer.null_string = NO_MASK
        self.mask_layer.reset_choices()
        self.mask_layer.value = None
        self.scribbles_layer = ComboBox(
            label="scribbles",
            choices=self._labels_choices,
            nullable=True,
            tooltip="Strokes per material in a Labels layer of the stack's height x width "
            "(0 = unlabelled, 1, 2, … = materials, at least two): a pixel classifier "
            "(random forest on multi-scale polarisation features) trained on the "
            "scribbled pixels replaces the normalized cut; with live update every stroke "
            "retrains it",
        )
        self.scribbles_layer.null_string = NO_SCRIBBLES
        self.scribbles_layer.reset_choices()
        self.scribbles_layer.value = None
        self.new_scribbles_button = PushButton(
            text="New scribbles layer",
            tooltip="Add an empty Labels layer of the stack's size, choose it as the "
            "scribbles and start the paint brush: paint label 1 on one material, 2 on "
            "another, …",
        )
        self.load_classifier_button = PushButton(
            text="Load classifier…",
            tooltip="Apply a saved pixel classifier (.polarseg-clf, from 'Save classifier…' "
            "or polarseg segment --save-classifier) to the chosen stack without "
            "retraining, until the strokes change or it is cleared. The file is checked "
            "and never runs code",
        )
        self.save_classifier_button = PushButton(
            text="Save classifier…",
            enabled=False,
            tooltip="Write the pixel classifier behind the chosen stack's segments to a "
            ".polarseg-clf file (for 'Load classifier…' and polarseg segment --classifier)",
        )
        self.clear_classifier_button = PushButton(
            text="Clear",
            enabled=False,
            tooltip="Stop applying the loaded classifier: train on the strokes again (or "
            "segment without supervision)",
        )
        self.classifier_file = Container(
            layout="horizontal",
            widgets=[
                self.load_classifier_button,
                self.save_classifier_button,
                self.clear_classifier_button,
            ],
            labels=False,
            label="classifier",
        )
        self.classifier_file.margins = (0, 0, 0, 0)
        self.export_button = PushButton(
            text="Export results…",
            enabled=False,
            tooltip="Write the last result of the chosen stack into a folder: labels, maps, "
            "mask, per-segment statistics (segments.csv), params.json (loadable with 'Load "
            "parameters…' and polarseg segment --params), summary.json and overview.png, "
            "as polarseg segment --out writes them",
        )
        self.views = CheckBox(
            text="HSV and Stokes layers",
            value=False,
            tooltip="Also add the AoLP/DoLP HSV view and the S0, S1, S2 Stokes layers "
            "(hidden) of each result, as the Polarisation image widget does",
        )
        self.view_mode = view_mode_box()
        self.parameter_widgets = [getattr(self, name) for name in self.controlled]
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
        self.show_advanced.changed.connect(self._on_show_advanced)
        self.views.changed.connect(self._on_views_changed)
        self.view_mode.changed.connect(self._on_views_changed)
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
        self._timer = QTimer(self.native)  # deleted with the widget: never fires after it
        self._timer.setSingleShot(True)
        self._timer.setInterval(LIVE_DELAY_MS)
        self._timer.timeout.connect(self._on_timer)
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
        watches, on_edit = self._watched, self._on_layer_edited

        def _unwatch(*_: Any) -> None:
            for layer in watches.values():
                _disconnect_edits(layer, on_edit)
            watches.clear()

        self.native.destroyed.connect(_unwatch)

    # -- parameters -------------------------------------------------------------------
    def params(self) -> SegmentParams:
        """The engine parameters the widget's values describe (raises PolarsegError).

        Fields without a control (``ridge``, ``spatial_radius``, ``spatial_sigma``,
        ``ncut_threshold``, ``affinity_graph``) come from the chosen preset or the last
        :meth:`set_params`. A float set with more decimals than its control shows (e.g.
        ``refractive_index`` 1.4537 from a file, shown as 1.454) is kept exactly until the
        control is changed.
        """
        values: dict[str, Any] = {}
        for name in self.controlled:
            spec, shown = self.param_specs[name], getattr(self, name).value
            if spec.choices is not None:
                values[name] = str(shown)
            elif spec.decimals is None:
                values[name] = int(shown)
            else:  # the control shows spec.decimals decimals of the exact value
                exact = float(getattr(self._base, name))
                tolerance = 0.5 * 10.0**-spec.decimals + 1e-12
                values[name] = exact if abs(exact - float(shown)) <= tolerance else float(shown)
        return self._base.replace(**values)

    def set_params(self, params: SegmentParams | None = None, **changes: Any) -> None:
        """Set the controls from ``params`` and/or keyword changes (SegmentParams names).

        Validated first, also against the controls' ranges (raises PolarsegError and
        changes nothing); with live update on, the burst of changes triggers one run.
        """
        values = (params or self.params()).replace(**changes)
        self._check_controls(values)
        self._base = values
        for name in self.controlled:
            getattr(self, name).value = getattr(values, name)

    def _check_controls(self, values: SegmentParams) -> None:
        """Raise PolarsegError if a value does not fit its control (range, menu)."""
        for name in self.controlled:
            control, value = getattr(self, name), getattr(values, name)
            if isinstance(control, ComboBox):
                if value not in control.choices:
                    raise PolarsegError(f"{name} {value!r} is not offered by the widget")
            elif not control.min <= value <= control.max:
                raise PolarsegError(
                    f"{name} {value} is outside the widget's range {control.min:g}..{control.max:g}"
                )

    def _on_show_advanced(self, shown: bool) -> None:
        self.advanced.visible = bool(shown)

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
            self._show_views(layer, shown[0], meta)

    def _show_views(self, layer: Layer, result: SegmentationResult, meta: dict) -> None:
        """The S0, S1, S2 Stokes layers (hidden) and the AoLP/DoLP HSV view of ``result``
        in the chosen *HSV view* (:data:`~napari_polarseg.widgets.polarisation.VIEW_MODES`),
        below the segments; the Polarisation image widget shares these layers."""
        arrays = (np.asarray(result.intensity), np.asarray(result.dop), np.asarray(result.phase))
        for role, data in zip(VIEW_OUTPUTS[:-1], stokes_components(*arrays), strict=True):
            self._show_below_segments(role, data, layer, meta)
        mode = str(self.view_mode.value)
        rgb, rho_max = composite_for(*arrays, 0.0, mode)
        composite = {"polarseg_composite": {"dolp_max": rho_max, "mode": mode}}
        self._show_below_segments("hsv", rgb, layer, {**meta, **composite})

    def _on_preset_changed(self, name: str) -> None:
        self.set_params(PRESETS[name])

    # -- parameter files --------------------------------------------------------------
    def save_params(self, path: str | Path) -> bool:
        """Write the current parameters to ``path`` as JSON (``SegmentParams.to_json``).

        The format of ``polarseg segment --params`` (and of *Load parameters…*, the
        batch widget's JSON file). Problems go to the status line and a notification;
        returns whether the file was written.
        """
        from ..io import atomic_output

        path = Path(path)
        try:
            text = self.params().to_json() + "\n"
            with atomic_output(path) as tmp:
                tmp.write_text(text, encoding="utf-8")
        except PolarsegError as exc:
            self._fail(exc)
            return False
        except OSError as exc:
            reason = exc.strerror or str(exc)
            self._fail(PolarsegError(f"{path}: cannot write the parameters file ({reason})"))
            return False
        self._params_dir = path.parent
        self._set_status(f"saved the parameters to {path}")
        return True

    def load_params(self, path: str | Path) -> bool:
        """Set every control from a parameters JSON file (see :func:`read_params_file`).

        Missing fields take the thesis defaults, as with ``polarseg segment --params``.
        Invalid JSON, an unknown field or a value out of range leave every control as it
        was and are reported in the status line (and a notification); returns whether
        the parameters were loaded. With live update on, loading triggers one run.
        """
        path = Path(path)
        try:
            params = read_params_file(path)
            try:
                self.set_params(params)
            except PolarsegError as exc:
                raise PolarsegError(f"{path}: {exc}") from None
        except PolarsegError as exc:
            self._fail(exc)
            return False
        self._params_dir = path.parent
        self._set_status(f"loaded the parameters from {path}")
        return True

    def _ask_path(self, save: bool) -> str | None:
        """A file chosen in a Qt dialog (None when cancelled)."""
        from qtpy.QtWidgets import QFileDialog

        filters = "JSON (*.json);;All files (*)"
        if save:
            start = str(self._params_dir / "params.json")
            path, _ = QFileDialog.getSaveFileName(self.native, "Save parameters", start, filters)
        else:
            start = str(self._params_dir)
            path, _ = QFileDialog.getOpenFileName(self.native, "Load parameters", start, filters)
        return path or None

    def _on_save_clicked(self, *_: Any) -> None:
        path = self._ask_path(save=True)
        if path:
            self.save_params(path if Path(path).suffix else f"{path}.json")

    def _on_load_clicked(self, *_: Any) -> None:
        path = self._ask_path(save=False)
        if path:
            self.load_params(path)

    # -- classifier files -------------------------------------------------------------
    @property
    def classifier(self) -> PixelClassifier | None:
        """The pixel classifier behind the chosen stack's segments (None if they did not
        come from it): what *Save classifier…* writes."""
        layer = self.stack_layer.value
        return None if layer is None else self.shown_classifier(layer)

    def shown_classifier(self, layer: Layer) -> PixelClassifier | None:
        """The pixel classifier behind ``layer``'s ``segments`` layer, if this widget made
        them with one (trained on strokes or loaded)."""
        if self.shown_result(layer) is None:
            return None
        return self._classifiers.get(source_key(layer))

    def save_classifier(self, path: str | Path) -> bool:
        """Write the chosen stack's pixel classifier to ``path`` in a worker thread.

        The ``.polarseg-clf`` format of ``polarseg segment --save-classifier`` (the suffix
        is added when missing). Returns whether the writing started; the status line then
        says where it went, or why it could not be written (also as a notification).
        """
        classifier = self.classifier
        if classifier is None:
            self._fail(
                PolarsegError(
                    "no classifier to save: paint strokes of at least 2 materials into the "
                    "scribbles layer and run first"
                )
            )
            return False
        from ..classifier_file import SUFFIX

        path = Path(path)
        if not path.name.endswith(SUFFIX):
            path = path.with_name(path.name + SUFFIX)

        def on_result(run_id: int, written: Path) -> None:
            self._classifier_dir = written.parent
            self._set_status(f"saved the classifier to {written}")

        self._set_status(f"saving the classifier to {path}…")
        self._classifier_slot.submit(write_classifier_job, (path, classifier), 1, on_result)
        return True

    def load_classifier(self, path: str | Path) -> bool:
        """Read a classifier file in a worker thread and apply it to the chosen stack.

        The file is checked before anything in it is used and never runs code
        (:func:`napari_polarseg.classifier_file.load_pixel_classifier`). A bad file is
        reported in the status line (and a notification) and changes nothing else. A good
        one is applied, without retraining, to the chosen stack at once and at every
        later run, until the scribbles change (painting, another layer) or
        :meth:`clear_classifier`. Returns whether the reading started.
        """
        path = Path(path)

        def on_result(run_id: int, classifier: PixelClassifier) -> None:
            try:
                key, strokes = self.current_scribbles()
            except PolarsegError:
                key, strokes = None, None
            self._loads += 1
            self.loaded = LoadedClassifier(
                classifier, path, (key, content_digest(strokes)), self._loads
            )
            self._classifier_dir = path.parent
            self._update_classifier_buttons()
            self._on_scribbles_changed()
            self._set_status(f"loaded the classifier {path.name}: {classifier_text(classifier)}")
            if self.stack_layer.value is not None:
                self.run()

        self._set_status(f"reading the classifier {path}…")
        self._classifier_slot.submit(read_classifier_job, (path,), 1, on_result)
        return True

    def clear_classifier(self, *_: Any) -> None:
        """Stop applying the loaded classifier (a rerun trains on the strokes again, or
        segments without supervision when no scribbles layer is chosen)."""
        if self.loaded is None:
            return
        name, self.loaded = self.loaded.path.name, None
        self._update_classifier_buttons()
        self._on_scribbles_changed()
        self._set_status(f"the classifier {name} is no longer applied")
        self._on_value_changed()

    def _applied(self, scribble_key: str | None, digest: str | None) -> LoadedClassifier | None:
        """The loaded classifier if it still applies (the strokes are as when loaded)."""
        loaded = self.loaded
        if loaded is None or loaded.strokes != (scribble_key, digest):
            return None
        return loaded

    def _ask_classifier_path(self, save: bool) -> str | None:
        """A classifier file chosen in a Qt dialog (None when cancelled)."""
        from qtpy.QtWidgets import QFileDialog

        from ..classifier_file import SUFFIX

        filters = f"Classifier (*{SUFFIX});;All files (*)"
        if save:
            layer = self.stack_layer.value
            stem = "classifier" if layer is None else f"{layer.name} classifier"
            start = str(self._classifier_dir / f"{stem}{SUFFIX}")
            path, _ = QFileDialog.getSaveFileName(self.native, "Save classifier", start, filters)
        else:
            start = str(self._classifier_dir)
            path, _ = QFileDialog.getOpenFileName(self.native, "Load classifier", start, filters)
        return path or None

    def _on_save_classifier_clicked(self, *_: Any) -> None:
        path = self._ask_classifier_path(save=True)
        if path:
            self.save_classifier(path)

    def _on_load_classifier_clicked(self, *_: Any) -> None:
        path = self._ask_classifier_path(save=False)
        if path:
            self.load_classifier(path)

    def _update_classifier_buttons(self, *_: Any) -> None:
        button = getattr(self, "save_classifier_button", None)  # None while being built
        if button is None:
            return
        try:
            button.enabled = self.classifier is not None
            self.clear_classifier_button.enabled = self.loaded is not None
        except RuntimeError:  # the widget was deleted
            pass

    def _notify_plots(self, layer: Layer, classifier: PixelClassifier | None) -> None:
        """Hand every docked :class:`ClassifierListener` (the *Polarisation plots*
        widget) the stack's new classifier."""
        try:
            docked = list(self._viewer.window.dock_widgets.values())
        except (AttributeError, RuntimeError):  # no window (headless viewer) or closing
            return
        for widget in docked:
            if isinstance(widget, ClassifierListener):
                widget.set_classifier(layer, classifier)

    # -- exporting --------------------------------------------------------------------
    def export_results(
        self, folder: str | Path, *, overview: bool = True, plots: bool = False
    ) -> bool:
        """Write the chosen stack's last result into ``folder``, in a worker thread.

        The files of ``polarseg segment --out`` (:func:`napari_polarseg.export.
        write_result_folder`): ``labels.tif`` (0 = first segment; after a scribble run the
        class index, 0 = smallest scribble value), the float maps, ``mask.tif``,
        ``segments.csv``, ``params.json`` (reloads with :meth:`load_params` and ``polarseg
        segment --params``), ``summary.json``, ``stokes.tif`` and ``aolp_dolp.png``,
        ``overview.png`` (unless ``overview`` is False), the analyst's plots in ``plots/``
        with ``plots``, and when the labels came from the pixel classifier
        ``probabilities.tif`` and ``uncertainty.tif``. The result is the one the stack's
        ``segments`` layer was made from, with the stack, angles, parameters and mask of
        that run. Returns whether the export started; the status line then says how many
        files were written, or why they could not be (also as a notification). :meth:`wait`
        waits for it.
        """
        layer = self.stack_layer.value
        record = None if layer is None else self._exports.get(source_key(layer))
        if record is None:
            self._fail(PolarsegError("nothing to export: run a segmentation of this stack first"))
            return False
        folder = Path(folder)
        kwargs = {**record.kwargs(), "overview": overview, "plots": plots}

        def on_result(run_id: int, written: list[str]) -> None:
            self._export_dir = folder
            self._set_status(f"exported {len(written)} files to {folder}")

        self._set_status(f"exporting to {folder}…")
        self._export_slot.submit(export_job, (folder, kwargs), 1, on_result)
        return True

    def _on_export_clicked(self, *_: Any) -> None:
        from qtpy.QtWidgets import QFileDialog

        folder = QFileDialog.getExistingDirectory(
            self.native, "Export results into a folder", str(self._export_dir)
        )
        if folder:
            self.export_results(folder)

    def _update_export_button(self, *_: Any) -> None:
        button = getattr(self, "export_button", None)  # None while the widget is built
        if button is None:
            return
        layer = self.stack_layer.value
        try:
            button.enabled = layer is not None and source_key(layer) in self._exports
        except RuntimeError:  # the widget was deleted
            pass

    def _record_export(self, layer: Layer, angles_deg: np.ndarray, shown: ShownResult) -> None:
        """Keep what *Export results…* needs of the result just shown for ``layer``."""
        key = source_key(layer)
        pipe = self.store.get(key)  # the pipeline that made the result (its pixel mask)
        source = getattr(getattr(layer, "source", None), "path", None)
        self._exports[key] = ExportRecord.of(
            shown,
            stack=layer.data,
            angles_deg=angles_deg,
            mask=None if pipe is None else pipe.mask,
            source=None if source is None else str(source),
            layer_name=layer.name,
        )
        self._update_export_button()

    # -- mask and scribbles -----------------------------------------------------------
    def _refresh_stacks(self) -> None:
        super()._refresh_stacks()
        for name in ("mask_layer", "scribbles_layer"):
            chooser = getattr(self, name, None)  # None while the base class initialises
            if chooser is not None:
                chooser.reset_choices()
        if getattr(self, "scribbles_layer", None) is not None:
            self._sync_watches()
            self._on_scribbles_changed()

    def current_mask(self) -> tuple[str | None, np.ndarray | None]:
        """Key and (H, W) bool region (a copy; True = use) of the chosen mask, or Nones."""
        layer = self.mask_layer.value
        if layer is None:
            return None, None
        if layer not in self._viewer.layers:
            raise PolarsegError(f"the mask layer {layer.name!r} is no longer in the viewer")
        return source_key(layer), np.asarray(layer.data) != 0

    def current_scribbles(self) -> tuple[str | None, np.ndarray | None]:
        """Key and (H, W) labels (a copy) of the chosen scribbles layer, or Nones."""
        layer = self.scribbles_layer.value
        if layer is None:
            return None, None
        if layer not in self._viewer.layers:
            raise PolarsegError(f"the scribbles layer {layer.name!r} is no longer in the viewer")
        return source_key(layer), np.array(layer.data, copy=True)

    def new_scribbles_layer(self, *_: Any) -> Labels | None:
        """Add an empty Labels layer for strokes, choose it and start the paint brush.

        Named ``"<stack> scribbles"``, of the stack's height x width (and placement),
        selected in the layer list with the paint tool on label 1.
        """
        stack = self.stack_layer.value
        if stack is None:
            self._fail(PolarsegError("choose an angle-stack image layer first"))
            return None
        h, w = stack.data.shape[-2:]
        layer = self._viewer.add_labels(
            np.zeros((h, w), dtype=np.int32),
            name=f"{stack.name} scribbles",
            colormap=label_colormap(),  # the segments' colours: a stroke and its segment match
            scale=tuple(stack.scale[-2:]),
            translate=tuple(stack.translate[-2:]),
        )
        self.scribbles_layer.reset_choices()
        self.scribbles_layer.value = layer
        layer.selected_label = 1
        self._viewer.layers.selection.active = layer
        layer.mode = "paint"
        self._set_status(
            f"paint strokes into {layer.name!r}: label 1 on one material, 2 on another, … "
            "(at least 2), then Run (or tick live update)"
        )
        return layer

    def _on_scribbles_changed(self, *_: Any) -> None:
        # the classifier replaces the cut: its controls do nothing
        unsupervised = self.scribbles_layer.value is None and self.loaded is None
        for name in CUT_ONLY:
            getattr(self, name).enabled = unsupervised

    def _sync_watches(self, *_: Any) -> None:
        """Listen to edits of the chosen mask and scribbles layers (and no others)."""
        for role, chooser in (("mask", self.mask_layer), ("scribbles", self.scribbles_layer)):
            old, new = self._watched.get(role), chooser.value
            if old is new:
                continue
            if old is not None and old not in self._watched_except(role):
                _disconnect_edits(old, self._on_layer_edited)
            if new is not None and new not in self._watched_except(role):
                for name in EDIT_EVENTS:
                    getattr(new.events, name).connect(self._on_layer_edited)
            self._watched[role] = new

    def _watched_except(self, role: str) -> list[Any]:
        return [layer for r, layer in self._watched.items() if r != role and layer is not None]

    def _on_layer_edited(self, *_: Any) -> None:
        """A stroke (or undo, new data) in the chosen mask or scribbles layer."""
        try:
            if self.live.value:
                self._timer.start()  # the same debounce as a changed value
        except RuntimeError:  # the widget was deleted
            pass

    def snapshot(self) -> tuple[Any, ...] | None:
        """Everything a result depends on, or None if the values are invalid."""
        try:
            params = self.params()
            mask_key, region = self.current_mask()
            scribble_key, scribbles = self.current_scribbles()
        except PolarsegError:
            return None
        return self._snapshot_of(params, mask_key, region, scribble_key, scribbles)

    def _snapshot_of(
        self,
        params: SegmentParams,
        mask_key: str | None,
        region: np.ndarray | None,
        scribble_key: str | None,
        scribbles: np.ndarray | None,
    ) -> tuple[Any, ...]:
        layer = self.stack_layer.value
        key = None if layer is None else source_key(layer)
        digest = content_digest(scribbles)
        loaded = self._applied(scribble_key, digest)
        return (
            key,
            self.angles.value,
            params,
            mask_key,
            region_digest(region),
            scribble_key,
            digest,
            None if loaded is None else loaded.serial,
        )

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
        shown = getattr(self, "_shown", None)
        if shown is not None:
            for key in set(shown) - keep:
                del shown[key]
        exports = getattr(self, "_exports", None)
        if exports is not None:
            for key in set(exports) - keep:
                del exports[key]
            self._update_export_button()
        classifiers = getattr(self, "_classifiers", None)
        if classifiers is not None:
            for key in set(classifiers) - keep:
                del classifiers[key]
            self._update_classifier_buttons()

    def _on_model_changed(self, model: str) -> None:
        self.specular_branch.visible = model == "specular"

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

    def _show(
        self,
        layer: Layer,
        angles_deg: np.ndarray,
        result: SegmentationResult | ClassifierOutput,
        seconds: float,
        inputs: dict[str, Any] | None = None,
    ) -> None:
        """Show a run's layers and summary.

        A partial result (no reconstruction yet: the worker yielded it before its last
        stage) updates the segments (and class probability, uncertainty) layers and the
        status line only; the complete result that follows updates the rest. Labels equal
        to those already shown only update the segments' metadata.
        """
        shown = shown_result(result, angles_deg, inputs)
        meta, out = shown.meta, shown.out
        if not shown.partial:
            self._show_complete(layer, shown)
        if out is not None:
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
        self._shown[source_key(layer)] = (shown.result, shown.inputs)
        self._record_classifier(layer, None if out is None else out.classifier)
        self._record_export(layer, angles_deg, shown)
        self._done(shown.status(seconds))

    def _show_complete(self, layer: Layer, shown: ShownResult) -> None:
        """The layers of a complete result below the segments: the error map, the
        diagnostics (masked pixels, fit residual) and the HSV and Stokes views."""
        result, meta = shown.result, shown.meta
        # the error map (added hidden) goes below the segments, which overlay the stack
        error = np.array(result.reconstruction_error)
        self._show_below_segments("error", error, layer, meta)
        masked = shown.masked()
        if self._shows_diagnostics(layer, result, masked):
            residual = np.array(result.residual)
            self._show_below_segments("residual", residual, layer, meta)
            self._show_below_segments("masked", masked, layer, meta)
        if self.views.value:
            self._show_views(layer, result, meta)

    def _record_classifier(self, layer: Layer, classifier: PixelClassifier | None) -> None:
        """Keep the classifier behind ``layer``'s segments (for *Save classifier…* and
        the plots' feature importances)."""
        key = source_key(layer)
        if classifier is None and key not in self._classifiers:
            return
        if classifier is None:
            del self._classifiers[key]
        else:
            self._classifiers[key] = classifier
        self._update_classifier_buttons()
        self._notify_plots(layer, classifier)

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

    def _shows_diagnostics(self, layer: Layer, result: Any, masked: np.ndarray) -> bool:
        """Whether to add/update ``masked pixels`` and ``fit residual`` for this result.

        From the first run that leaves a pixel out or fits robustly on; once they exist
        they are updated on every run (so they never show a stale mask).
        """
        if result.params.fit != "lsq" or bool(masked.any()):
            return True
        return any(find_output(self._viewer, r, layer) is not None for r in ("masked", "residual"))



def _disconnect_edits(layer: Any, callback: Any) -> None:
    if layer is None:
        return
    for name in EDIT_EVENTS:
        with contextlib.suppress(Exception):
            getattr(layer.events, name).disconnect(callback)
