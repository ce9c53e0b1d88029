"""Segment one input into a result folder: the job behind ``polarseg segment`` and batch.

:func:`segment_to_folder` reads an input with :class:`ReadOptions`, segments it (normalized
cut, or a pixel classifier trained on scribbles or loaded from a file), and writes the
``segment`` result folder (:func:`napari_polarseg.outputs.write_result_folder`) with the
optional files of :class:`OutputOptions`. Everything is computed before the first file is
written. What a command line would say about the run (its summary line, the warning of a
degenerate result, the classifier and evaluation lines, worded in
:mod:`napari_polarseg.messages`) comes back as :class:`Message` data in the
:class:`FolderResult`; nothing is printed here. This module never imports napari, Qt or
the command line.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import io as pio
from .engine import Scene, disk_arrays
from .engine.analysis.evaluation import adjusted_rand_index, evaluate
from .engine.errors import PolarsegError
from .engine.limits import work_bytes
from .engine.params import SegmentParams
from .engine.physics.pixel_mask import PixelMask, validity_mask
from .engine.registered import computes_block_maps
from .engine.run_memory import check_pipeline_memory
from .engine.timing import timed
from .io.read_options import ReadOptions
from .job_options import OutputOptions
from .job_run import Run
from .messages import (
    PROG,
    Message,
    classifier_messages,
    degenerate_warning,
    evaluation_message,
    report_messages,
)
from .outputs import classifier_summary, result_files, write_result_folder
from .status_line import StatusLine

#: Progress callback of a run: (stage, stages done, total), as a stage starts and within.
Progress = Callable[[str, float, int], None]


@dataclass
class FolderResult:
    """What :func:`segment_to_folder` did: the folder, its files, the run and the messages.

    Attributes
    ----------
    out : Path
        The result folder.
    written : list of str
        The files written, relative to ``out``.
    run : Run
        The run (stack, parameters, result, mask, seconds).
    summary : dict
        The job's items of ``summary.json`` (seconds, classifier, adjusted Rand index).
    messages : list of Message
        The lines a command line prints about the run, in order.
    degenerate : str or None
        The warning line of a degenerate result (also among ``messages``), or None.
    evaluation : dict or None
        ``evaluation.json`` against a ground-truth file.
    """

    out: Path
    written: list[str]
    run: Run
    summary: dict[str, Any]
    messages: list[Message]
    degenerate: str | None = None
    evaluation: dict[str, Any] | None = None


def pixel_mask(data: pio.StackData, read: ReadOptions) -> PixelMask:
    """Validity mask: the reader's saturated samples, black samples, the user's region.
    A stack read lazily is read into memory here, once: the engine takes it whole."""
    region = None
    if read.mask:
        superpixel = data.metadata.get("demosaic") == "superpixel"
        raw_shape = data.metadata.get("raw_shape") if superpixel else None
        region = pio.read_mask(read.mask, data.stack.shape[1:], raw_shape)
    # a lazy stack read and the flags (1 byte a sample) made in temporary files when the
    # run's full-size arrays do not fit its limit less the stack and the flags, as the
    # pipeline places its own
    held = data.stack.nbytes + data.stack.size  # as Pipeline.held_limit counts them
    with disk_arrays.full_size_limit(work_bytes(read.max_bytes(), held)):
        pio.in_memory(data, read.max_bytes())
        return validity_mask(
            data.stack,
            saturation=data.metadata.get("saturation_level"),
            dark_level=read.dark_level,
            region=region,
            saturated=data.saturated,
        )


@dataclass
class LabelSource:
    """Labels from the pixel classifier instead of the cut: trained on ``scribbles`` or
    the classifier saved in ``classifier_file``; what it produced is kept here."""

    scribbles: np.ndarray | None = None
    scribbles_file: str | None = None
    classifier_file: str | None = None
    segmentation: Any = None

    def label(self, run: Run, progress: Progress | None = None, maps: bool = True) -> None:
        """Label ``run`` with the pixel classifier (sets ``run.result``)."""
        from .classifier_file import load_pixel_classifier
        from .engine.classifier.pixel_segmentation import PixelSegmentation

        classifier = None
        if self.classifier_file:
            classifier = load_pixel_classifier(self.classifier_file)
        inputs = {"scribbles": self.scribbles, "classifier": classifier}
        inputs["colour_stack"] = run.colour_stack
        try:
            assert run.scene is not None
            result = run.scene.segment(
                run.params, inputs, maps=maps, reconstruction=maps, progress=progress
            )
        except PolarsegError as exc:
            where = self.scribbles_file or self.classifier_file
            raise PolarsegError(f"{where}: {exc}") from None
        extra = run.scene.method_output(run.params, inputs).extra
        self.segmentation = PixelSegmentation(
            result, extra["prediction"], extra["classifier"], extra["seconds"]
        )
        run.result = result
        run.seconds["classifier"] = float(sum(extra["seconds"].values()))

    def summary(self) -> dict[str, Any]:
        """The classifier's items of ``summary.json``."""
        labels_from = "scribbles" if self.scribbles is not None else "classifier"
        return classifier_summary(self.segmentation, labels_from)


