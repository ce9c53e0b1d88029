"""Batch and time-series widgets: the batch engine over a folder, change maps as layers.

- :class:`BatchWidget` ("Batch over a folder"): applies the current segmentation
  parameters (those of a docked *Segment by material* widget, a preset or a JSON file)
  to every scene of a folder through :func:`napari_polarseg.batch.iter_batch` (a local
  Dask cluster, a running scheduler, or inline), in a napari worker thread with a
  progress bar and *Cancel*, and shows the summary as a table.
- :class:`TimeSeriesWidget` ("Time series change map"): segments several angle-stack
  layers (days, in the chosen order) in one shared basis
  (:func:`napari_polarseg.engine.analysis.timeseries.segment_timeseries`) and adds the per-day
  segments and the change maps as Labels layers and the graded change score as an Image
  layer (:func:`add_timeseries_layers`).

Both are thin: the work is done by the engine; nothing here is needed by the CLI.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Generator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import (
    CheckBox,
    ComboBox,
    FileEdit,
    Label,
    LineEdit,
    PushButton,
    Select,
    SpinBox,
    Table,
)
from napari.utils.notifications import show_error

from .. import batch as batch_engine
from ..engine import PolarsegError, SegmentParams
from ..engine.analysis.change_test import DEFAULT_FALSE_ALARM
from ..engine.analysis.timeseries import METHODS, segment_timeseries
from ..engine.analysis.timeseries_result import TimeSeriesResult
from ..engine.methods.scene import pipeline_labels
from ..io import parse_angles
from ..io.read_options import ReadOptions
from ._base import ScrollingContainer, is_angle_stack
from ._layers import ANGLES_KEY, TAG, label_colormap, source_key
from ._runner import WorkerSlot
from .param_sources import PARAM_SOURCES, params_from
from .session import relay

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

#: Where the batch parameters come from.
#: False-alarm rates (per change block and pair of days) the time-series widget offers.
FALSE_ALARM_CHOICES = (1e-2, 1e-3, 1e-4, 1e-6)
#: Columns of the summary table in the widget.
TABLE_COLUMNS = (
    "scene",
    "status",
    "n_segments",
    "adjusted_rand_index",
    "task_seconds",
    "mean_reconstruction_error",
    "error",
)


def summary_table(rows: list[dict[str, Any]]) -> dict[str, list[Any]]:
    """Table data (column -> values) of a batch summary's scene rows."""

    def cell(value: Any) -> Any:
        if value is None:
            return ""
        if isinstance(value, float):
            return round(value, 4)
        return value

    return {col: [cell(r.get(col)) for r in rows] for col in TABLE_COLUMNS}


def batch_job(
    scenes: list[batch_engine.Scene],
    out: Path,
    params: SegmentParams,
    options: dict[str, Any],
    stop: threading.Event,
) -> Generator[tuple[str, int, int], None, batch_engine.BatchResult]:
    """Worker job: run the batch, yielding ``(scene: status, index, total)`` per scene.

    With a classifier file in ``options["read"]`` (*Apply classifier*), it is read and
    checked first, as ``polarseg batch --classifier`` does: a bad file stops the batch
    before any scene, with one message."""
    read = options.get("read")
    if read is not None and read.classifier:
        from ..classifier_file import load_pixel_classifier

        load_pixel_classifier(read.classifier)
    rows = batch_engine.iter_batch(scenes, out, params, cancel=stop.is_set, **options)
    index = itertools.count(1)

    def stage(row: dict[str, Any]) -> tuple[str, int, int]:
        return f"{row['scene']}: {row['status']}", next(index), len(scenes)

    return (yield from relay(rows, stage))


