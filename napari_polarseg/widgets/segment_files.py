"""The Segment widget's files: the pixel classifier (*Load classifier…*, *Save
classifier…*, *Clear*) and *Export results…*, each written or read in a worker.

Two objects the widget holds (:class:`ClassifierFiles`, :class:`ResultExport`). Both
read and write the dock's state (:class:`~napari_polarseg.widgets.session.state.SegmentState`:
the chosen stack and scribbles, the results shown, the loaded classifier, the exports)
and follow its signals; what else they need of the widget comes in as callables.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import Container, PushButton

from ..engine import PolarsegError
from ._base import ClassifierListener, ask_file
from ._layers import source_key
from ._runner import WorkerSlot
from .docks import docked
from .materials import layer_names
from .segment_layers import result_on_screen
from .session import (
    ExportRecord,
    LoadedClassifier,
    PipelineStore,
    classifier_text,
    content_digest,
    export_job,
    read_classifier_job,
    write_classifier_job,
)
from .session.state import SegmentState, ShownEntry

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer
    from qtpy.QtWidgets import QWidget

    from ..engine.classifier.pixel_classifier import PixelClassifier


class ClassifierFiles:
    """The pixel classifier behind the segments, its files and the loaded one.

    The classifier behind a stack's segments is the one of the state's entry for it;
    the loaded one is the state's (``SegmentState.loaded``). A docked *Polarisation
    plots* widget gets every new classifier shown.

    Parameters
    ----------
    state : SegmentState
        The dock's state.
    viewer : napari.viewer.Viewer
        Its viewer (the docked plots get each new classifier).
    parent : callable() -> QWidget
        The widget file dialogs open over.
    status, fail : callable
        The widget's status line and error report.
    changed : callable()
        A change that a live update reruns after (the classifier was cleared).
    run : callable()
        Runs the widget (a classifier was loaded).
    """

    def __init__(
        self,
        state: SegmentState,
        viewer: napari.viewer.Viewer,
        parent: Callable[[], QWidget],
        status: Callable[[str], None],
        fail: Callable[[PolarsegError], None],
        changed: Callable[[], None],
        run: Callable[[], None],
    ) -> None:
        self._state, self._viewer, self._parent = state, viewer, parent
        self._status, self._fail = status, fail
        self._changed, self._run = changed, run
        self._loads = 0  # serial number of the last load
        self._classifier_dir = Path.home()
        self.slot = WorkerSlot("Classifier file", on_status=status)
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
        self.load_classifier_button.changed.connect(self._on_load_classifier_clicked)
        self.save_classifier_button.changed.connect(self._on_save_classifier_clicked)
        self.clear_classifier_button.changed.connect(self.clear_classifier)
        for signal in (state.inputs_changed, state.loaded_changed, state.forgotten):
            signal.connect(self.update_buttons)
        state.shown_changed.connect(self._on_shown)

    @property
    def loaded(self) -> LoadedClassifier | None:
        """The classifier *Load classifier…* read, while it is applied (the state's)."""
        return self._state.loaded

    @property
    def classifier(self) -> PixelClassifier | None:
        """The pixel classifier behind the chosen stack's segments (None if they did not
        come from it): what *Save classifier…* writes."""
        layer = self._state.inputs.stack
        return None if layer is None else self.shown_classifier(layer)

    def shown_classifier(self, layer: Layer) -> PixelClassifier | None:
        """The pixel classifier behind ``layer``'s ``segments`` layer, if this widget made
        them with one (trained on strokes or loaded)."""
        entry = result_on_screen(self._state, self._viewer, layer)
        return None if entry is None else entry.classifier

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
            self._status(f"saved the classifier to {written}")

        self._status(f"saving the classifier to {path}…")
        classifier = classifier.named(layer_names(self._state.inputs.scribbles))
        self.slot.submit(write_classifier_job, (path, classifier), 1, on_result)
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
            layer = self._state.inputs.scribbles
            key, strokes = None, None
            if layer is not None and layer in self._viewer.layers:
                key, strokes = source_key(layer), np.array(layer.data, copy=True)
            self._loads += 1
            strokes_id = (key, content_digest(strokes))
            self._classifier_dir = path.parent
            self._state.set_loaded(LoadedClassifier(classifier, path, strokes_id, self._loads))
            self._status(f"loaded the classifier {path.name}: {classifier_text(classifier)}")
            if self._state.inputs.stack is not None:
                self._run()

        self._status(f"reading the classifier {path}…")
        self.slot.submit(read_classifier_job, (path,), 1, on_result)
        return True

    def clear_classifier(self, *_: Any) -> None:
        """Stop applying the loaded classifier (a rerun trains on the strokes again, or
        segments without supervision when no scribbles layer is chosen)."""
        loaded = self._state.loaded
        if loaded is None:
            return
        self._state.set_loaded(None)
        self._status(f"the classifier {loaded.path.name} is no longer applied")
        self._changed()

    def ask_path(self, save: bool) -> str | None:
        """A classifier file chosen in a Qt dialog (None when cancelled)."""
        from ..classifier_file import SUFFIX

        filters = f"Classifier (*{SUFFIX});;All files (*)"
        if save:
            layer = self._state.inputs.stack
            stem = "classifier" if layer is None else f"{layer.name} classifier"
            start = str(self._classifier_dir / f"{stem}{SUFFIX}")
            return ask_file(self._parent(), "Save classifier", start, filters, save=True)
        parent = self._parent()
        return ask_file(parent, "Load classifier", str(self._classifier_dir), filters)

    def _on_save_classifier_clicked(self, *_: Any) -> None:
        path = self.ask_path(save=True)
        if path:
            self.save_classifier(path)

    def _on_load_classifier_clicked(self, *_: Any) -> None:
        path = self.ask_path(save=False)
        if path:
            self.load_classifier(path)

    def update_buttons(self, *_: Any) -> None:
        """*Save classifier…* while there is one to save, *Clear* while one is loaded."""
        try:
            self.save_classifier_button.enabled = self.classifier is not None
            self.clear_classifier_button.enabled = self.loaded is not None
        except RuntimeError:  # the widget was deleted
            pass

    def _on_shown(self, key: str, old: ShownEntry | None) -> None:
        """A stack shows another result: *Save classifier…* follows, and the docked
        plots get its classifier when it is another one."""
        entry = self._state.shown.get(key)
        self.update_buttons()
        before = None if old is None else old.classifier
        classifier = None if entry is None else entry.classifier
        if entry is not None and classifier is not before:
            self._notify_plots(entry.layer, classifier)

    def _notify_plots(self, layer: Layer, classifier: PixelClassifier | None) -> None:
        """Hand every docked :class:`ClassifierListener` (the *Polarisation plots*
        widget) the stack's new classifier."""
        for widget in docked(self._viewer, ClassifierListener):
            widget.set_classifier(layer, classifier)


class ResultExport:
    """*Export results…*: the chosen stack's last result as the folder ``polarseg
    segment --out`` writes.

    What it writes is the state's record of the chosen stack
    (``SegmentState.exports``), made from each completed result the state shows (with
    the pixel mask and the scene of the pipeline that made it).

    Parameters
    ----------
    state : SegmentState
        The dock's state.
    store : PipelineStore
        The widget's pipelines (the mask and scene behind a result).
    parent : callable() -> QWidget
        The widget the folder dialog opens over.
    status, fail : callable
        The widget's status line and error report.
    """

    def __init__(
        self,
        state: SegmentState,
        store: PipelineStore,
        parent: Callable[[], QWidget],
        status: Callable[[str], None],
        fail: Callable[[PolarsegError], None],
    ) -> None:
        self._state, self._store, self._parent = state, store, parent
        self._status, self._fail = status, fail
        self._export_dir = Path.home()
        self.slot = WorkerSlot("Export results", on_status=status)
        self.export_button = PushButton(
            text="Export results…",
            enabled=False,
            tooltip="Write the last result of the chosen stack into a folder: labels, maps, "
            "mask, per-segment statistics (segments.csv), params.json (loadable with 'Load "
            "parameters…' and polarseg segment --params), summary.json and overview.png, "
            "as polarseg segment --out writes them",
        )
        self.export_button.changed.connect(self._on_export_clicked)
        for signal in (state.inputs_changed, state.exports_changed, state.forgotten):
            signal.connect(self.update_button)
        state.shown_changed.connect(self._on_shown)

    def export_results(
        self, folder: str | Path, *, overview: bool = True, plots: bool = False
    ) -> bool:
        """Write the chosen stack's last result into ``folder``, in a worker thread.

        The files of ``polarseg segment --out``
        (:func:`napari_polarseg.outputs.write_result_folder`): ``labels.tif`` (0 = first segment;
        after a scribble run the
        class index, 0 = smallest scribble value), the float maps, ``mask.tif``,
        ``segments.csv``, ``params.json`` (reloads with
        :meth:`~napari_polarseg.widgets.segment.SegmentWidget.load_params` and ``polarseg
        segment --params``), ``summary.json``, ``stokes.tif`` and ``aolp_dolp.png``,
        ``overview.png`` (unless ``overview`` is False), the analyst's plots in ``plots/``
        with ``plots``, and when the labels came from the pixel classifier
        ``probabilities.tif`` and ``uncertainty.tif``. The result is the one the stack's
        ``segments`` layer was made from, with the stack, angles, parameters and mask of
        that run. Returns whether the export started; the status line then says how many
        files were written, or why they could not be (also as a notification).
        :meth:`~napari_polarseg.widgets.segment.SegmentWidget.wait`
        waits for it.
        """
        layer = self._state.inputs.stack
        record = None if layer is None else self._state.exports.get(source_key(layer))
        if record is None:
            self._fail(PolarsegError("nothing to export: run a segmentation of this stack first"))
            return False
        folder = Path(folder)
        options = {"overview": overview, "plots": plots}
        record = record.named(layer_names(self._state.inputs.scribbles))  # renamed since

        def on_result(run_id: int, written: list[str]) -> None:
            self._export_dir = folder
            self._status(f"exported {len(written)} files to {folder}")

        first = " (the thesis maps and error map first)" if record.incomplete else ""
        self._status(f"exporting to {folder}{first}…")
        self.slot.submit(export_job, (folder, record, options), 2, on_result)
        return True

    def _on_export_clicked(self, *_: Any) -> None:
        from qtpy.QtWidgets import QFileDialog

        folder = QFileDialog.getExistingDirectory(
            self._parent(), "Export results into a folder", str(self._export_dir)
        )
        if folder:
            self.export_results(folder)

    def update_button(self, *_: Any) -> None:
        """*Export results…* while the chosen stack has a result."""
        layer = self._state.inputs.stack
        exports = self._state.exports
        try:
            self.export_button.enabled = layer is not None and source_key(layer) in exports
        except RuntimeError:  # the widget was deleted
            pass

    def _on_shown(self, key: str, old: ShownEntry | None) -> None:
        """A stack shows another result: keep what *Export results…* writes of it. The
        same result shown again for parameters its method does not read: the folder
        records them (its maps are computed for them at the export)."""
        state = self._state
        entry = state.shown.get(key)
        if entry is None:
            state.set_export(key, None)
            return
        if old is not None and entry.shown is old.shown:  # re-shown for other parameters
            record = state.exports.get(key)
            if record is not None and record.scene is not None and entry.snap is not None:
                state.set_export(key, replace(record, params=entry.snap.params))
            return
        state.set_export(key, self.record_of(key, entry))

    def record_of(self, key: str, entry: ShownEntry) -> ExportRecord:
        """What *Export results…* needs of ``entry``, just shown for stack ``key``."""
        layer, store = entry.layer, self._store
        pipe = store.get(key)  # the pipeline that made the result (its pixel mask)
        source = getattr(getattr(layer, "source", None), "path", None)
        held = store.stack_of(key)  # a lazy layer's stack as read for the run
        return ExportRecord.of(
            entry.shown,
            stack=layer.data if held is None else held,
            angles_deg=entry.angles_deg,
            mask=None if pipe is None else pipe.mask,
            source=None if source is None else str(source),
            layer_name=layer.name,
            scene=None if pipe is None else store.scene(key),
        )
