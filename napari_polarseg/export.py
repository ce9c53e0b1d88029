"""A segmentation's results as a folder: what ``polarseg segment --out DIR`` writes.

:func:`write_result_folder` writes, from a :class:`~napari_polarseg.engine.SegmentationResult`
and the angle stack it came from, the files of the ``segment`` contract (the table in
:mod:`napari_polarseg.cli`): ``labels.tif``, the float maps of :data:`FLOAT_OUTPUTS`,
``mask.tif``, ``segments.csv``, ``params.json`` (its ``"params"`` entry is what ``polarseg
segment --params`` and the plugin's *Load parameters…* read), ``summary.json``, and on
request ``overview.png``, ``plots/*.png``, ``probabilities.tif`` (scribble classifier) and
``evaluation.json`` (ground truth), and the polarisation views ``stokes.tif`` (S0, S1,
S2) and ``aolp_dolp.png`` (the AoLP/DoLP HSV composite). The command line and the
*Segment by material* widget's *Export results…* both write through it.

Everything (statistics, figures, JSON) is computed before the first file is written, and
every file is written to a temporary name and renamed (:func:`napari_polarseg.io.atomic_output`),
so a failure never leaves a partial file where a good one was; a file that cannot be
written raises :class:`OutputError` naming it. No napari, no Qt: usable from scripts.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import __version__
from . import io as pio
from .engine import SegmentationResult, valid_blocks
from .engine.analysis.evaluation import STATISTICS_COLUMNS, segment_statistics
from .engine.analysis.views import CompositeParams, aolp_dolp_composite, auto_dolp_max
from .engine.errors import PolarsegError
from .engine.physics.pixel_mask import PixelMask
from .engine.physics.polarimage import duplicate_angle_frames
from .engine.physics.stokes import STOKES_CONVENTION, stokes_components

#: The polarisation views every result folder holds beside the contract files.
STOKES_FILE = "stokes.tif"
COMPOSITE_FILE = "aolp_dolp.png"

if TYPE_CHECKING:
    from matplotlib.figure import Figure

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

PROBABILITY_META = {
    "quantity": "class probability from the pixel classifier",
    "unit": "1",
    "axes": "class, row, column (class k = the k-th smallest scribble value)",
}

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


# -- the pieces -----------------------------------------------------------------------------


def labels_image(labels: np.ndarray) -> np.ndarray:
    """Labels as the smallest unsigned type that holds them (uint16, else uint32)."""
    dtype = np.uint16 if labels.max(initial=0) < 2**16 else np.uint32
    return labels.astype(dtype)


def used_pixels(result: SegmentationResult) -> np.ndarray:
    """``mask.tif``: 1 where the fit and the features used the pixel (uint8)."""
    valid = result.valid
    if valid is None:
        return np.ones(result.labels.shape, np.uint8)
    return np.asarray(valid, dtype=np.uint8)


def segment_rows(result: SegmentationResult) -> list[dict[str, Any]]:
    """Per-segment statistics of ``result`` (the rows of ``segments.csv``).

    Means over the used pixels (``result.valid``) and, for the PCA features, over the
    blocks that entered the graph (:func:`~napari_polarseg.engine.stages.valid_blocks`).
    """
    valid = result.valid
    block_valid = None if valid is None else valid_blocks(valid, result.params.window)
    return segment_statistics(
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


def _csv_value(value: Any) -> str:
    if isinstance(value, float):
        return "" if not np.isfinite(value) else f"{value:.6g}"
    return str(value)


def write_segments_csv(path: str | os.PathLike[str], rows: list[dict[str, Any]]) -> None:
    """Write per-segment statistics (:data:`STATISTICS_COLUMNS`) as CSV, atomically.

    NaN (a segment with no used pixel or block, fewer than 3 PCA features) is empty.
    """
    lines = [",".join(STATISTICS_COLUMNS)]
    lines += [",".join(_csv_value(row[c]) for c in STATISTICS_COLUMNS) for row in rows]
    with pio.atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")


def segment_colours_for(truth: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Colour indices of the true materials and of the segments, matched by overlap.

    The true labels are numbered 0, 1, … in increasing order; each segment gets the index
    of the true material it is matched to (the largest total overlap, a linear
    assignment on the contingency table), so a material and its segment share a colour.
    Unmatched segments get the indices after the true materials'. Returns ``(truth
    index (H, W), segment index by label value (n_labels,))``.
    """
    from scipy.optimize import linear_sum_assignment

    true_values, true_index = np.unique(np.asarray(truth), return_inverse=True)
    true_index = true_index.reshape(np.shape(truth))
    n_labels = int(np.max(labels, initial=0)) + 1
    table = np.zeros((true_values.size, n_labels))
    np.add.at(table, (true_index.ravel(), np.asarray(labels).ravel()), 1.0)
    rows, cols = linear_sum_assignment(table, maximize=True)
    colour = np.full(n_labels, -1)
    colour[cols] = rows
    spare = iter(range(true_values.size, true_values.size + n_labels))
    for j in np.flatnonzero(colour < 0):
        colour[j] = next(spare)
    return true_index, colour


