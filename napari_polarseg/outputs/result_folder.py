"""A segmentation's results as a folder: what ``polarseg segment --out DIR`` writes.

:func:`write_result_folder` writes, from a :class:`~napari_polarseg.engine.SegmentationResult`
and the angle stack it came from, the files of the ``segment`` contract (the table in
:mod:`napari_polarseg.cli`): ``labels.tif``, the float maps of
:data:`~napari_polarseg.outputs.contract.FLOAT_OUTPUTS`, ``mask.tif``, ``segments.csv``,
``params.json`` (its ``"params"`` entry is what ``polarseg segment --params`` and the
plugin's *Load parameters…* read), ``summary.json``, and on request ``overview.png``
(:mod:`napari_polarseg.outputs.overview`), ``plots/*.png``
(:mod:`napari_polarseg.outputs.figures`), ``probabilities.tif`` (scribble classifier) and
``evaluation.json`` (ground truth), and the polarisation views ``stokes.tif`` (S0, S1,
S2) and ``aolp_dolp.png`` (the AoLP/DoLP HSV composite). The command line and the
*Segment by material* widget's *Export results…* both write through it.

Everything (statistics, figures, JSON) is computed before the first file is written, and
every file is written to a temporary name and renamed (:func:`napari_polarseg.io.atomic_output`),
so a failure never leaves a partial file where a good one was; a file that cannot be
written raises :class:`~napari_polarseg.outputs.contract.OutputError` naming it. No
napari, no Qt: usable from scripts.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import shutil
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .. import io as pio
from ..engine import SegmentationResult, valid_blocks
from ..engine.analysis.evaluation import segment_statistics
from ..engine.analysis.views import CompositeParams, aolp_dolp_composite, auto_dolp_max
from ..engine.errors import PolarsegError
from ..engine.physics.pixel_mask import PixelMask
from ..engine.physics.polarimage import duplicate_angle_frames
from ..engine.physics.stokes import STOKES_CONVENTION
from .band_statistics import banded_segment_statistics
from .bands import (
    as_dtype,
    auto_dolp_max_banded,
    composite_image,
    is_large,
    labels_image_banded,
    stokes_image,
    used_pixels_banded,
    write_picture,
)
from .contract import (
    COMPOSITE_FILE,
    EVALUATION_SUMMARY_KEYS,
    FLOAT_OUTPUTS,
    MASK_META,
    PROBABILITY_META,
    SEGMENTS_CSV_COLUMNS,
    STOKES_FILE,
    UNCERTAINTY_META,
    OutputError,
    labels_image,
    labels_meta,
    stale_files,
    used_pixels,
)
from .image_formats import IMAGE_FORMATS
from .overview import render_overview

#: One file to write: (name relative to the folder, the writing, listed among the files
#: written). The name is the one an :class:`OutputError` gives when the writing fails.
Step = tuple[str, Callable[[], None], bool]

# -- the pieces -----------------------------------------------------------------------------


def segment_rows(result: SegmentationResult) -> list[dict[str, Any]]:
    """Per-segment statistics of ``result`` (the rows of ``segments.csv``).

    One row per value of the pixel labels (0 to the largest; ``pixels`` is their count),
    for every method. Means over the used pixels (``result.valid``) and, for the PCA
    features (only when the run computed the thesis maps), over the blocks that entered
    the graph (:func:`~napari_polarseg.engine.stages.valid_blocks`). ``segment`` is the
    segment's value in ``labels.tif`` (a scribble classifier's: the scribble value of
    its material) and ``name`` its material's name (empty without ``result.materials``).
    """
    valid = result.valid
    block_valid = None
    if valid is not None and result.features is not None:  # blocks only with the maps
        block_valid = valid_blocks(valid, result.params.window)
    statistics = banded_segment_statistics if is_large(result.labels.shape) else segment_statistics
    rows = statistics(
        result.labels,
        result.intensity,
        result.dop,
        result.zenith,
        result.phase,
        valid=valid,
        block_labels=result.block_labels,
        features=result.features,
        block_valid=block_valid,
    )
    materials = result.materials
    for row in rows:
        k = row["segment"]
        if materials is not None and k < len(materials.values):
            row["segment"], row["name"] = materials.values[k], materials.names[k]
        else:
            row["name"] = ""
    return rows


def _csv_value(value: Any) -> str:
    if isinstance(value, float):
        return "" if not np.isfinite(value) else f"{value:.6g}"
    return str(value)


def write_segments_csv(path: str | os.PathLike[str], rows: list[dict[str, Any]]) -> None:
    """Write per-segment rows (:func:`segment_rows`) as CSV with the columns
    :data:`~napari_polarseg.outputs.contract.SEGMENTS_CSV_COLUMNS`, atomically.

    NaN (a segment with no used pixel or block, fewer than 3 PCA features) is empty; a
    row without a ``name`` has an empty one.
    """
    columns = SEGMENTS_CSV_COLUMNS
    lines = [",".join(columns)]
    lines += [",".join(_csv_value(row.get(c, "")) for c in columns) for row in rows]
    with pio.atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")


def run_info(
    result: SegmentationResult,
    *,
    command: str,
    stack_shape: Sequence[int],
    angles_deg: Sequence[float],
    source: str | None = None,
    mask: PixelMask | None = None,
    shifts: np.ndarray | None = None,
    **extra: Any,
) -> dict[str, Any]:
    """The content of ``params.json``: the run's parameters, input and settings.

    Every key ``polarseg segment`` writes is present (None where it does not apply, e.g.
    the reader's settings for a stack that came from a napari layer); ``extra`` items
    fill or add keys. ``"params"`` is ``result.params`` as a SegmentParams dict.
    """
    angles = np.asarray(angles_deg, dtype=float).ravel()
    info: dict[str, Any] = {
        "polarseg_version": __version__,
        "command": command,
        "input": source,
        "input_format": None,
        "input_files": None,
        "stack_shape": [int(n) for n in stack_shape],
        "output_shape": list(result.labels.shape),
        "angles_deg": angles.tolist(),
        "angles_from": None,
        "mosaic_layout_deg": None,
        "raw_shape": None,
        "channel": None,
        "demosaic": None,
        "bayer": None,
        "sensor": None,
        "dark_frame": None,
        "offset": None,
        "saturation_level": None if mask is None else mask.saturation_level,
        "bits_per_sample": None,
        "dark_level": None if mask is None else mask.dark_level,
        "mask_file": None,
        "duplicate_angles": [
            {
                "angle_deg": float(angles[frames[0]]),
                "frames": frames,
                "handling": "averaged before the fit",
            }
            for frames in duplicate_angle_frames(np.deg2rad(angles))
        ],
        "registration": {
            "ran": shifts is not None,
            "reference_frame": 0 if shifts is not None else None,
            "shifts_px": None if shifts is None else np.asarray(shifts).tolist(),
        },
        "params": result.params.to_dict(),
    }
    info.update(extra)
    return info


def evaluation_summary(evaluation: dict[str, Any]) -> dict[str, Any]:
    """What ``summary.json`` repeats of an ``evaluation.json``."""
    return {
        "adjusted_rand_index": evaluation["adjusted_rand_index"],
        "evaluation": {k: evaluation[k] for k in EVALUATION_SUMMARY_KEYS},
    }


def classifier_summary(segmentation: Any, labels_from: str) -> dict[str, Any]:
    """What ``summary.json`` says of labels from the pixel classifier.

    ``segmentation`` is a
    :class:`~napari_polarseg.engine.classifier.pixel_segmentation.PixelSegmentation`;
    ``labels_from`` is ``"scribbles"`` (trained on them) or ``"classifier"`` (a saved
    classifier applied). Shared by ``polarseg segment`` and the plugin's export.
    """
    clf = segmentation.classifier
    top = list(clf.importances().items())[:5]
    return {
        "labels_from": labels_from,
        "scribble_classes": [int(c) for c in clf.classes],
        "materials": segmentation.result.materials.to_dict()
        if segmentation.result.materials is not None
        else clf.materials().to_dict(),
        "classifier": {
            "model": clf.params.model,
            "n_features": len(clf.feature_names),
            "n_training_pixels": clf.n_training_pixels,
            "seconds": {k: round(v, 6) for k, v in segmentation.seconds.items()},
            "top_features": {k: round(v, 4) for k, v in top},
        },
    }


# -- writing --------------------------------------------------------------------------------


class _Folder:
    """Writes the files of a result folder, each atomically, its images in ``image_format``
    (:data:`~napari_polarseg.outputs.image_formats.IMAGE_FORMATS`); keeps the names written
    and the path being written (the one an :class:`OutputError` names)."""

    def __init__(self, out: Path, image_format: str = "tiff") -> None:
        self.out = out
        self.written: list[str] = []
        self.current = str(out)
        if image_format not in IMAGE_FORMATS:
            words = ", ".join(IMAGE_FORMATS)
            raise PolarsegError(f"the image format must be one of {words}; got {image_format!r}")
        self.format = IMAGE_FORMATS[image_format]

    def path(self, rel: str) -> Path:
        """The path of ``rel``, named by the error of any failure from now on."""
        self.current = str(self.out / rel)
        return self.out / rel

    def tiff(self, rel: str, image: Any, meta: dict[str, Any], labels: bool = False) -> None:
        """The image named ``rel`` as a TIFF, in the folder's image format."""
        rel = self.format.name(rel)
        self.format.write(self.path(rel), image, meta, labels=labels)
        self.written.append(rel)

    def remove(self, rel: str) -> None:
        """Remove an earlier run's file (an OME-Zarr image: its directory)."""
        path = self.path(rel)
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)

    def png(self, rel: str, image: Any) -> None:
        """The PNG named ``rel`` of an array or a Pillow image (:func:`.bands.write_picture`)."""
        if isinstance(image, np.ndarray):
            pio.write_png(self.path(rel), image)
        else:  # a large image's composite, drawn now (bands.composite_image)
            write_picture(self.path(rel), image() if callable(image) else image)
        self.written.append(rel)

    def json(self, rel: str, data: dict[str, Any]) -> None:
        pio.write_json(self.path(rel), data)
        self.written.append(rel)


