"""The Segment widget's files: the pixel classifier (*Load classifier…*, *Save
classifier…*, *Clear*) and *Export results…*, each written or read in a worker.

Two objects the widget holds (:class:`ClassifierFiles`, :class:`ResultExport`); what
they need of it comes in as a :class:`SegmentHost` (its public members) and callables.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from magicgui.widgets import Container, PushButton

from ..engine import PolarsegError
from ._base import ClassifierListener, ask_file
from ._layers import source_key
from ._runner import WorkerSlot
from .docks import docked
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
    import napari
    from magicgui.widgets import ComboBox
    from napari.layers import Layer
    from qtpy.QtWidgets import QWidget

    from ..engine import SegmentationResult
    from ..engine.classifier.pixel_classifier import PixelClassifier


class SegmentHost(Protocol):
    """What the file parts use of the Segment widget (its public members)."""

    stack_layer: ComboBox
    native: QWidget

    def current_scribbles(self) -> tuple[str | None, Any]: ...

    def material_names(self) -> dict[int, str]: ...

    def shown_result(self, layer: Layer) -> SegmentationResult | None: ...

    def run(self, *_: Any) -> None: ...

    @property
    def store(self) -> PipelineStore: ...


class ClassifierFiles:
    """The pixel classifier behind the segments, its files and the loaded one.

    Parameters
    ----------
    host : SegmentHost
        The Segment widget (stack chooser, scribbles, results, ``run``).
    viewer : napari.viewer.Viewer
        Its viewer (the docked plots get each new classifier).
    status, fail : callable
        The widget's status line and error report.
    changed : callable()
        A change that a live update reruns after (the classifier was cleared).
    inputs_changed : callable()
        The scribbles or the loaded classifier changed (the cut's controls follow).
    """

    def __init__(
        self,
        host: SegmentHost,
        viewer: napari.viewer.Viewer,
        status: Callable[[str], None],
        fail: Callable[[PolarsegError], None],
        changed: Callable[[], None],
        inputs_changed: Callable[[], None],
    ) -> None:
        self._host, self._viewer = host, viewer
        self._status, self._fail = status, fail
        self._changed, self._inputs_changed = changed, inputs_changed
        #: Per stack key: the pixel classifier behind the stack's ``segments`` layer.
        self._classifiers: dict[str, PixelClassifier] = {}
        #: The classifier *Load classifier…* read, while it is applied.
        self.loaded: LoadedClassifier | None = None
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
        host.stack_layer.changed.connect(self.update_buttons)

    @property
    def classifier(self) -> PixelClassifier | None:
        """The pixel classifier behind the chosen stack's segments (None if they did not
        come from it): what *Save classifier…* writes."""
        layer = self._host.stack_layer.value
        return None if layer is None else self.shown_classifier(layer)

    def shown_classifier(self, layer: Layer) -> PixelClassifier | None:
        """The pixel classifier behind ``layer``'s ``segments`` layer, if this widget made
        them with one (trained on strokes or loaded)."""
        if self._host.shown_result(layer) is None:
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
            self._status(f"saved the classifier to {written}")

        self._status(f"saving the classifier to {path}…")
        classifier = classifier.named(self._host.material_names())
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
            try:
                key, strokes = self._host.current_scribbles()
            except PolarsegError:
                key, strokes = None, None
            self._loads += 1
            self.loaded = LoadedClassifier(
                classifier, path, (key, content_digest(strokes)), self._loads
            )
            self._classifier_dir = path.parent
            self.update_buttons()
            self._inputs_changed()
            self._status(f"loaded the classifier {path.name}: {classifier_text(classifier)}")
            if self._host.stack_layer.value is not None:
                self._host.run()

        self._status(f"reading the classifier {path}…")
        self.slot.submit(read_classifier_job, (path,), 1, on_result)
        return True

    def clear_classifier(self, *_: Any) -> None:
        """Stop applying the loaded classifier (a rerun trains on the strokes again, or
        segments without supervision when no scribbles layer is chosen)."""
        if self.loaded is None:
            return
        name, self.loaded = self.loaded.path.name, None
        self.update_buttons()
        self._inputs_changed()
        self._status(f"the classifier {name} is no longer applied")
        self._changed()

    def ask_path(self, save: bool) -> str | None:
        """A classifier file chosen in a Qt dialog (None when cancelled)."""
        from ..classifier_file import SUFFIX

        filters = f"Classifier (*{SUFFIX});;All files (*)"
        if save:
            layer = self._host.stack_layer.value
            stem = "classifier" if layer is None else f"{layer.name} classifier"
            start = str(self._classifier_dir / f"{stem}{SUFFIX}")
            return ask_file(self._host.native, "Save classifier", start, filters, save=True)
        parent = self._host.native
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

    def forget(self, keep: set[str]) -> None:
        """Drop the classifiers of stack layers whose key is not in ``keep``."""
        for key in set(self._classifiers) - keep:
            del self._classifiers[key]
        self.update_buttons()

    def record(self, layer: Layer, classifier: PixelClassifier | None) -> None:
        """Keep the classifier behind ``layer``'s segments (for *Save classifier…* and
        the plots' feature importances)."""
        key = source_key(layer)
        if classifier is None and key not in self._classifiers:
            return
        if classifier is None:
            del self._classifiers[key]
        else:
            self._classifiers[key] = classifier
        self.update_buttons()
        self._notify_plots(layer, classifier)

    def _notify_plots(self, layer: Layer, classifier: PixelClassifier | None) -> None:
        """Hand every docked :class:`ClassifierListener` (the *Polarisation plots*
        widget) the stack's new classifier."""
        for widget in docked(self._viewer, ClassifierListener):
            widget.set_classifier(layer, classifier)


