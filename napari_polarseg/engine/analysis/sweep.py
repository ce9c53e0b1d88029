"""Parameter sweep: segment one stack over a grid of w, L and n and score every cell.

:func:`sweep` runs the cached :class:`~napari_polarseg.engine.pipeline.Pipeline` of one
stack over every combination of window size w (pixels), harmonic degree L and refractive
index n, and scores each cell without ground truth (and against it, when given):

``n_segments``
    Segments the cut reached (fewer than asked when the minimum segment size or the
    Ncut threshold stopped it).
``mean_ncut``
    Mean Ncut value of the cuts made (Shi & Malik; each in [0, 2], lower = the segments
    are better separated in the affinity graph). NaN with one segment.
``silhouette``
    Silhouette coefficient of the block labels in the whitened PCA feature space
    (Euclidean distance there is the Mahalanobis distance of the affinity, eq. 4.24), in
    [−1, 1], higher = tighter, better separated segments. Computed on at most
    :data:`SILHOUETTE_SAMPLES` blocks (a fixed-seed random sample). NaN with one segment.
``stability``
    Mean pixel-level adjusted Rand index between this cell's labels and those of its
    grid neighbours (the next smaller and larger w, the next smaller and larger L, same
    n): 1 = the segmentation does not depend on the exact setting. NaN without a
    neighbour that ran.
``ari``
    Pixel-level adjusted Rand index against the ground truth (when given).
``score``
    The combined label-free score, in [0, 1], higher is better: the mean of the finite
    terms among ``(silhouette + 1) / 2``, ``1 − mean_ncut / 2`` and
    ``clip(stability, 0, 1)``; NaN when the cell failed or reached only one segment.
``seconds``
    Wall-clock seconds of the cell's pipeline run (stages the cache could not supply)
    and its silhouette.

Which label-free criterion to trust: on the bundled synthetic scenes (leaves,
camouflage, fruit; seeds 0 and 1; ``RECOMMENDED`` over w 6..16 × L 4, 8, 12) the
stability had a positive rank correlation with the ARI on 5 of 6 scenes (Spearman
+0.26..+0.65), while the silhouette's was negative on all 6 (it prefers few PCA
components, i.e. low L, whatever the segments) and the mean Ncut's and the combined
score's sign varied. The mean Ncut compares badly across settings anyway: every cell
cuts another graph (other blocks, other PCA components; with the absolute affinity scale
the graph's edge weights depend on the number of components). The stability is
therefore the default criterion; on a scene with a
clear material contrast every criterion finds the same cell (``tests/test_sweep.py``).
None of them replaces a ground truth where the material signal is weak.

The cells run with n outermost, then w, then L, so one pipeline serves the whole grid:
the polarisation image is computed once and the surface normals once per n; harmonics
and everything after them once per cell (their key contains w and L). The
reconstruction stage is not run. A cell whose parameters cannot run on this stack (a
window larger than the image, fewer than two blocks, more memory than allowed) is
recorded with its ``error`` and no scores; parameters that are nonsense anywhere
(window 0, degree out of range, n <= 1, an empty grid) raise :class:`PolarsegError`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from ..errors import Cancelled, PolarsegError
from ..features.pca import whiten
from ..params import SegmentParams
from ..pipeline import Pipeline
from ..registered import computes_block_maps
from ..run_memory import check_pipeline_memory
from .evaluation import adjusted_rand_index
from .sweep_result import DEFAULT_SCORE, SCORES, SweepCell, SweepResult

#: Most blocks the silhouette is computed on (a random sample with a fixed seed above).
SILHOUETTE_SAMPLES = 2000
#: Seed of the silhouette's block sample.
SILHOUETTE_SEED = 0


# -- scores ---------------------------------------------------------------------------------


def block_silhouette(
    features: np.ndarray,
    labels: np.ndarray,
    max_samples: int = SILHOUETTE_SAMPLES,
    seed: int = SILHOUETTE_SEED,
) -> float:
    """Silhouette of block labels in the whitened feature space (Mahalanobis distance).

    Parameters
    ----------
    features : array (n_blocks, k)
        Block features (e.g. the PCA features of the ``pca`` stage).
    labels : array (n_blocks,)
        Segment of each block.
    max_samples : int
        Above this many blocks, a random sample of this size (``seed``) is scored.

    Returns
    -------
    float
        Mean silhouette coefficient in [−1, 1]; NaN with fewer than 2 segments (in the
        sample) or as many segments as samples.
    """
    from sklearn.metrics import silhouette_score

    x = np.asarray(features, dtype=float)
    x = x.reshape(x.shape[0], -1) if x.ndim > 1 else x[:, None]
    y = np.asarray(labels).ravel()
    if x.shape[0] != y.size:
        raise PolarsegError(f"{x.shape[0]} feature vectors but {y.size} labels")
    z = whiten(x)
    if y.size > max_samples:
        pick = np.random.default_rng(seed).choice(y.size, max_samples, replace=False)
        z, y = z[pick], y[pick]
    k = np.unique(y).size
    if k < 2 or k >= y.size:
        return math.nan
    return float(silhouette_score(z, y, metric="euclidean"))


def combined_score(silhouette: float, mean_ncut: float, stability: float) -> float:
    """The label-free score in [0, 1] (higher is better).

    Mean of the finite terms among ``(silhouette + 1) / 2``, ``1 − mean_ncut / 2`` (an
    Ncut value is in [0, 2]) and ``clip(stability, 0, 1)``; NaN if none is finite.
    """
    terms = []
    if math.isfinite(silhouette):
        terms.append((silhouette + 1.0) / 2.0)
    if math.isfinite(mean_ncut):
        terms.append(min(max(1.0 - mean_ncut / 2.0, 0.0), 1.0))
    if math.isfinite(stability):
        terms.append(min(max(stability, 0.0), 1.0))
    return float(np.mean(terms)) if terms else math.nan


def neighbour_stability(
    labels: dict[tuple[int, int, int], np.ndarray | None], shape: tuple[int, int, int]
) -> np.ndarray:
    """Mean pixel ARI of every grid cell's labels with its w and L neighbours' labels.

    Parameters
    ----------
    labels : dict (n index, w index, L index) → array (H, W) or None
        Pixel labels of the cells that ran (None or missing: the cell failed).
    shape : (n values, windows, degrees)
        Grid shape.

    Returns
    -------
    ndarray ``shape``
        For each cell the mean adjusted Rand index against the cells one step away in w
        or in L (same n) that have labels; NaN for a cell without labels or without such
        a neighbour.
    """
    out = np.full(shape, np.nan)
    pairs: dict[tuple[tuple[int, ...], tuple[int, ...]], float] = {}
    for idx in np.ndindex(*shape):
        own = labels.get(idx)
        if own is None:
            continue
        k, i, j = idx
        values = []
        for nb in ((k, i - 1, j), (k, i + 1, j), (k, i, j - 1), (k, i, j + 1)):
            if not (0 <= nb[1] < shape[1] and 0 <= nb[2] < shape[2]):
                continue
            other = labels.get(nb)
            if other is None:
                continue
            key = (min(idx, nb), max(idx, nb))
            if key not in pairs:
                pairs[key] = adjusted_rand_index(own, other)
            values.append(pairs[key])
        if values:
            out[idx] = float(np.mean(values))
    return out


# -- the sweep ------------------------------------------------------------------------------


def _axis(values: Any, name: str, kind: type) -> tuple:
    if values is None:
        raise PolarsegError(f"give at least one {name}")
    if isinstance(values, (int, float, np.integer, np.floating)):
        values = [values]
    try:
        items = list(values)
    except TypeError:
        raise PolarsegError(f"{name}s must be a list of numbers, got {values!r}") from None
    if not items:
        raise PolarsegError(f"the sweep needs at least one {name}")
    out = []
    for v in items:
        if isinstance(v, (bool, np.bool_)) or not isinstance(
            v, (int, float, np.integer, np.floating)
        ):
            raise PolarsegError(f"{name}s must be numbers, got {v!r}")
        if kind is int:
            if float(v) != int(v):
                raise PolarsegError(f"{name}s must be whole numbers, got {v!r}")
            out.append(int(v))
        else:
            out.append(float(v))
    return tuple(sorted(set(out)))


def check_grid(
    base: SegmentParams,
    windows: Sequence[int],
    degrees: Sequence[int],
    refractive_indices: Sequence[float] | None = None,
) -> tuple[tuple[int, ...], tuple[int, ...], tuple[float, ...]]:
    """Validated, sorted, de-duplicated grid axes (raises PolarsegError naming the bad one).

    Every value must make valid :class:`SegmentParams` with ``base``; whether a window
    fits the image is left to the cell (it is recorded as that cell's error).
    """
    if not isinstance(base, SegmentParams):
        raise PolarsegError("base must be a SegmentParams")
    if not computes_block_maps(base.method):
        raise PolarsegError(
            f"the w x L x n grid cuts the thesis block graph, not method {base.method}; "
            "sweep its own parameters with analysis.param_sweep (polarseg sweep --vary)"
        )
    if base.n_segments < 2:
        raise PolarsegError(
            f"a sweep compares segmentations: the number of segments must be at least 2, "
            f"got {base.n_segments}"
        )
    ws = _axis(windows, "window size", int)
    ls = _axis(degrees, "harmonic degree", int)
    ns = _axis(
        [base.refractive_index] if refractive_indices is None else refractive_indices,
        "refractive index",
        float,
    )
    for w in ws:
        base.replace(window=w)
    for d in ls:
        base.replace(degree=d)
    for n in ns:
        base.replace(refractive_index=n)
    return ws, ls, ns


def _labels_dtype(labels: np.ndarray) -> np.ndarray:
    top = int(labels.max(initial=0))
    return labels.astype(np.uint8 if top < 2**8 else np.uint16 if top < 2**16 else np.int32)


def iter_sweep(
    stack: np.ndarray,
    angles: np.ndarray,
    base: SegmentParams,
    windows: Sequence[int],
    degrees: Sequence[int],
    refractive_indices: Sequence[float] | None = None,
    ground_truth: np.ndarray | None = None,
    score: str = DEFAULT_SCORE,
    cancel: Callable[[], bool] | None = None,
    mask: Any = None,
    max_bytes: int | None = None,
    keep_labels: bool = True,
) -> Iterator[tuple[int, int, SweepCell]]:
    """Generator form of :func:`sweep`: yields ``(done, total, cell)`` after every cell.

    Its return value (``StopIteration.value``) is the :class:`SweepResult`. Closing the
    generator between cells stops the sweep; ``cancel()`` is also checked between the
    stages of a cell and raises :class:`Cancelled`. Parameters as :func:`sweep`.
    """
    t0 = time.perf_counter()
    ws, ls, ns = check_grid(base, windows, degrees, refractive_indices)
    if score not in SCORES:
        raise PolarsegError(f"score must be one of {', '.join(SCORES)}; got {score!r}")
    if score == "ari" and ground_truth is None:
        raise PolarsegError("score 'ari' needs a ground truth")
    pipe = Pipeline(stack, angles, base, mask=mask)
    shape2d = pipe.stack.shape[1:]
    truth = None
    if ground_truth is not None:
        truth = np.asarray(ground_truth)
        if truth.shape != shape2d:
            raise PolarsegError(
                f"the ground truth is {' x '.join(map(str, truth.shape))} pixels but the "
                f"frames are {shape2d[0]} x {shape2d[1]}"
            )
        adjusted_rand_index(truth, np.zeros(shape2d, np.int32))  # validates the labels
    grid_shape = (len(ns), len(ws), len(ls))
    total = int(np.prod(grid_shape))
    cells: list[SweepCell] = []
    done = 0
    for k, n in enumerate(ns):
        for i, w in enumerate(ws):
            for j, d in enumerate(ls):
                cell = _run_cell(pipe, (k, i, j), n, w, d, cancel, max_bytes)
                cells.append(cell)
                done += 1
                yield done, total, cell
    labels = {c.index: c.labels for c in cells}
    stability = neighbour_stability(labels, grid_shape)
    for c in cells:
        c.stability = float(stability[c.index])
        if c.ok and truth is not None and c.labels is not None:
            c.ari = adjusted_rand_index(truth, c.labels)
        if c.ok and c.n_segments > 1:
            c.score = combined_score(c.silhouette, c.mean_ncut, c.stability)
        if not keep_labels:
            c.labels = None
    return SweepResult(
        base=base,
        windows=ws,
        degrees=ls,
        refractive_indices=ns,
        cells=cells,
        score=score,
        has_ground_truth=truth is not None,
        total_seconds=time.perf_counter() - t0,
        stage_calls=dict(pipe.calls),
    )


def _run_cell(
    pipe: Pipeline,
    index: tuple[int, int, int],
    n: float,
    w: int,
    d: int,
    cancel: Callable[[], bool] | None,
    max_bytes: int | None,
) -> SweepCell:
    cell = SweepCell(index=index, refractive_index=n, window=w, degree=d)
    t0 = time.perf_counter()
    try:
        params = pipe.params.replace(window=w, degree=d, refractive_index=n)
        if max_bytes is not None:
            check_pipeline_memory(pipe.stack.shape, params, max_bytes)
        for stage, index_, count in pipe.run_iter(params, reconstruction=False):
            if cancel is not None and cancel() and index_ < count:
                raise Cancelled(f"sweep cancelled at w={w}, L={d}, n={n:g} ({stage})")
        result = pipe.result(params, reconstruction=False)
        valid = pipe.block_valid(params)
        blocks = result.block_labels.ravel()
        cell.n_segments = result.n_segments
        cell.n_blocks = int(valid.sum())
        cell.n_components = int(result.features.shape[1])
        cell.ncut_values = [float(v) for v in result.ncut_values[: max(cell.n_segments - 1, 0)]]
        cell.mean_ncut = float(np.mean(cell.ncut_values)) if cell.ncut_values else math.nan
        cell.silhouette = block_silhouette(result.features[valid], blocks[valid])
        cell.labels = _labels_dtype(result.labels)
        cell.recomputed = list(result.recomputed)
    except (PolarsegError, np.linalg.LinAlgError, MemoryError) as exc:
        cell.error = str(exc) or type(exc).__name__
    cell.seconds = time.perf_counter() - t0
    return cell


def sweep(
    stack: np.ndarray,
    angles: np.ndarray,
    base: SegmentParams,
    windows: Sequence[int],
    degrees: Sequence[int],
    refractive_indices: Sequence[float] | None = None,
    ground_truth: np.ndarray | None = None,
    score: str = DEFAULT_SCORE,
    progress: Callable[[int, int], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    mask: Any = None,
    max_bytes: int | None = None,
    keep_labels: bool = True,
) -> SweepResult:
    """Segment a stack for every (n, w, L) of a grid and score each cell.

    Parameters
    ----------
    stack : array (N, H, W)
        Angle stack.
    angles : array (N,)
        Polariser angles in **radians**.
    base : SegmentParams
        Every other parameter (number of segments, features, affinity scale, …).
    windows : sequence of int
        Window sizes w in pixels (sorted and de-duplicated).
    degrees : sequence of int
        Harmonic degrees L.
    refractive_indices : sequence of float, optional
        Refractive indices n (> 1); default ``[base.refractive_index]``.
    ground_truth : array (H, W) of int, optional
        True materials: adds the ``ari`` column.
    score : {"stability", "combined", "silhouette", "ncut", "ari"}
        What :meth:`SweepResult.best` picks by default: the stability (default), the
        combined label-free score, one of its other parts (``"ncut"``: the smallest
        mean Ncut), or the adjusted Rand index against ``ground_truth``.
    progress : callable(done, total), optional
        Called after every cell.
    cancel : callable() -> bool, optional
        Checked between stages; True raises :class:`Cancelled`.
    mask : array (H, W) or PixelMask, optional
        Region / pixel mask, as for :class:`Pipeline`.
    max_bytes : int, optional
        Memory limit per cell (:func:`~napari_polarseg.engine.run_memory.check_pipeline_memory`);
        a cell above it is recorded as failed.
    keep_labels : bool
        Keep every cell's pixel labels in memory (``SweepResult.labels(cell)``).

    Returns
    -------
    SweepResult

    Raises
    ------
    PolarsegError
        An empty or invalid grid, an unknown score, ``"ari"`` without ground truth, a
        ground truth of the wrong size, or a stack the pipeline refuses.
    Cancelled
        If ``cancel()`` returned True.

    Examples
    --------
    >>> res = sweep(stack, angles, RECOMMENDED, [8, 10, 12], [4, 8])   # doctest: +SKIP
    >>> res.best()                                                      # doctest: +SKIP
    SegmentParams(window=10, degree=8, ...)
    >>> res.grid("silhouette")[0]       # w × L for the first n            # doctest: +SKIP
    """
    rest = (ground_truth, score, cancel, mask, max_bytes, keep_labels)
    gen = iter_sweep(stack, angles, base, windows, degrees, refractive_indices, *rest)
    while True:
        try:
            done, total, _ = next(gen)
        except StopIteration as stop:
            return stop.value
        if progress is not None:
            progress(done, total)
        if cancel is not None and cancel() and done < total:
            gen.close()
            raise Cancelled(f"sweep cancelled after {done} of {total} cells")
