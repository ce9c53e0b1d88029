"""Time series: scenes of one view over time segmented in one shared feature basis.

Day 3, day 4, … of the same fruit, field or net: every day runs the ordinary pipeline up
to the block coefficients (:class:`~napari_polarseg.engine.Pipeline`'s ``"harmonics"``
stage), then

1. the block feature vectors of **all** days (:func:`~.features.harmonic_features`) are
   stacked and one PCA is fitted to them (:func:`~.features.pca_features`), so every day
   is described in the same basis and with the same Mahalanobis metric (the covariance
   over the blocks of all days);
2. the blocks are segmented either

   - ``"reference"`` (default): the first day is cut alone (the ordinary affinity and
     recursive normalized cut on its blocks), which defines the segments and their means
     (over the first day's blocks); then every block of every day, day 1 included, takes
     the segment whose mean is nearest in the shared whitened basis (Mahalanobis
     distance with the covariance of all days), so a block that did not change gets the
     same segment on every day;
   - ``"joint"``: one affinity over the blocks of all days and one cut of that graph. A
     segment is then a set of blocks from any day, so a material that appears only
     later can get a segment of its own; an unchanged block and its copy on the next
     day have nearly the same features and stay together. Costs a dense affinity over
     T × the blocks of one day (:data:`~.pipeline.MAX_DENSE_BLOCKS` in all);

   either way segment k means the same material on every day;
3. a **change map** per pair of consecutive days marks the blocks whose segment changed,
   and a **feature distance** map gives, per block, the Mahalanobis distance between its
   features on the two days (graded; the static geometry cancels in it).

Why ``reference`` is the default: on the synthetic bruised fruit whose bruise grows by
10 px between two days (120 × 130, ``RECOMMENDED`` with k = 2, 8 seeds; the renderer is
in ``tests/test_timeseries.py``) it flagged nearly twice as much of the growth (9.7 %
against 5.5 % of the newly bruised pixels) at nearly the same consistency (97.5 % against
98.2 % of the pixels whose truth did not change keep their label); it also costs one
day's affinity whatever the number of days. Choose ``joint`` when a material may appear
that day 1 does not show. Both are limited by the single-day segmentation, which on the
fruit scene is weak (adjusted Rand index about 0.2): the segments follow surface tilt
more than the bruise, so most of the growth stays in the "healthy" segment. The feature
distance ranks grown blocks above unchanged ones better (area under the ROC curve about
0.78).

All days must show the same view at the same size (no registration between days is
done; register them beforehand if the camera moved). Angles are radians here.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import features as feat
from . import harmonics, ncut
from .errors import Cancelled, PolarsegError
from .params import SegmentParams
from .pipeline import MAX_DENSE_BLOCKS, Pipeline

#: Ways to segment the days in the shared basis (see the module docstring).
METHODS = ("joint", "reference")


@dataclass
class TimeSeriesResult:
    """Segments of several days of one view in one shared basis, and their changes.

    Attributes
    ----------
    params : SegmentParams
        Parameters used for every day.
    method : {"joint", "reference"}
        How the blocks were segmented (module docstring).
    labels : ndarray (T, H, W) int32
        Segment of every pixel on each day; segment k means the same material on every
        day (0 = first segment, numbered in order of first appearance on day 1).
    block_labels : ndarray (T, rows, cols) int32
        Segment of every w × w block on each day.
    changes : ndarray (T − 1, H, W) bool
        ``changes[t]``: the pixel's block is in another segment on day t + 1 than on day t.
    block_changes : ndarray (T − 1, rows, cols) bool
        The same per block.
    feature_distance : ndarray (T − 1, H, W) float32
        Mahalanobis distance (covariance of all days' blocks) between the features of
        the pixel's block on day t and on day t + 1: how much the block changed, whether
        or not it changed segment. The view is static, so the surface geometry that
        dominates the features cancels here; a graded companion of ``changes``.
    block_feature_distance : ndarray (T − 1, rows, cols)
        The same per block.
    features : ndarray (T, n_blocks, n_components)
        Block features of every day in the shared PCA basis.
    explained_variance_ratio : ndarray (n_components,)
        Share of the variance (over all days' blocks) each kept component explains.
    components : ndarray (n_components, n_features)
        The shared principal axes.
    segment_means : ndarray (K, n_components)
        Mean feature vector of each segment (over all days for ``joint``, over day 1
        for ``reference``).
    ncut_values : list of float
        Ncut value of each split.
    pipelines : list of Pipeline
        The per-day pipelines (their cached stages hold Î, ρ, φ, normals, coefficients).
    timings : dict
        Seconds per step.
    """

    params: SegmentParams
    method: str
    labels: np.ndarray
    block_labels: np.ndarray
    changes: np.ndarray
    block_changes: np.ndarray
    feature_distance: np.ndarray
    block_feature_distance: np.ndarray
    features: np.ndarray
    explained_variance_ratio: np.ndarray
    components: np.ndarray
    segment_means: np.ndarray
    ncut_values: list[float]
    pipelines: list[Pipeline] = field(default_factory=list, repr=False)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def n_days(self) -> int:
        return int(self.labels.shape[0])

    @property
    def n_segments(self) -> int:
        return int(self.block_labels.max()) + 1

    def changed_fraction(self) -> np.ndarray:
        """Share of blocks that changed segment between each pair of consecutive days."""
        if self.block_changes.shape[0] == 0:
            return np.zeros(0)
        return self.block_changes.reshape(self.block_changes.shape[0], -1).mean(axis=1)

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures: segments per day, changes per pair of days, PCA, timings."""
        k = self.n_segments
        return {
            "method": self.method,
            "n_days": self.n_days,
            "n_segments": k,
            "segment_pixels": [
                np.bincount(day.ravel(), minlength=k).tolist() for day in self.labels
            ],
            "segment_blocks": [
                np.bincount(day.ravel(), minlength=k).tolist() for day in self.block_labels
            ],
            "block_grid": list(self.block_labels.shape[1:]),
            "changed_blocks": [int(c.sum()) for c in self.block_changes],
            "changed_block_fraction": [float(v) for v in self.changed_fraction()],
            "changed_pixels": [int(c.sum()) for c in self.changes],
            "mean_feature_distance": [float(d.mean()) for d in self.block_feature_distance],
            "n_components": int(self.features.shape[-1]),
            "explained_variance": float(np.sum(self.explained_variance_ratio)),
            "explained_variance_ratio": [float(v) for v in self.explained_variance_ratio],
            "ncut_values": [float(v) for v in self.ncut_values],
            "seconds": {name: round(v, 6) for name, v in self.timings.items()},
        }


def change_map(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Where two labellings of the same view disagree (True = the segment changed).

    Only meaningful for labels in one shared numbering (:func:`segment_timeseries`);
    labels of two independent runs are numbered arbitrarily.

    Parameters
    ----------
    before, after : array (H, W) of int
        Labels of two consecutive days.

    Returns
    -------
    ndarray (H, W) bool
    """
    a, b = np.asarray(before), np.asarray(after)
    if a.shape != b.shape:
        raise PolarsegError(f"labels of {a.shape} and {b.shape} cannot be compared")
    return a != b


def _as_list(angles: Sequence[np.ndarray] | np.ndarray, n: int) -> list[np.ndarray]:
    arr = np.asarray(angles, dtype=object if isinstance(angles, list) else float)
    if arr.dtype != object and arr.ndim == 1:
        return [np.asarray(angles, dtype=float)] * n
    out = [np.asarray(a, dtype=float).ravel() for a in angles]
    if len(out) != n:
        raise PolarsegError(f"{n} stacks but {len(out)} sets of angles")
    return out


def segment_timeseries(
    stacks: Sequence[np.ndarray],
    angles: Sequence[np.ndarray] | np.ndarray,
    params: SegmentParams | None = None,
    *,
    method: str = "reference",
    masks: Sequence[Any] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    cancel: Callable[[], bool] | None = None,
) -> TimeSeriesResult:
    """Segment several days of the same view with features in one shared PCA basis.

    Parameters
    ----------
    stacks : sequence of arrays (N_t, H, W)
        One angle stack per day, in time order; every day must be H × W.
    angles : array (N,) or sequence of arrays (N_t,)
        Polariser angles in radians: one array for all days, or one per day.
    params : SegmentParams, optional
        Parameters for every day (default: the thesis defaults). ``min_segment_blocks``
        is per day: the joint cut requires T times as many blocks of all days together.
    method : {"joint", "reference"}
        One cut over all days' blocks, or cut day 1 and assign later blocks to the
        nearest segment mean (module docstring).
    masks : sequence, optional
        Per-day ``mask`` for :class:`~napari_polarseg.engine.Pipeline` (region arrays
        or :class:`~napari_polarseg.engine.polarimage.PixelMask`, None entries allowed).
    progress : callable(stage, index, total), optional
        Called after each step.
    cancel : callable() -> bool, optional
        Checked between steps; returning True raises :class:`Cancelled`.

    Returns
    -------
    TimeSeriesResult

    Raises
    ------
    PolarsegError
        Fewer than 2 days, days of different sizes, a bad method, too many blocks for
        the dense joint affinity, or any error of the per-day pipeline (prefixed with
        the day).

    Examples
    --------
    >>> res = segment_timeseries([day1, day2], angles, RECOMMENDED)  # doctest: +SKIP
    >>> res.labels.shape, res.changes.shape                           # doctest: +SKIP
    ((2, 120, 130), (1, 120, 130))
    """
    params = SegmentParams() if params is None else params
    if not isinstance(params, SegmentParams):
        raise PolarsegError("params must be a SegmentParams")
    if method not in METHODS:
        raise PolarsegError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    stacks = list(stacks)
    n_days = len(stacks)
    if n_days < 2:
        raise PolarsegError(f"a time series needs at least 2 scenes, got {n_days}")
    angle_list = _as_list(angles, n_days)
    mask_list = [None] * n_days if masks is None else list(masks)
    if len(mask_list) != n_days:
        raise PolarsegError(f"{n_days} stacks but {len(mask_list)} masks")

    total = n_days + 4
    step = 0
    timings: dict[str, float] = {}

    def done(stage: str, t0: float) -> None:
        nonlocal step
        step += 1
        timings[stage] = time.perf_counter() - t0
        if progress is not None:
            progress(stage, step, total)
        if cancel is not None and step < total and cancel():
            raise Cancelled(f"cancelled after {stage!r}")

    # 1. per-day pipelines up to the block coefficients
    pipelines: list[Pipeline] = []
    vectors: list[np.ndarray] = []
    shape: tuple[int, ...] | None = None
    grid: tuple[int, ...] | None = None
    for t in range(n_days):
        t0 = time.perf_counter()
        try:
            pipe = Pipeline(np.asarray(stacks[t]), angle_list[t], params, mask=mask_list[t])
            coef = pipe.get("harmonics")
        except PolarsegError as exc:
            raise PolarsegError(f"day {t + 1}: {exc}") from None
        day_shape = tuple(pipe.stack.shape[1:])
        if shape is None:
            shape, grid = day_shape, tuple(coef.shape[:2])
        elif day_shape != shape:
            raise PolarsegError(
                f"day {t + 1} is {day_shape[0]} x {day_shape[1]} pixels but day 1 is "
                f"{shape[0]} x {shape[1]}: a time series needs the same view every day"
            )
        pipelines.append(pipe)
        vectors.append(feat.harmonic_features(coef, params.features))
        done(f"day {t + 1} harmonics", t0)
    assert shape is not None and grid is not None
    n_blocks = int(np.prod(grid))

    # 2. one PCA over the blocks of all days
    t0 = time.perf_counter()
    pca = feat.pca_features(np.concatenate(vectors, axis=0), params.variance)
    scores = pca.features
    done("shared pca", t0)

    # 3. segments
    t0 = time.perf_counter()
    if method == "joint":
        if scores.shape[0] > MAX_DENSE_BLOCKS:
            raise PolarsegError(
                f"{n_days} days of {n_blocks} blocks is too many for the joint affinity "
                f"(limit {MAX_DENSE_BLOCKS} blocks in all); use a larger window or "
                "method='reference'"
            )
        graph_feats, min_size = scores, params.min_segment_blocks * n_days
    else:
        graph_feats, min_size = scores[:n_blocks], params.min_segment_blocks
    W = feat.affinity_matrix(graph_feats, params.scale, params.scale_mode)
    if params.spatial_radius > 0:
        kernel = feat.spatial_kernel(grid, params.spatial_radius, params.spatial_sigma)
        reps = W.shape[0] // n_blocks
        W *= np.tile(kernel, (reps, reps))  # the same position on any day is a neighbour
    done("affinity", t0)

    t0 = time.perf_counter()
    tree = ncut.CutTree(W, min_size=min_size, threshold=params.ncut_threshold)
    graph_labels = tree.labels(params.n_segments).astype(np.int32)
    k = int(graph_labels.max()) + 1
    # Mahalanobis distance under the covariance of all days' blocks = Euclidean on z
    z = feat.whiten(scores)
    if method == "joint":
        flat = graph_labels
        segment_means = _segment_means(scores, flat, k)
    else:
        # every block of every day, day 1 included, takes its nearest segment mean, so
        # that identical blocks on two days always get the same segment
        means_z = _segment_means(z[:n_blocks], graph_labels, k)
        d2 = np.einsum("ij,ij->i", z, z)[:, None] - 2.0 * z @ means_z.T
        d2 += np.einsum("ij,ij->i", means_z, means_z)[None, :]
        flat = np.argmin(d2, axis=1).astype(np.int32)
        segment_means = _segment_means(scores[:n_blocks], graph_labels, k)
    zd = z.reshape(n_days, n_blocks, -1)
    distance = np.sqrt(((zd[1:] - zd[:-1]) ** 2).sum(-1)).reshape(n_days - 1, *grid)
    done("cut", t0)

    # 4. pixel labels and change maps
    t0 = time.perf_counter()
    block_labels = flat.reshape(n_days, *grid).astype(np.int32)
    labels = np.stack(
        [harmonics.upsample_block_labels(b, shape, params.window) for b in block_labels]
    ).astype(np.int32)
    block_changes = block_labels[1:] != block_labels[:-1]
    changes = labels[1:] != labels[:-1]
    pixel_distance = np.stack(
        [harmonics.upsample_block_labels(d, shape, params.window) for d in distance]
    ).astype(np.float32)
    done("labels", t0)

    return TimeSeriesResult(
        params=params,
        method=method,
        labels=labels,
        block_labels=block_labels,
        changes=changes,
        block_changes=block_changes,
        feature_distance=pixel_distance,
        block_feature_distance=distance,
        features=scores.reshape(n_days, n_blocks, -1),
        explained_variance_ratio=pca.explained_variance_ratio,
        components=pca.components,
        segment_means=segment_means,
        ncut_values=tree.ncut_values,
        pipelines=pipelines,
        timings=timings,
    )


def _segment_means(x: np.ndarray, labels: np.ndarray, k: int) -> np.ndarray:
    """Mean row of ``x`` per label 0..k−1 (vectorised with bincount-style sums)."""
    counts = np.bincount(labels, minlength=k).astype(float)
    sums = np.zeros((k, x.shape[1]))
    np.add.at(sums, labels, x)
    return sums / np.maximum(counts, 1.0)[:, None]