def segment_data(
    data: pio.StackData,
    params: SegmentParams,
    register: bool,
    mask: PixelMask | None = None,
    max_bytes: int | None = None,
    labels_by: LabelSource | None = None,
    status: StatusLine | None = None,
    progress: Progress | None = None,
    maps: bool = True,
) -> Run:
    """Register (optionally) and segment an angle stack in memory; seconds per step.

    ``maps``: also the thesis maps and the reconstruction-error map (a method that
    declares ``block_maps``, the thesis method, computes them in any case; the memory
    check counts the blocks only then). ``max_bytes`` (default: the engine's
    :func:`~napari_polarseg.engine.limits.memory_limit`) is the run's memory limit: the
    methods that tile choose their tiles from it, and the run is refused only when its
    estimate with those tiles exceeds it
    (:func:`~napari_polarseg.engine.run_memory.check_pipeline_memory`)."""
    status = status or StatusLine(False, PROG)
    seconds: dict[str, float] = {}
    # the engine takes the stack in memory: a stack read lazily is read here, once
    data = pio.in_memory(data, max_bytes or pio.ReadOptions().max_bytes())
    stack, shifts = data.stack, None
    maps = maps or computes_block_maps(params.method) and labels_by is None
    check_pipeline_memory(stack.shape, params, max_bytes, blocks=maps, **run_kinds(data, labels_by))
    if mask is None:
        mask = validity_mask(
            stack, saturation=data.metadata.get("saturation_level"), saturated=data.saturated
        )
    colour_stack = data.colour_stack
    if register:
        # scipy.signal (a second of imports) only when registering
        from .engine.physics.registration import register_stack, shift_frames

        status.show("registering the frames")
        with timed(seconds, "register"):
            stack, shifts = register_stack(stack)
            mask = mask.shifted(shifts)
            if colour_stack is not None:
                colour_stack = shift_frames(colour_stack, shifts)
    with timed(seconds, "segment"):
        scene = Scene(stack, data.angles_rad, mask=mask, max_bytes=max_bytes)
        run = Run(data, params, stack, None, shifts, seconds, mask, scene.pipeline)  # type: ignore[arg-type]
        run.colour_stack = colour_stack
        run.scene = scene
        if labels_by is None:
            total = len(scene.stages(params, maps=maps, reconstruction=maps))
            status.stage("polarisation", 1, total, "segmenting:")
            run.result = scene.segment(params, maps=maps, reconstruction=maps, progress=progress)
        else:
            status.show("pixel classifier: features, training and prediction")
            labels_by.label(run, progress, maps)
    return run