def _write_maps(
    folder: _Folder,
    result: SegmentationResult,
    stokes: Any,
    composite: Any,
) -> None:
    """``labels.tif``, the float maps, ``mask.tif`` and the polarisation views (those
    of a large image made band by band as they are written: :mod:`.bands`)."""
    materials = result.materials
    large = is_large(result.labels.shape)
    if large:
        labels = labels_image_banded(result.labels, materials)
    else:
        labels = labels_image(result.labels, materials)
    folder.tiff("labels.tif", labels, labels_meta(materials), labels=True)
    for fname, (attr, meta) in FLOAT_OUTPUTS.items():
        value = getattr(result, attr)
        if value is not None:  # the reconstruction error: the thesis maps, when computed
            folder.tiff(fname, as_dtype(value, np.float32), meta)
    if large:
        folder.tiff("mask.tif", used_pixels_banded(result.valid, result.labels.shape), MASK_META)
    else:
        folder.tiff("mask.tif", used_pixels(result), MASK_META)
    if stokes is not None:
        lazy = pio.is_lazy(stokes)
        folder.tiff(
            STOKES_FILE, stokes if lazy else np.asarray(stokes, np.float32), STOKES_CONVENTION
        )
    if composite is not None:
        folder.png(COMPOSITE_FILE, composite)