class BatchWidget(ScrollingContainer):
    """Apply the current parameters (or a saved classifier) to every scene of a folder.

    Scenes are the stack files (``.tif``, ``.npz``, …) and sub-folders of the input
    folder, or the entries matching *pattern*. Each goes to ``OUT/<scene>/`` as with
    ``polarseg segment``; ``OUT/batch_summary.csv`` and ``.json`` list the results,
    which the table shows. *scheduler* empty: a local Dask cluster of *workers*
    processes (0 = one per core); ``inline``: no Dask; else a scheduler address.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer (its *Segment by material* widget supplies the parameters).
    """

    dock_title = "Batch"

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(labels=True)
        self._viewer = viewer
        self._build_inputs()
        self.scheduler = LineEdit(
            label="scheduler",
            tooltip="Empty: a local Dask cluster; 'inline': no Dask (one scene after the "
            "other); or the address of a running dask.distributed scheduler",
        )
        self.workers = SpinBox(label="workers", value=0, min=0, max=256, tooltip="0: auto")
        self.resume = CheckBox(
            text="skip complete scenes (resume)",
            value=True,
            tooltip="Leave out the scenes whose result folder is already complete (to "
            "resume a batch that stopped); off: segment every scene again",
        )
        self.run_button = PushButton(
            text="Run batch",
            tooltip="Segment every input of the folder or pattern into its own result "
            "folder (as polarseg batch), in the background",
        )
        self.cancel_button = PushButton(
            text="Cancel", enabled=False, tooltip="Stop after the scenes that are running"
        )
        self.load_button = PushButton(
            text="Load summary", tooltip="Show the summary.csv of an earlier batch run"
        )
        self.status = Label(value="")
        self.status.native.setWordWrap(True)
        self.table = Table(value=summary_table([]))
        self.extend(
            [
                self.folder,
                self.pattern,
                self.out,
                self.source,
                self.params_file,
                self.classifier,
                self.scheduler,
                self.workers,
                self.resume,
                self.load_button,
                self.table,
            ]
        )
        self.footer = self.add_footer([self.run_button, self.cancel_button, self.status])
        self._stop = threading.Event()
        self.result: batch_engine.BatchResult | None = None
        self._slot = WorkerSlot("Batch", on_status=self._set_status, on_idle=self._on_idle)
        self.source.changed.connect(self._on_source)
        self.run_button.changed.connect(self.run)
        self.cancel_button.changed.connect(self.cancel)
        self.load_button.changed.connect(self.load_summary)
        stop, slot = self._stop, self._slot

        def _closed(*_: Any) -> None:
            stop.set()
            slot.cancel()

        self.native.destroyed.connect(_closed)

    def _build_inputs(self) -> None:
        """The input and output folders, the pattern and the parameters' source."""
        self.folder = FileEdit(
            label="input folder",
            mode="d",
            tooltip="The folder of scenes: each stack file (.tif, .npz, …), sub-folder of "
            "frames or raw camera frame named after its sensor (…_IMX250MZR.png) in it is "
            "one scene",
        )
        self.pattern = LineEdit(
            label="pattern",
            tooltip="Glob inside the folder, e.g. *.npz; empty: every stack file and sub-folder",
        )
        self.out = FileEdit(
            label="output folder",
            mode="d",
            tooltip="Where each scene's results go (OUT/<scene>/, as polarseg segment "
            "writes them) with batch_summary.csv and .json",
        )
        self.source = ComboBox(
            label="parameters",
            choices=list(PARAM_SOURCES),
            tooltip="The parameters of every scene: the docked Segment by material "
            "widget's values, a preset, or a parameters JSON file",
        )
        self.params_file = FileEdit(
            label="JSON file",
            mode="r",
            filter="*.json",
            visible=False,
            tooltip="A parameters JSON (from 'Save parameters…', 'Save best…' or a "
            "params.json of polarseg segment); missing fields take the thesis defaults",
        )

        from ..classifier_file.format import SUFFIX as CLASSIFIER_SUFFIX

        self.classifier = FileEdit(
            label="apply classifier",
            mode="r",
            filter=f"*{CLASSIFIER_SUFFIX}",
            tooltip="Optional: a saved pixel classifier (.polarseg-clf, from 'Save "
            "classifier…' or polarseg segment --save-classifier) labels every scene "
            "instead of the unsupervised method, as polarseg batch --classifier; empty: "
            "the parameters' method",
        )

    # -- inputs -----------------------------------------------------------------------
    def _on_source(self, value: str) -> None:
        self.params_file.visible = value == "JSON file"

    def params(self) -> SegmentParams:
        """The parameters the batch will use (raises PolarsegError)."""
        return params_from(self._viewer, self.source.value, self.params_file.value)

    def classifier_file(self) -> Path | None:
        """The classifier file *Apply classifier* names (None: empty; raises
        PolarsegError when it is not a file)."""
        value = str(self.classifier.value or "").strip()
        if value in ("", "."):
            return None
        path = Path(value).expanduser().resolve()
        if not path.is_file():
            raise PolarsegError(f"the classifier {path} is not a file")
        return path

    def scenes(self) -> list[batch_engine.Scene]:
        """The scenes the batch would run (raises PolarsegError)."""
        folder, out = self._folder(self.folder, "input"), self._folder(self.out, "output")
        pattern = self.pattern.value.strip()
        inputs = [str(folder / pattern)] if pattern else batch_engine.folder_inputs(folder)
        scenes = batch_engine.plan(inputs, out)
        if not scenes:
            raise PolarsegError(
                f"{folder}: no scenes found (stack files, sub-folders of frames, or raw "
                "camera frames named after their sensor, e.g. …_IMX250MZR.png; for other "
                "raw frames give a pattern such as *.png)"
            )
        return scenes

    @staticmethod
    def _folder(edit: FileEdit, what: str) -> Path:
        value = str(edit.value or "").strip()
        if value in ("", "."):
            raise PolarsegError(f"choose the {what} folder")
        return Path(value)

    # -- running ----------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self._slot.busy

    def run(self, *_: Any) -> None:
        """Start the batch in a worker thread; returns at once."""
        try:
            params = self.params()
            scenes = self.scenes()
            classifier = self.classifier_file()
        except PolarsegError as exc:
            self._set_status(f"error: {exc}")
            show_error(str(exc))
            return
        options = {
            "scheduler": self.scheduler.value.strip() or None,
            "n_workers": int(self.workers.value) or None,
            "resume": bool(self.resume.value),
        }
        if classifier is not None:  # every scene labelled by it (recorded in its marker)
            options["read"] = ReadOptions(classifier=str(classifier))
        out = self._folder(self.out, "output")
        self._stop = threading.Event()
        self.cancel_button.enabled = True
        self.run_button.enabled = False
        self._set_status(f"running {len(scenes)} scene(s)…")

        def on_result(run_id: int, result: batch_engine.BatchResult) -> None:
            self._show(result)

        self._slot.submit(
            batch_job, (scenes, out, params, options, self._stop), len(scenes), on_result
        )

    def cancel(self, *_: Any) -> None:
        """Stop the batch: running scenes are abandoned, the summary is still written."""
        self._stop.set()
        if self._slot.busy:
            self._set_status("cancelling…")

    def wait(self, timeout: float | None = 120.0) -> bool:
        """Process events until the batch has ended (scripts and tests)."""
        return self._slot.wait(timeout)

    def load_summary(self, *_: Any) -> None:
        """Show ``batch_summary.json`` of the output folder in the table."""
        try:
            data = batch_engine.read_summary(self._folder(self.out, "output"))
        except PolarsegError as exc:
            self._set_status(f"error: {exc}")
            show_error(str(exc))
            return
        self.table.value = summary_table(data.get("scenes", []))
        counts = data.get("counts", {})
        self._set_status(", ".join(f"{v} {k}" for k, v in counts.items()))

    def _show(self, result: batch_engine.BatchResult) -> None:
        self.result = result
        self.table.value = summary_table(result.records)
        self._set_status(
            f"{result.count('done')} done, {result.count('skipped')} skipped, "
            f"{result.count('failed')} failed, {result.count('cancelled')} cancelled"
            f" in {result.wall_seconds:.1f} s{result.rate_text()}"
            f" · {result.out / batch_engine.SUMMARY_CSV}"
        )

    def _set_status(self, text: str) -> None:
        try:
            self.status.value = text
        except RuntimeError:  # the widget is gone
            pass

    def _on_idle(self) -> None:
        try:
            self.cancel_button.enabled = False
            self.run_button.enabled = True
        except RuntimeError:
            pass