def run_kinds(data: pio.StackData, labels_by: LabelSource | None) -> dict[str, Any]:
    """What the memory estimate of a run needs to know of it beyond its shape: the
    bytes a sample of the stack as the engine keeps it (an integer stack as it is, a
    float one as float64), and for the pixel classifier its channels (the luminance and
    a colour stack's colours) and classes (the scribbles' materials, else 4)."""
    dtype = np.dtype(data.stack.dtype)
    itemsize = dtype.itemsize if np.issubdtype(dtype, np.integer) else 8
    kinds: dict[str, Any] = {"itemsize": itemsize}
    if labels_by is not None:
        colours = data.colour_stack
        kinds["scribbles"] = True
        kinds["channels"] = 1 + (0 if colours is None else int(np.shape(colours)[0]))
        if labels_by.scribbles is not None:
            values = np.unique(labels_by.scribbles)
            kinds["n_classes"] = max(int(np.count_nonzero(values)), 2)
    return kinds


def _resolved(name: str | None) -> str | None:
    return None if name in (None, "array") else str(Path(name).resolve())


def input_info(data: pio.StackData, read: ReadOptions) -> dict[str, Any]:
    """What ``params.json`` records of the reading, beyond
    :func:`~napari_polarseg.outputs.result_folder.run_info`."""
    meta = data.metadata
    return {
        "input_format": meta.get("format"),
        "input_files": meta.get("files"),
        "angles_from": meta.get("angles_from"),
        "mosaic_layout_deg": meta.get("mosaic_layout_deg"),
        "raw_shape": meta.get("raw_shape"),
        "channel": read.channel,
        "demosaic": meta.get("demosaic"),
        "bayer": meta.get("bayer"),
        "sensor": meta.get("sensor"),
        "dark_frame": _resolved(meta.get("dark_frame")),
        "offset": meta.get("offset"),
        "bits_per_sample": meta.get("bits_per_sample"),
        "mask_file": _resolved(read.mask),
    }


def _seconds_summary(run: Run, read_seconds: float) -> dict[str, Any]:
    """The job's items of ``summary.json`` (beyond ``result.summary()``): seconds."""
    return {
        "io_seconds": {
            "read": round(read_seconds, 6),
            "register": round(run.seconds.get("register", 0.0), 6),
        },
        "segment_seconds": round(run.seconds["segment"], 6),
    }


def segment_to_folder(
    input: pio.PathLike | Sequence[pio.PathLike],
    out: pio.PathLike,
    params: SegmentParams,
    read: ReadOptions | None = None,
    outputs: OutputOptions | None = None,
    *,
    command: str = "segment",
    status: StatusLine | None = None,
    progress: Progress | None = None,
) -> FolderResult:
    """Read ``input`` (a stack file, folder, raw frame, or one file per frame), segment it
    with ``params`` and write the ``segment`` result folder ``out``.

    Raises :class:`PolarsegError` for bad input and
    :class:`napari_polarseg.outputs.OutputError` when the folder cannot be written.
    """
    read = read or ReadOptions()
    status = status or StatusLine(False, PROG)
    first = input if isinstance(input, (str, Path)) else list(input)[0]
    status.show(f"reading {Path(first).name}")
    seconds: dict[str, float] = {}
    with timed(seconds, "read"):
        data = pio.read_stack(input, options=read)
    return data_to_folder(
        data,
        out,
        params,
        read,
        outputs,
        read_seconds=seconds["read"],
        command=command,
        status=status,
        progress=progress,
    )


def _label_source(
    read: ReadOptions, outputs: OutputOptions, scribbles: np.ndarray | None
) -> LabelSource | None:
    """The pixel classifier that labels the run (scribbles or a saved one), or None."""
    if outputs.save_classifier and scribbles is None:
        raise PolarsegError("--save-classifier needs --scribbles (a classifier to train)")
    if scribbles is None and not read.classifier:
        return None
    return LabelSource(scribbles, read.scribbles, read.classifier)


