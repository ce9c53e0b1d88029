"""The names and metadata of the files in a ``segment`` result folder, and their error.

The file names and the TIFF metadata every result folder's images carry
(:data:`FLOAT_OUTPUTS`, :data:`MASK_META`, …), the error a writer raises
(:class:`OutputError`), and the two images every folder derives from a result
(:func:`labels_image`, :func:`used_pixels`). Shared by the result-folder writer
(:mod:`napari_polarseg.outputs.result_folder`) and the batch runner's completeness check
(:func:`napari_polarseg.batch.contract_files`).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..engine.analysis.evaluation import STATISTICS_COLUMNS

if TYPE_CHECKING:
    from ..engine import SegmentationResult
    from ..engine.materials import Materials

#: The polarisation views every result folder holds beside the contract files.
STOKES_FILE = "stokes.tif"
COMPOSITE_FILE = "aolp_dolp.png"
#: Files :func:`~napari_polarseg.outputs.figures.save_plots` writes (into ``plots/`` of a
#: result folder).
PLOT_FILES = (
    "scatter.png",
    "explained_variance.png",
    "coefficients.png",
    "components.png",
    "histograms.png",
    "error_table.png",
)

#: Output images: file name -> (result attribute, TIFF metadata).
FLOAT_OUTPUTS = {
    "intensity.tif": ("intensity", {"quantity": "mean intensity", "unit": "input units"}),
    "dop.tif": ("dop", {"quantity": "degree of polarisation", "unit": "1"}),
    "phase.tif": ("phase", {"quantity": "phase", "unit": "radians", "range": "[0, pi)"}),
    "zenith.tif": ("zenith", {"quantity": "zenith angle", "unit": "radians"}),
    "reconstruction_error.tif": (
        "reconstruction_error",
        {"quantity": "absolute reconstruction error of the mean intensity", "unit": "input units"},
    ),
    "residual.tif": (
        "residual",
        {"quantity": "RMS residual of the sinusoid fit", "unit": "input units"},
    ),
}

MASK_META = {
    "quantity": "pixels used by the fit and the features",
    "values": "1 used, 0 excluded (saturated, black, not finite, outside the mask, or no "
    "positive intensity)",
}

#: ``axes`` is tifffile's own key (one letter per dimension: C planes, Y rows, X columns),
#: so readers take it as the series' axes; the words go under ``dimensions`` (as in
#: ``stokes.tif``). Free text under ``axes`` made every read warn.
PROBABILITY_META = {
    "quantity": "class probability from the pixel classifier",
    "unit": "1",
    "axes": "CYX",
    "dimensions": "class, row, column (class k = the k-th smallest scribble value)",
}

#: Columns of ``segments.csv``: the segment's ``labels.tif`` value, its material's name
#: (a scribble classifier's; empty for the unsupervised methods), then its statistics
#: (:data:`~napari_polarseg.engine.analysis.evaluation.STATISTICS_COLUMNS` but the first).
SEGMENTS_CSV_COLUMNS = (STATISTICS_COLUMNS[0], "name", *STATISTICS_COLUMNS[1:])

UNCERTAINTY_META = {
    "quantity": "uncertainty of the pixel classifier: 1 - (p1 - p2), one minus the margin "
    "between the two most probable classes",
    "unit": "1",
}

#: Figures of an ``evaluation.json`` that ``summary.json`` repeats under ``"evaluation"``.
EVALUATION_SUMMARY_KEYS = (
    "adjusted_rand_index",
    "mean_iou",
    "iou_per_segment",
    "block_accuracy_worst",
    "block_accuracy_optimistic",
    "window",
)


class OutputError(Exception):
    """The outputs could not be written (``polarseg`` exit code 1)."""


def labels_image(labels: np.ndarray, materials: Materials | None = None) -> np.ndarray:
    """``labels.tif``: labels as the smallest unsigned type that holds them (uint16, else
    uint32); with ``materials`` (a scribble classifier's) label k is written as the
    scribble value ``materials.values[k]``, the value its strokes were painted with."""
    if materials is not None:
        labels = materials.label_values(labels)
    dtype = np.uint16 if labels.max(initial=0) < 2**16 else np.uint32
    return labels.astype(dtype)


def labels_meta(materials: Materials | None) -> dict[str, Any]:
    """The ImageDescription of ``labels.tif``: 0 = first segment, or with a scribble
    classifier the scribble values and the materials' names."""
    if materials is None:
        return {"quantity": "segment labels", "first_label": 0}
    return {
        "quantity": "segment labels",
        "values": "scribble value of each material",
        "materials": materials.to_dict(),
    }


def used_pixels(result: SegmentationResult) -> np.ndarray:
    """``mask.tif``: 1 where the fit and the features used the pixel (uint8)."""
    valid = result.valid
    if valid is None:
        return np.ones(result.labels.shape, np.uint8)
    return np.asarray(valid, dtype=np.uint8)


#: The images of a result folder, by their TIFF names: ``polarseg segment --format zarr``
#: writes each as an OME-Zarr directory of the same stem (:func:`image_name`).
IMAGE_FILES: tuple[str, ...] = (
    "labels.tif",
    *FLOAT_OUTPUTS,
    "mask.tif",
    STOKES_FILE,
    "probabilities.tif",
    "uncertainty.tif",
)
#: Suffix of an image written as OME-Zarr (a directory).
ZARR_SUFFIX = ".zarr"


def image_name(name: str, suffix: str) -> str:
    """The name of the image ``name`` (an :data:`IMAGE_FILES` name) written with the file
    suffix ``suffix`` (``.tif``, ``.zarr``): ``image_name("labels.tif", ".zarr")`` is
    ``"labels.zarr"``."""
    return name.removesuffix(".tif") + suffix


#: Every file a result folder may hold, relative to it (the images in either format; an
#: OME-Zarr image is a directory). A run into a folder that holds an earlier run's results
#: removes those of these files it did not write itself (:func:`stale_files`), so the
#: folder describes one run, whichever format each wrote; no other file is touched.
RESULT_FILES: tuple[str, ...] = (
    "labels.tif",
    *FLOAT_OUTPUTS,
    "mask.tif",
    STOKES_FILE,
    COMPOSITE_FILE,
    "segments.csv",
    "probabilities.tif",
    "uncertainty.tif",
    *(image_name(name, ZARR_SUFFIX) for name in IMAGE_FILES),
    "evaluation.json",
    "overview.png",
    *(f"plots/{name}" for name in PLOT_FILES),
    "params.json",
    "summary.json",
)


def _present(path: Path) -> bool:
    """Whether a result file is there: a file, or an OME-Zarr image's directory."""
    return path.is_dir() if path.suffix == ZARR_SUFFIX else path.is_file()


def result_files(out: Path) -> list[str]:
    """The files of :data:`RESULT_FILES` that the folder ``out`` holds, relative to it."""
    return [name for name in RESULT_FILES if _present(out / name)]


def stale_files(out: Path, written: Iterable[str]) -> list[str]:
    """The files of :data:`RESULT_FILES` in ``out`` that ``written`` does not name: an
    earlier run's results (in either image format), which a new run into ``out``
    removes."""
    keep = set(written)
    return [name for name in result_files(out) if name not in keep]