def _write_extras(
    folder: _Folder,
    segments: list[dict[str, Any]] | None,
    probabilities: np.ndarray | None,
    uncertainty: np.ndarray | None,
    evaluation: dict[str, Any] | None,
    overview: np.ndarray | None,
    materials: Any = None,
) -> None:
    """The files a run writes on request, in the contract's order; ``materials`` (a
    scribble classifier's) name the planes of ``probabilities.tif``."""
    if segments is not None:
        write_segments_csv(folder.path("segments.csv"), segments)
        folder.written.append("segments.csv")
    if probabilities is not None:
        meta = dict(PROBABILITY_META)
        if materials is not None and len(materials.values) == probabilities.shape[0]:
            meta["materials"] = materials.to_dict()  # plane k: the k-th of these
        folder.tiff("probabilities.tif", probabilities.astype(np.float32), meta)
    if uncertainty is not None:
        folder.tiff("uncertainty.tif", uncertainty.astype(np.float32), UNCERTAINTY_META)
    if evaluation is not None:
        folder.json("evaluation.json", evaluation)
    if overview is not None:
        folder.png("overview.png", overview)


def _write_plots(folder: _Folder, plots: dict[str, bytes]) -> None:
    """The folder ``plots/`` and each PNG in it (``plots/<name>.png``)."""
    folder.path("plots").mkdir(parents=True, exist_ok=True)
    for fname, content in plots.items():
        with pio.atomic_output(folder.path(f"plots/{fname}")) as tmp:
            tmp.write_bytes(content)
        folder.written.append(f"plots/{fname}")


