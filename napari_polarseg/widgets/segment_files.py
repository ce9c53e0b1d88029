"""The Segment widget's files: the pixel classifier (*Load classifier…*, *Save
classifier…*, *Clear*) and *Export results…*, each written or read in a worker."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import Container, PushButton

from ..engine import PolarsegError
from ._base import ClassifierListener, WidgetPart, ask_file
from ._layers import source_key
from ._runner import WorkerSlot
from .session import (
    ExportRecord,
    LoadedClassifier,
    PipelineStore,
    ShownResult,
    classifier_text,
    content_digest,
    export_job,
    read_classifier_job,
    write_classifier_job,
)

if TYPE_CHECKING:
    from napari.layers import Layer

    from ..engine.analysis.pixel_classifier import PixelClassifier


class ClassifierFiles(WidgetPart):
    """Mixin of :class:`~napari_polarseg.widgets.segment.SegmentWidget`: the pixel
    classifier behind the segments, its files and the loaded one.

    Uses the widget's viewer, stack chooser, scribbles (``current_scribbles``), results
    (``shown_result``), ``run`` and ``_on_value_changed``, and its status line.
    """

    current_scribbles: Any
    shown_result: Any
    run: Any
    _on_value_changed: Any
    _on_scribbles_changed: Any

    def _build_classifier_controls(self) -> None:
        """The classifier-file buttons and the state behind them."""
        #: Per stack key: the pixel classifier behind the stack's ``segments`` layer.
        self._classifiers: dict[str, PixelClassifier] = {}
        #: The classifier *Load classifier…* read, while it is applied.
        self.loaded: LoadedClassifier | None = None
        self._loads = 0  # serial number of the last load
        self._classifier_dir = Path.home()
        self._classifier_slot = WorkerSlot("Classifier file", on_status=self._set_status)
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

    def _ask_classifier_path(self, save: bool) -> str | None:
        """A classifier file chosen in a Qt dialog (None when cancelled)."""
        from ..classifier_file import SUFFIX

        filters = f"Classifier (*{SUFFIX});;All files (*)"
        if save:
            layer = self.stack_layer.value
            stem = "classifier" if layer is None else f"{layer.name} classifier"
            start = str(self._classifier_dir / f"{stem}{SUFFIX}")
            return ask_file(self.native, "Save classifier", start, filters, save=True)
        return ask_file(self.native, "Load classifier", str(self._classifier_dir), filters)

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


class ResultExport(WidgetPart):
    """Mixin of :class:`~napari_polarseg.widgets.segment.SegmentWidget`: *Export
    results…*, the chosen stack's last result as the folder ``polarseg segment --out``
    writes.

    Uses the widget's stack chooser, pipelines (``store``) and status line.
    """

    store: PipelineStore

    def _build_export_controls(self) -> None:
        """*Export results…* and the records it writes."""
        #: Per stack key: what *Export results…* writes (the last result shown).
        self._exports: dict[str, ExportRecord] = {}
        self._export_dir = Path.home()
        self._export_slot = WorkerSlot("Export results", on_status=self._set_status)
        self.export_button = PushButton(
            text="Export results…",
            enabled=False,
            tooltip="Write the last result of the chosen stack into a folder: labels, maps, "
            "mask, per-segment statistics (segments.csv), params.json (loadable with 'Load "
            "parameters…' and polarseg segment --params), summary.json and overview.png, "
            "as polarseg segment --out writes them",
        )

    def export_results(
        self, folder: str | Path, *, overview: bool = True, plots: bool = False
    ) -> bool:
        """Write the chosen stack's last result into ``folder``, in a worker thread.

        The files of ``polarseg segment --out`` (:func:`napari_polarseg.outputs.
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