def _files_info(read: ReadOptions) -> dict[str, Any]:
    """The label and truth files ``params.json`` records, resolved."""
    info = {}
    for key, name in (
        ("scribbles_file", read.scribbles),
        ("classifier_file", read.classifier),
        ("ground_truth_file", read.ground_truth),
    ):
        if name:
            info[key] = str(Path(name).resolve())
    return info


def _folder_options(outputs: OutputOptions) -> dict[str, Any]:
    """The keywords of :func:`write_result_folder` that ``outputs`` chooses."""
    chosen = {"overview": outputs.overview, "plots": outputs.plots}
    return {**chosen, "image_format": outputs.image_format}


def data_to_folder(
    data: pio.StackData,
    out: pio.PathLike,
    params: SegmentParams,
    read: ReadOptions | None = None,
    outputs: OutputOptions | None = None,
    *,
    read_seconds: float = 0.0,
    command: str = "segment",
    extra: dict[str, Any] | None = None,
    note_repeated: bool = True,
    status: StatusLine | None = None,
    progress: Progress | None = None,
) -> FolderResult:
    """:func:`segment_to_folder` of already-read data (``read`` still gives the mask,
    registration, label files and memory limit; ``extra`` goes into ``summary.json``)."""
    read = read or ReadOptions()
    outputs = outputs or OutputOptions()
    status = status or StatusLine(False, PROG)
    mask = pixel_mask(data, read)
    shape = data.stack.shape[1:]
    scribbles = pio.read_labels(read.scribbles, shape, "scribbles") if read.scribbles else None
    truth_file = read.ground_truth
    truth = pio.read_labels(truth_file, shape, "ground truth") if truth_file else None
    source = _label_source(read, outputs, scribbles)
    maps = outputs.thesis_maps or outputs.plots
    run = segment_data(
        data, params, read.register, mask, read.max_bytes(), source, status, progress, maps
    )
    probabilities = uncertainty = None
    summary = {**_seconds_summary(run, read_seconds), **(extra or {})}
    if source is not None:
        probabilities = source.segmentation.prediction.probabilities
        uncertainty = source.segmentation.prediction.uncertainty
        summary.update(source.summary())
        summary["classifier_seconds"] = round(run.seconds["classifier"], 6)
    if data.ground_truth is not None:
        summary["adjusted_rand_index"] = adjusted_rand_index(data.ground_truth, run.result.labels)
    evaluation = None
    if truth is not None:
        # the block accuracy for a method that cuts blocks; the pixel measures for all
        window = run.params.window if run.result.cuts_blocks else None
        evaluation = {
            "ground_truth": str(Path(truth_file).resolve()),
            **evaluate(truth, run.result.labels, window),
        }
    out = Path(out)
    status.show(f"writing the results to {out}")
    before = result_files(out) if out.is_dir() else []
    written = write_result_folder(
        out,
        stack=run.stack,
        angles_deg=data.angles_deg,
        result=run.result,
        mask=run.mask,
        source=str(Path(data.source).resolve()),
        command=command,
        probabilities=probabilities,
        uncertainty=uncertainty,
        evaluation=evaluation,
        shifts=run.shifts,
        info={**input_info(data, read), **_files_info(read)},
        summary=summary,
        truth=truth if truth is not None else data.ground_truth,
        **_folder_options(outputs),
    )
    status.clear()
    removed = [name for name in before if name not in written]  # an earlier run's
    messages = report_messages(out, run, written, note_repeated, removed)
    if source is not None:
        if outputs.save_classifier:
            from .classifier_file import save_pixel_classifier

            save_pixel_classifier(outputs.save_classifier, source.segmentation.classifier)
        clf = source.segmentation.classifier
        messages += classifier_messages(clf, source.classifier_file, outputs.save_classifier)
    if evaluation is not None:
        messages.append(evaluation_message(evaluation))
    return FolderResult(out, written, run, summary, messages, degenerate_warning(run), evaluation)