def write_outputs(
    out: str | os.PathLike[str],
    result: SegmentationResult,
    info: dict[str, Any],
    summary: dict[str, Any],
    overview: np.ndarray | None = None,
    *,
    segments: list[dict[str, Any]] | None = None,
    probabilities: np.ndarray | None = None,
    uncertainty: np.ndarray | None = None,
    evaluation: dict[str, Any] | None = None,
    plots: dict[str, bytes] | None = None,
    stokes: Any = None,
    composite: Any = None,
    image_format: str = "tiff",
) -> list[str]:
    """Write already computed outputs into ``out`` (created), each file atomically, the
    images as ``image_format`` (:data:`~napari_polarseg.outputs.image_formats.IMAGE_FORMATS`:
    ``tiff``, ``zarr``).

    ``stokes`` (3, H, W; NumPy or Dask) goes to
    :data:`~napari_polarseg.outputs.contract.STOKES_FILE` (float32; its planes and sign
    convention in the JSON ImageDescription,
    :data:`napari_polarseg.engine.physics.stokes.STOKES_CONVENTION`), ``composite``
    ((H, W, 3) uint8, a Pillow image or a callable giving one: :mod:`.bands`) to
    :data:`~napari_polarseg.outputs.contract.COMPOSITE_FILE`.

    Returns the files written, relative to ``out`` (``plots/<name>.png`` for plots), in
    the order written. Records the writing time in ``summary["io_seconds"]["write"]``.
    Raises :class:`~napari_polarseg.outputs.contract.OutputError` naming the file that
    could not be written.
    """
    out = Path(out)
    t0 = time.perf_counter()
    folder = _Folder(out, image_format)
    try:
        out.mkdir(parents=True, exist_ok=True)
        _write_maps(folder, result, stokes, composite)
        extras = (segments, probabilities, uncertainty, evaluation, overview)
        _write_extras(folder, *extras, result.materials)
        if plots is not None:
            _write_plots(folder, plots)
        folder.json("params.json", info)
        stale = stale_files(out, [*folder.written, "summary.json"])
        if stale:  # an earlier run's results: the folder is to describe this run only
            summary["removed_from_earlier_run"] = stale
        summary["io_seconds"]["write"] = round(time.perf_counter() - t0, 6)
        folder.json("summary.json", summary)
        for name in stale:
            folder.remove(name)
        if any(name.startswith("plots/") for name in stale):
            with contextlib.suppress(OSError):  # only when no file is left in it
                folder.path("plots").rmdir()
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputError(f"cannot write {folder.current}: {reason}") from exc
    return folder.written