# -- time series ----------------------------------------------------------------------------


def read_timeseries_folder(folder: str | Path) -> dict[str, np.ndarray]:
    """Labels, change, change-score and distance maps of a ``polarseg timeseries`` folder.

    Returns ``{"labels": (T, H, W), "changes": (T − 1, H, W), "score": (T − 1, H, W),
    "distance": (T − 1, H, W)}`` (the last three when their files are there).
    """
    import tifffile

    root = Path(folder)
    labels = sorted(root.glob("labels_*.tif"))
    if not labels:
        raise PolarsegError(f"{root}: no labels_XX.tif (not a polarseg timeseries folder)")
    out = {"labels": np.stack([tifffile.imread(p) for p in labels]).astype(np.int32)}
    patterns = (
        ("changes", "change_*.tif"),
        ("score", "score_*.tif"),
        ("distance", "distance_*.tif"),
    )
    for key, pattern in patterns:
        files = sorted(root.glob(pattern))
        if files:
            out[key] = np.stack([tifffile.imread(p) for p in files])
    return out


def add_timeseries_layers(
    viewer: napari.viewer.Viewer,
    result: TimeSeriesResult | str | Path,
    name: str = "time series",
    source: Layer | None = None,
) -> list[Layer]:
    """Add a time series' segments and change maps to ``viewer``.

    Layers: ``<name> segments`` (Labels, days × H × W; segment k is label k + 1, the
    same on every day), ``<name> change`` (Labels, (days − 1) × H × W; 1 where the block
    changed segment from one day to the next, slider position t = day t + 1 → t + 2),
    ``<name> change score`` (Image, hidden; the graded change test, significant above
    ~3.1 at the default false-alarm rate) and ``<name> feature distance`` (Image,
    hidden); with a ``source`` each name ends in its name, e.g.
    ``time series change score (day 1)``. A folder without score maps (an older run)
    gets no score layer. Each layer is tagged as the plugin's output
    (:data:`~napari_polarseg.widgets._layers.TAG`, role ``time series …``), so no widget
    offers it as an angle stack (a day of another series).

    Parameters
    ----------
    viewer : napari.viewer.Viewer
    result : TimeSeriesResult, or a folder written by ``polarseg timeseries``
    name : str
        Prefix of the layer names.
    source : Layer, optional
        A layer whose last two axes' scale and translation the new layers take.
    """
    if isinstance(result, TimeSeriesResult):
        labels, changes = result.labels, result.changes
        score: np.ndarray | None = result.change_score
        distance: np.ndarray | None = result.feature_distance
    else:
        data = read_timeseries_folder(result)
        labels, changes = data["labels"], data.get("changes")
        score, distance = data.get("score"), data.get("distance")
        if changes is None:
            changes = labels[1:] != labels[:-1]
    place: dict[str, Any] = {}
    suffix, key = "", ""
    if source is not None:
        place = {"scale": tuple(source.scale[-2:]), "translate": tuple(source.translate[-2:])}
        suffix, key = f" ({source.name})", source_key(source)

    def own(kind: str) -> dict[str, Any]:
        meta = {TAG: {"role": f"time series {kind}", "source": key}}
        return {"name": f"{name} {kind}{suffix}", "metadata": meta, **place}

    layers = [
        viewer.add_labels(
            np.asarray(labels, np.int32) + 1,
            **own("segments"),
            opacity=0.6,
            colormap=label_colormap(),
        ),
        viewer.add_labels(np.asarray(changes, np.uint8), **own("change")),
    ]
    if score is not None:
        score = np.asarray(score, np.float32)
        layers.append(
            viewer.add_image(
                score,
                **own("change score"),
                colormap="inferno",
                contrast_limits=(0.0, max(float(score.max(initial=0.0)), 4.0)),
                visible=False,
            )
        )
    if distance is not None:
        layers.append(
            viewer.add_image(
                np.asarray(distance, np.float32),
                **own("feature distance"),
                colormap="magma",
                visible=False,
            )
        )
    return layers