def overview_figure(
    first_frame: np.ndarray,
    result: SegmentationResult,
    *,
    truth: np.ndarray | None = None,
    composite: np.ndarray | None = None,
    dolp_max: float | None = None,
) -> Figure:
    """The figure of ``overview.png``: one panel per map, side by side.

    Input, Î, ρ, φ, the AoLP/DoLP HSV composite, the segments, the ground truth (when
    given) and the reconstruction error. Uses matplotlib's object-oriented API on an Agg
    canvas (no pyplot, so no global backend is switched and no window opens; safe in a
    worker thread); :func:`render_overview` draws it into pixels.

    Parameters
    ----------
    first_frame : array (H, W)
        First frame of the angle stack.
    result : SegmentationResult
        The pipeline's result.
    truth : array (H, W) of int, optional
        The true materials: drawn beside the segments, in the colours of the segments
        they are matched to, and the segments' title gives the adjusted Rand index.
    composite : array (H, W, 3) uint8, optional
        The AoLP/DoLP HSV composite
        (:func:`napari_polarseg.engine.analysis.views.aolp_dolp_composite`);
        computed with ρ_max = ``dolp_max`` (default
        :func:`~napari_polarseg.engine.analysis.views.auto_dolp_max`) when not given.
    dolp_max : float, optional
        The composite's ρ_max, for its title.

    Returns
    -------
    matplotlib.figure.Figure
        On an Agg canvas, laid out; ``fig.axes[:n]`` are the n panels in order, their
        colour bars follow.
    """
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, Normalize
    from matplotlib.figure import Figure

    from .engine.analysis.evaluation import adjusted_rand_index

    if composite is None:
        if dolp_max is None:
            dolp_max = auto_dolp_max(result.dop)
        composite = aolp_dolp_composite(
            result.intensity, result.dop, result.phase, CompositeParams(dolp_max=dolp_max)
        )
    hsv_title = "AoLP hue, DoLP saturation"
    if dolp_max is not None:
        hsv_title += f"\n(full at ρ = {dolp_max:g})"
    labels = np.asarray(result.labels)
    k = max(result.n_segments, 1)
    seg_title = f"segments ({result.n_segments})"
    # colour-bar ticks of the label panels: positions (colour indices) and their labels
    ticks = {"segments": (np.arange(k), [str(v) for v in range(k)])}
    truth_panel = None
    if truth is not None:
        true_index, colour = segment_colours_for(truth, labels)
        true_values = np.unique(np.asarray(truth))
        labels = colour[labels]
        k = max(k, true_values.size, int(colour.max(initial=0)) + 1)
        ticks["segments"] = (colour, [str(v) for v in range(colour.size)])
        ticks["truth"] = (np.arange(true_values.size), [str(v) for v in true_values])
        seg_title += f", ARI {adjusted_rand_index(truth, result.labels):.3f}"
        truth_panel = (f"ground truth ({true_values.size})", true_index, "truth", -0.5, k - 0.5)
    base = "tab10" if k <= 10 else "tab20"
    seg_cmap = ListedColormap(colormaps[base](np.arange(k) % colormaps[base].N))
    error = result.reconstruction_error
    error = np.zeros_like(result.intensity) if error is None else error
    finite_err = error[np.isfinite(error)]
    err_max = float(np.percentile(finite_err, 99)) if finite_err.size else 1.0
    panels = [
        ("input (first frame)", first_frame, "gray", None, None),
        ("Î mean intensity", result.intensity, "gray", None, None),
        ("ρ degree of polarisation", result.dop, "viridis", 0.0, None),
        ("φ phase (rad)", result.phase, "twilight", 0.0, np.pi),
        (hsv_title, composite, "rgb", None, None),
        (seg_title, labels, "segments", -0.5, k - 0.5),
    ]
    if truth_panel is not None:
        panels.append(truth_panel)
    panels.append(("reconstruction error", error, "magma", 0.0, err_max or None))
    h, w = result.labels.shape
    panel_w = 3.2
    fig = Figure(figsize=(panel_w * len(panels), panel_w * h / w + 0.8), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels))
    for ax, (title, image, cmap, vmin, vmax) in zip(axes, panels, strict=True):
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
        if cmap == "rgb":
            ax.imshow(image, interpolation="nearest")
            hue = ScalarMappable(Normalize(0.0, 180.0), colormaps["hsv"])
            bar = fig.colorbar(hue, ax=ax, fraction=0.046, pad=0.02)
            bar.set_ticks([0, 45, 90, 135, 180])
            bar.set_label("AoLP (°)", fontsize=8)
            continue
        is_labels = cmap in ticks
        shown = ax.imshow(
            np.asarray(image, dtype=float),
            cmap=seg_cmap if is_labels else cmap,
            vmin=vmin,
            vmax=vmax,
            interpolation="nearest",
        )
        bar = fig.colorbar(shown, ax=ax, fraction=0.046, pad=0.02)
        if is_labels:
            where, names = ticks[cmap]
            if len(names) <= 12:
                bar.set_ticks(np.asarray(where, dtype=float), labels=names)
            else:
                bar.set_ticks(np.linspace(0, k - 1, 5).round())
    fig.tight_layout()
    return fig