def _checked_arrays(
    result: SegmentationResult,
    stack: np.ndarray,
    angles_deg: Sequence[float],
    probabilities: np.ndarray | None,
    uncertainty: np.ndarray | None,
    truth: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """``stack`` and ``probabilities`` as arrays, after checking that every array fits the
    result's pixels and the angles the frames; raises :class:`PolarsegError`."""
    stack = np.asarray(stack)
    angles = np.asarray(angles_deg, dtype=float).ravel()
    shape = tuple(result.labels.shape)
    pixels = f"the result's {shape[0]} x {shape[1]} pixels"
    if stack.ndim != 3 or tuple(stack.shape[1:]) != shape:
        raise PolarsegError(f"the stack {stack.shape} does not match {pixels}")
    if angles.size != stack.shape[0]:
        raise PolarsegError(f"{stack.shape[0]} frames but {angles.size} angles")
    if probabilities is not None:
        probabilities = np.asarray(probabilities)
        if probabilities.ndim != 3 or tuple(probabilities.shape[1:]) != shape:
            raise PolarsegError(f"the probabilities {probabilities.shape} do not match {pixels}")
    if truth is not None and np.shape(truth) != shape:
        raise PolarsegError(f"the ground truth {np.shape(truth)} does not match {pixels}")
    if uncertainty is not None and np.shape(uncertainty) != shape:
        raise PolarsegError(f"the uncertainty {np.shape(uncertainty)} does not match {pixels}")
    return stack, probabilities


def _params_json(
    result: SegmentationResult,
    stack: np.ndarray,
    angles_deg: Sequence[float],
    command: str,
    source: str | None,
    mask: PixelMask | None,
    shifts: np.ndarray | None,
    info: dict[str, Any] | None,
) -> dict[str, Any]:
    """``params.json``: :func:`run_info` of the run, ``info``'s items added."""
    return run_info(
        result,
        command=command,
        stack_shape=stack.shape,
        angles_deg=np.asarray(angles_deg, dtype=float).ravel(),
        source=source,
        mask=mask,
        shifts=shifts,
        **(info or {}),
    )


def _summary_json(
    result: SegmentationResult, summary: dict[str, Any] | None, evaluation: dict[str, Any] | None
) -> dict[str, Any]:
    """``summary.json``: the result's summary, ``summary``'s items, the evaluation's."""
    summary_json = {**result.summary(), "io_seconds": {}, "output_shape": list(result.labels.shape)}
    summary_json.update(summary or {})
    summary_json["io_seconds"] = dict(summary_json["io_seconds"])  # leave the caller's dict
    if evaluation is not None:
        summary_json.update(evaluation_summary(evaluation))
    return summary_json


def _pictures(
    first_frame: np.ndarray,
    result: SegmentationResult,
    params_json: dict[str, Any],
    truth: np.ndarray | None,
    overview: bool,
    plots: bool,
    views: bool,
    composite_params: CompositeParams | None,
) -> dict[str, Any]:
    """The images :func:`write_outputs` takes (``overview``, ``plots``, ``stokes``,
    ``composite``); records the composite's settings in ``params_json["aolp_dolp"]``."""
    composite = stokes = None
    large = is_large(result.labels.shape)  # a Pillow image drawn band by band: .bands
    if views or overview:
        if composite_params is None:
            dolp_max = auto_dolp_max_banded if large else auto_dolp_max
            composite_params = CompositeParams(dolp_max=dolp_max(result.dop))
        maps = (result.intensity, result.dop, result.phase, composite_params)
        composite = (
            functools.partial(composite_image, *maps) if large else aolp_dolp_composite(*maps)
        )
        params_json["aolp_dolp"] = dataclasses.asdict(composite_params)
    if views:
        stokes = stokes_image(result.intensity, result.dop, result.phase)
    picture = None
    if overview:
        picture = render_overview(
            first_frame,
            result,
            truth=truth,
            composite=np.asarray(composite() if large else composite),
            dolp_max=composite_params.dolp_max,
        )
    pngs = None
    if plots:
        from .figures import render_plots

        pngs = render_plots(result)
    return {
        "overview": picture,
        "plots": pngs,
        "stokes": stokes,
        "composite": composite if views else None,
    }


def write_result_folder(
    out: str | os.PathLike[str],
    *,
    stack: np.ndarray,
    angles_deg: Sequence[float],
    result: SegmentationResult,
    mask: PixelMask | None = None,
    source: str | None = None,
    command: str = "export",
    overview: bool = True,
    plots: bool = False,
    probabilities: np.ndarray | None = None,
    uncertainty: np.ndarray | None = None,
    evaluation: dict[str, Any] | None = None,
    shifts: np.ndarray | None = None,
    info: dict[str, Any] | None = None,
    summary: dict[str, Any] | None = None,
    truth: np.ndarray | None = None,
    views: bool = True,
    composite_params: CompositeParams | None = None,
    image_format: str = "tiff",
) -> list[str]:
    """Write a segmentation's results into the folder ``out``, as ``polarseg segment``.

    Parameters
    ----------
    out : path
        The folder (created if missing; files of the same names are replaced).
    stack, angles_deg : array (N, H, W), sequence of N floats
        The angle stack the result was computed from (after any registration; its first
        frame is drawn in ``overview.png``) and each frame's polariser angle, degrees.
    result : SegmentationResult
        What to write; ``params.json`` records ``result.params``.
    mask, source, command, shifts
        What ``params.json`` records (:func:`run_info`): the pixel mask the pipeline used
        (its saturation and dark levels; ``mask.tif`` is ``result.valid`` in any case),
        where the stack came from (``"input"``), ``"command"`` (``"segment"``,
        ``"demo"``, ``"napari"``, …), registration shifts (N, 2) in pixels.
    overview, plots, views : bool
        Also write ``overview.png`` (:func:`~napari_polarseg.outputs.overview.render_overview`),
        the plots into ``plots/`` (:func:`napari_polarseg.outputs.figures.render_plots`),
        and ``stokes.tif`` (S0, S1, S2) and ``aolp_dolp.png`` (the AoLP/DoLP HSV composite)
        of :mod:`napari_polarseg.engine.analysis.views`.
    probabilities, uncertainty : array (K, H, W), array (H, W), optional
        The pixel classifier's: ``probabilities.tif``, ``uncertainty.tif``.
    evaluation : dict, optional
        :func:`~napari_polarseg.engine.analysis.evaluation.evaluate` figures (and e.g. the
        truth's file): ``evaluation.json``, in ``summary.json`` too.
    info, summary : dict, optional
        Items added to (or replacing those of) ``params.json`` and ``summary.json``.
    truth : array (H, W) of int, optional
        The true materials, drawn beside the segments in ``overview.png``.
    composite_params : CompositeParams, optional
        Settings of the composite (``params.json``'s ``"aolp_dolp"``; default: ρ_max from
        :func:`~napari_polarseg.engine.analysis.views.auto_dolp_max`, value from Î).
    image_format : {"tiff", "zarr"}
        Images as TIFF or OME-Zarr (:mod:`~napari_polarseg.outputs.image_formats`).

    Returns
    -------
    list of str
        The files written, relative to ``out``, in order.

    Raises
    ------
    PolarsegError
        The stack, angles, result and arrays do not fit (before any file is written).
    OutputError
        A file could not be written (the files written before it stay).
    """
    arrays = (probabilities, uncertainty, truth)
    stack, probabilities = _checked_arrays(result, stack, angles_deg, *arrays)
    params_json = _params_json(result, stack, angles_deg, command, source, mask, shifts, info)
    summary_json = _summary_json(result, summary, evaluation)
    files = {"segments": segment_rows(result), "evaluation": evaluation}
    files.update(probabilities=probabilities, uncertainty=uncertainty)
    files.update(
        _pictures(stack[0], result, params_json, truth, overview, plots, views, composite_params)
    )
    return write_outputs(out, result, params_json, summary_json, **files, image_format=image_format)