class ResultExport:
    """*Export results…*: the chosen stack's last result as the folder ``polarseg
    segment --out`` writes.

    Parameters
    ----------
    host : SegmentHost
        The Segment widget (stack chooser, the pipeline of a stack).
    status, fail : callable
        The widget's status line and error report.
    """

    def __init__(
        self,
        host: SegmentHost,
        status: Callable[[str], None],
        fail: Callable[[PolarsegError], None],
    ) -> None:
        self._host, self._status, self._fail = host, status, fail
        #: Per stack key: what *Export results…* writes (the last result shown).
        self._exports: dict[str, ExportRecord] = {}
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
        host.stack_layer.changed.connect(self.update_button)

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
        layer = self._host.stack_layer.value
        record = None if layer is None else self._exports.get(source_key(layer))
        if record is None:
            self._fail(PolarsegError("nothing to export: run a segmentation of this stack first"))
            return False
        folder = Path(folder)
        options = {"overview": overview, "plots": plots}
        record = record.named(self._host.material_names())  # renamed since the run

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
            self._host.native, "Export results into a folder", str(self._export_dir)
        )
        if folder:
            self.export_results(folder)

    def update_button(self, *_: Any) -> None:
        """*Export results…* while the chosen stack has a result."""
        layer = self._host.stack_layer.value
        try:
            self.export_button.enabled = layer is not None and source_key(layer) in self._exports
        except RuntimeError:  # the widget was deleted
            pass

    def forget(self, keep: set[str]) -> None:
        """Drop the records of stack layers whose key is not in ``keep``."""
        for key in set(self._exports) - keep:
            del self._exports[key]
        self.update_button()

    def reshown(self, layer: Layer, params: Any) -> None:
        """``layer``'s result is shown again for ``params``, which its method does not
        read: the folder records them (its maps are computed for them at the export)."""
        record = self._exports.get(source_key(layer))
        if record is not None and record.scene is not None:
            self._exports[source_key(layer)] = replace(record, params=params)

    def record(self, layer: Layer, angles_deg: np.ndarray, shown: ShownResult) -> None:
        """Keep what *Export results…* needs of the result just shown for ``layer``."""
        key = source_key(layer)
        store = self._host.store
        pipe = store.get(key)  # the pipeline that made the result (its pixel mask)
        source = getattr(getattr(layer, "source", None), "path", None)
        self._exports[key] = ExportRecord.of(
            shown,
            stack=layer.data,
            angles_deg=angles_deg,
            mask=None if pipe is None else pipe.mask,
            source=None if source is None else str(source),
            layer_name=layer.name,
            scene=None if pipe is None else store.scene(key),
        )
        self.update_button()