def render_overview(
    first_frame: np.ndarray,
    result: SegmentationResult,
    *,
    truth: np.ndarray | None = None,
    composite: np.ndarray | None = None,
    dolp_max: float | None = None,
) -> np.ndarray:
    """Draw :func:`overview_figure` (same arguments) into pixels.

    Returns
    -------
    ndarray (rows, columns, 4) uint8
        The RGBA figure, ready for :func:`napari_polarseg.io.write_png`.
    """
    fig = overview_figure(first_frame, result, truth=truth, composite=composite, dolp_max=dolp_max)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba()).copy()


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
    :class:`~napari_polarseg.engine.analysis.pixel_segmentation.PixelSegmentation`;
    ``labels_from`` is ``"scribbles"`` (trained on them) or ``"classifier"`` (a saved
    classifier applied). Shared by ``polarseg segment`` and the plugin's export.
    """
    clf = segmentation.classifier
    top = list(clf.importances().items())[:5]
    return {
        "labels_from": labels_from,
        "scribble_classes": [int(c) for c in clf.classes],
        "classifier": {
            "model": clf.params.model,
            "n_features": len(clf.feature_names),
            "n_training_pixels": clf.n_training_pixels,
            "seconds": {k: round(v, 6) for k, v in segmentation.seconds.items()},
            "top_features": {k: round(v, 4) for k, v in top},
        },
    }


# -- writing --------------------------------------------------------------------------------


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
    stokes: np.ndarray | None = None,
    composite: np.ndarray | None = None,
) -> list[str]:
    """Write already computed outputs into ``out`` (created), each file atomically.

    ``stokes`` (3, H, W) goes to :data:`STOKES_FILE` (float32; its planes and sign
    convention in the JSON ImageDescription, :data:`.engine.stokes.STOKES_CONVENTION`),
    ``composite`` (H, W, 3) uint8 to :data:`COMPOSITE_FILE`.

    Returns the files written, relative to ``out`` (``plots/<name>.png`` for plots), in
    the order written. Records the writing time in ``summary["io_seconds"]["write"]``.
    Raises :class:`OutputError` naming the file that could not be written.
    """
    out = Path(out)
    t0 = time.perf_counter()
    written: list[str] = []
    name = str(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        name = str(out / "labels.tif")
        pio.write_tiff(
            out / "labels.tif",
            labels_image(result.labels),
            {"quantity": "segment labels", "first_label": 0},
        )
        written.append("labels.tif")
        for fname, (attr, meta) in FLOAT_OUTPUTS.items():
            name = str(out / fname)
            pio.write_tiff(out / fname, np.asarray(getattr(result, attr), np.float32), meta)
            written.append(fname)
        name = str(out / "mask.tif")
        pio.write_tiff(out / "mask.tif", used_pixels(result), MASK_META)
        written.append("mask.tif")
        if stokes is not None:
            name = str(out / STOKES_FILE)
            pio.write_tiff(out / STOKES_FILE, np.asarray(stokes, np.float32), STOKES_CONVENTION)
            written.append(STOKES_FILE)
        if composite is not None:
            name = str(out / COMPOSITE_FILE)
            pio.write_png(out / COMPOSITE_FILE, composite)
            written.append(COMPOSITE_FILE)
        if segments is not None:
            name = str(out / "segments.csv")
            write_segments_csv(out / "segments.csv", segments)
            written.append("segments.csv")
        if probabilities is not None:
            name = str(out / "probabilities.tif")
            pio.write_tiff(
                out / "probabilities.tif", probabilities.astype(np.float32), PROBABILITY_META
            )
            written.append("probabilities.tif")
        if uncertainty is not None:
            name = str(out / "uncertainty.tif")
            pio.write_tiff(
                out / "uncertainty.tif", uncertainty.astype(np.float32), UNCERTAINTY_META
            )
            written.append("uncertainty.tif")
        if evaluation is not None:
            name = str(out / "evaluation.json")
            pio.write_json(out / "evaluation.json", evaluation)
            written.append("evaluation.json")
        if overview is not None:
            name = str(out / "overview.png")
            pio.write_png(out / "overview.png", overview)
            written.append("overview.png")
        if plots is not None:
            name = str(out / "plots")
            (out / "plots").mkdir(parents=True, exist_ok=True)
            for fname, content in plots.items():
                name = str(out / "plots" / fname)
                with pio.atomic_output(out / "plots" / fname) as tmp:
                    tmp.write_bytes(content)
                written.append(f"plots/{fname}")
        name = str(out / "params.json")
        pio.write_json(out / "params.json", info)
        written.append("params.json")
        summary["io_seconds"]["write"] = round(time.perf_counter() - t0, 6)
        name = str(out / "summary.json")
        pio.write_json(out / "summary.json", summary)
        written.append("summary.json")
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputError(f"cannot write {name}: {reason}") from exc
    return written


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
) -> list[str]:
    """Write a segmentation's results into the folder ``out``, as ``polarseg segment``.

    Parameters
    ----------
    out : path
        The folder (created if missing; files of the same names are replaced).
    stack : array (N, H, W)
        The angle stack the result was computed from (after any registration); its first
        frame is drawn in ``overview.png``.
    angles_deg : sequence of N floats
        Polariser angle of each frame, degrees.
    result : SegmentationResult
        What to write; ``params.json`` records ``result.params``.
    mask : PixelMask, optional
        The pixel mask the pipeline used (its saturation and dark levels go to
        ``params.json``; ``mask.tif`` is ``result.valid`` in any case).
    source : str, optional
        Where the stack came from (``params.json``'s ``"input"``).
    command : str
        ``params.json``'s ``"command"`` (``"segment"``, ``"demo"``, ``"napari"``, …).
    overview, plots : bool
        Also write ``overview.png`` (:func:`render_overview`), and the analyst's plots
        into ``plots/`` (:func:`napari_polarseg.figures.render_plots`).
    probabilities : array (K, H, W), optional
        Class probabilities of a classifier run: ``probabilities.tif``.
    uncertainty : array (H, W), optional
        The pixel classifier's uncertainty: ``uncertainty.tif``.
    evaluation : dict, optional
        :func:`~napari_polarseg.engine.analysis.evaluation.evaluate` figures (plus e.g. the ground
        truth's file): ``evaluation.json``, repeated in ``summary.json``.
    shifts : array (N, 2), optional
        Registration shifts (rows, columns) in pixels, if the frames were registered.
    info, summary : dict, optional
        Items added to (or replacing those of) ``params.json`` (:func:`run_info`) and
        ``summary.json`` (``result.summary()``, ``io_seconds``, ``output_shape``).
    truth : array (H, W) of int, optional
        The true materials, when known: ``overview.png`` draws them beside the segments
        and gives the adjusted Rand index in the segments' title.
    views : bool
        Also write the Stokes components S0, S1, S2 (``stokes.tif``,
        :func:`~napari_polarseg.engine.physics.stokes.stokes_components`) and the AoLP/DoLP HSV
        composite (``aolp_dolp.png``,
        :func:`~napari_polarseg.engine.analysis.views.aolp_dolp_composite`).
    composite_params : CompositeParams, optional
        Settings of the composite (default: ρ_max from
        :func:`~napari_polarseg.engine.analysis.views.auto_dolp_max`, value from Î); recorded in
        ``params.json`` under ``"aolp_dolp"``.

    Returns
    -------
    list of str
        The files written, relative to ``out``, in the order written.

    Raises
    ------
    PolarsegError
        The stack, angles, result and probabilities do not fit together (before any file
        is written).
    OutputError
        A file could not be written (the files written before it stay).
    """
    stack = np.asarray(stack)
    angles = np.asarray(angles_deg, dtype=float).ravel()
    shape = tuple(result.labels.shape)
    if stack.ndim != 3 or tuple(stack.shape[1:]) != shape:
        raise PolarsegError(
            f"the stack {stack.shape} does not match the result's {shape[0]} x {shape[1]} pixels"
        )
    if angles.size != stack.shape[0]:
        raise PolarsegError(f"{stack.shape[0]} frames but {angles.size} angles")
    if probabilities is not None:
        probabilities = np.asarray(probabilities)
        if probabilities.ndim != 3 or tuple(probabilities.shape[1:]) != shape:
            raise PolarsegError(
                f"the probabilities {probabilities.shape} do not match the result's "
                f"{shape[0]} x {shape[1]} pixels"
            )
    if truth is not None and np.shape(truth) != shape:
        raise PolarsegError(
            f"the ground truth {np.shape(truth)} does not match the result's "
            f"{shape[0]} x {shape[1]} pixels"
        )
    if uncertainty is not None and np.shape(uncertainty) != shape:
        raise PolarsegError(
            f"the uncertainty {np.shape(uncertainty)} does not match the result's "
            f"{shape[0]} x {shape[1]} pixels"
        )
    params_json = run_info(
        result,
        command=command,
        stack_shape=stack.shape,
        angles_deg=angles,
        source=source,
        mask=mask,
        shifts=shifts,
        **(info or {}),
    )
    summary_json = {**result.summary(), "io_seconds": {}, "output_shape": list(shape)}
    summary_json.update(summary or {})
    summary_json["io_seconds"] = dict(summary_json["io_seconds"])  # leave the caller's dict
    if evaluation is not None:
        summary_json.update(evaluation_summary(evaluation))
    rows = segment_rows(result)
    composite = stokes = None
    if views or overview:
        if composite_params is None:
            composite_params = CompositeParams(dolp_max=auto_dolp_max(result.dop))
        composite = aolp_dolp_composite(
            result.intensity, result.dop, result.phase, composite_params
        )
        params_json["aolp_dolp"] = dataclasses.asdict(composite_params)
    if views:
        stokes = stokes_components(result.intensity, result.dop, result.phase)
    picture = None
    if overview:
        picture = render_overview(
            stack[0],
            result,
            truth=truth,
            composite=composite,
            dolp_max=composite_params.dolp_max,
        )
    pngs = None
    if plots:
        from . import figures

        pngs = figures.render_plots(result)
    return write_outputs(
        out,
        result,
        params_json,
        summary_json,
        picture,
        segments=rows,
        probabilities=probabilities,
        uncertainty=uncertainty,
        evaluation=evaluation,
        plots=pngs,
        stokes=stokes,
        composite=composite if views else None,
    )