def timeseries_job(
    stacks: list[np.ndarray],
    angles: list[np.ndarray],
    params: SegmentParams,
    method: str,
    false_alarm: float = DEFAULT_FALSE_ALARM,
) -> Generator[tuple[str, int, int], None, TimeSeriesResult]:
    """Worker job: the time-series engine, yielding after each step."""
    steps: list[tuple[str, int, int]] = []
    result = segment_timeseries(
        stacks,
        angles,
        params,
        method=method,
        false_alarm=false_alarm,
        progress=lambda *s: steps.append(s),
        day_labels=pipeline_labels,  # a method that does not cut blocks labels day 1
    )
    yield from steps
    return result


class TimeSeriesWidget(ScrollingContainer):
    """Segment several angle-stack layers (days of one view) and map what changed.

    Select the day layers in time order (the list order), choose the method, the
    false-alarm rate of the change test and the parameters (as in :class:`BatchWidget`),
    press *Run*: adds the layers of :func:`add_timeseries_layers`.
    """

    dock_title = "Time series"

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(labels=True)
        self._viewer = viewer
        self.days = Select(
            label="days (in order)",
            choices=self._stack_choices,
            tooltip="The angle-stack layers of the same view on successive days, in time "
            "order (the list's order); at least two",
        )
        self.method = ComboBox(
            label="method",
            choices=list(METHODS),
            value=METHODS[0],
            tooltip="tracked: cut day 1 and move only the blocks whose polarisation "
            "changed significantly to the segment of what they changed into; reference: "
            "give every day's blocks the nearest day-1 segment; joint: one cut over all "
            "days' blocks",
        )
        self.false_alarm = ComboBox(
            label="false-alarm rate",
            choices=[(f"{p:g} per block", p) for p in FALSE_ALARM_CHOICES],
            value=DEFAULT_FALSE_ALARM,
            tooltip="Share of unchanged blocks the change test may flag by chance: lower "
            "flags fewer blocks, only the surer changes",
        )
        # the time series cuts one block graph of all days: no superpixel preset
        self.source = ComboBox(
            label="parameters",
            choices=[s for s in PARAM_SOURCES if s not in ("auto", "JSON file")],
            tooltip="The parameters of every day: the docked Segment by material widget's "
            "values or a preset (no auto: the series cuts one block graph of all days)",
        )
        self.run_button = PushButton(
            text="Run", tooltip="Segment the time series and test every block for change"
        )
        self.status = Label(value="")
        self.status.native.setWordWrap(True)
        self.result: TimeSeriesResult | None = None
        self.extend([self.days, self.method, self.false_alarm, self.source])
        self.footer = self.add_footer([self.run_button, self.status])
        self._slot = WorkerSlot("Time series", on_status=self._set_status)
        self.run_button.changed.connect(self.run)
        events = viewer.layers.events
        events.inserted.connect(self._refresh)
        events.removed.connect(self._refresh)
        self.native.destroyed.connect(lambda *_: self._slot.cancel())

    def _stack_choices(self, _widget: Any = None) -> list[tuple[str, Layer]]:
        return [(layer.name, layer) for layer in self._viewer.layers if is_angle_stack(layer)]

    def _refresh(self, *_: Any) -> None:
        try:
            self.days.reset_choices()
        except RuntimeError:
            pass

    @property
    def busy(self) -> bool:
        return self._slot.busy

    def wait(self, timeout: float | None = 120.0) -> bool:
        return self._slot.wait(timeout)

    def params(self) -> SegmentParams:
        """Parameters from the Segment widget or a preset (raises PolarsegError)."""
        return params_from(self._viewer, self.source.value)

    def run(self, *_: Any) -> None:
        layers = list(self.days.value)
        try:
            if len(layers) < 2:
                raise PolarsegError("select at least two angle-stack layers (the days)")
            angles = []
            for layer in layers:
                meta = layer.metadata.get(ANGLES_KEY) if isinstance(layer.metadata, dict) else None
                if meta is None:
                    raise PolarsegError(f"layer {layer.name!r} has no polariser angles")
                angles.append(np.deg2rad(parse_angles(",".join(str(a) for a in meta), option=None)))
            params = self.params()
        except PolarsegError as exc:
            self._set_status(f"error: {exc}")
            show_error(str(exc))
            return
        stacks = [np.asarray(layer.data) for layer in layers]

        def on_result(run_id: int, result: TimeSeriesResult) -> None:
            self.result = result
            add_timeseries_layers(self._viewer, result, source=layers[0])
            changed = ", ".join(f"{f:.0%}" for f in result.changed_fraction())
            significant = ", ".join(str(int(s.sum())) for s in result.change_significant)
            self._set_status(
                f"{result.n_days} days, {result.n_segments} segments "
                f"({len(result.changed_segments)} changed materials); pixels changed "
                f"segment: {changed}; significant change blocks: {significant}"
            )

        args = (stacks, angles, params, self.method.value, self.false_alarm.value)
        self._slot.submit(timeseries_job, args, len(layers) + 5, on_result)

    def _set_status(self, text: str) -> None:
        try:
            self.status.value = text
        except RuntimeError:
            pass
