"""Time series: one view over several days, segmented consistently, and what changed.

Day 3, day 4, … of the same fruit, field or net. Every day runs the ordinary pipeline up
to the block coefficients (:class:`~napari_polarseg.engine.Pipeline`'s ``"harmonics"``
stage); the block feature vectors of **all** days are stacked and one PCA is fitted to
them, so every day is described in the same basis and Mahalanobis metric. Then:

1. **Change test** (:func:`change_statistics`), from the polarisation images directly.
   The view is static, so a pixel sees the same surface (tilt, azimuth, texture,
   shading) on every day: per pixel, the change of log Î and of the normalised Stokes
   vector ρ·e^{2iφ} between consecutive days cancels the geometry that dominates Î and
   ρ (and the single-day features) and keeps the change of material plus noise. Per
   change block (side ``change_window``, default 6 px for w = 8–12) Hotelling's T²
   tests whether the mean of these three differences (Î; ρ along and across the block's
   polarisation direction) is zero against their scatter over the block's own pixels:
   under independent pixel noise its law is F(3, n − 3) whatever the noise level, so a
   block without change is flagged with exactly the chosen **false-alarm rate**
   (default 0.001 per block and pair of days; the score is the normal deviate of the
   p-value, 3.09 at 0.001). Two nuisances are removed from the data, not tuned: an
   image-wide intensity gain (exposure, illumination level; a trimmed precision-weighted
   mean of the blocks' log Î change) and a noise inflation λ >= 1 (spatially correlated
   noise such as interpolated demosaicing makes block means vary more than their pixel
   scatter says; λ is fitted so that the blocks below the threshold follow the
   truncated χ² of no change, which changed blocks cannot inflate).
2. **Segments**, by ``method``; day 1 is cut alone as below under a method that cuts
   the block graph (declares ``block_maps``: the thesis method), any other method
   labels day 1's pixels itself (``day_labels``) and ``"reference"`` takes each block's
   most frequent label of them:

   - ``"tracked"`` (default): day 1 is cut alone (the usual affinity and cut on its
     blocks, in the shared basis); each later day starts as a copy of the day before
     and only the change blocks flagged by the test move, to the segment of the
     material they changed into (:func:`.tracking.track_labels`): a changed segment is
     a kind of change, described by the signs of the components significant over its
     blocks (the fruit's bruise: Î down, ρ down); a flagged block joins the changed segment
     whose signs it does not contradict, stays in it when its change goes on the same
     way, goes back to its former segment when it undoes the change, or starts a new
     changed segment. Unchanged blocks keep their segment by construction.
   - ``"reference"``: day 1 is cut alone; every block of every day, day 1 included,
     takes the segment whose mean (over day 1) is nearest in the shared whitened basis.
   - ``"joint"``: one affinity over the blocks of all days and one cut of that graph
     (a material that day 1 does not show can get a segment of its own; the dense
     affinity over T × the blocks of one day is limited to
     :data:`~napari_polarseg.engine.stages.MAX_DENSE_BLOCKS`; a method that cuts blocks
     only);

   either way segment k means the same material on every day.
3. **Maps** per pair of consecutive days: the change map (pixels, block-shaped, whose
   segment changed), the graded change score of the test, and the older feature
   distance (Mahalanobis distance between a block's shared-basis features on the two
   days).

Measured on the synthetic bruised fruit whose bruise grows by 10 px between two days
(120 × 130, ``RECOMMENDED`` with 2 segments, a minimum segment of 2 blocks, the
defaults above; renderer and figures in ``tests/test_timeseries.py``; 10 seeds,
``.venv/bin/python benchmarks/bench_timeseries.py``), mean (worst seed):

=====================================================  ================  ==============
figure                                                 tracked           reference
=====================================================  ================  ==============
pixels whose truth did not change keeping their label  97.2 % (96.3 %)   96.9 % (94.2 %)
newly bruised pixels in the change map                 83.0 % (74.3 %)   9.0 % (0 %)
change blocks, majority newly bruised, in the map      93.4 % (83.3 %)   9.3 % (0 %)
change blocks without any change in the map            0.13 % (0.61 %)   2.7 % (5.2 %)
same truth both days: pixels changing segment          0.12 % (0.46 %)   2.2 % (3.7 %)
=====================================================  ================  ==============

(``joint``: 97.8 %, 6.9 %, 7.4 %, 1.9 %, 2.0 %.) The change score ranks the grown change
blocks above the unchanged ones with an area under the ROC curve of 0.998 (min 0.989;
per pixel 0.974, limited by the block size), against 0.78 for the feature distance.
With the same truth on both days 0.5 of the 420 change blocks were flagged on average
(0.42 expected at 0.001; 3.9 at 0.01 for 4.2 expected; 0.1 at 0.0001), so the
threshold means what it says. With the pixel noise blurred over 2 × 2 pixels λ comes
out at 3.4–4 and keeps the flags at 0 (without it 17 % of the blocks are flagged).
``reference`` and ``joint`` are limited by the single-day segmentation, whose segments
on this scene follow surface tilt more than the bruise (adjusted Rand index ≈ 0.2), so
most newly bruised blocks keep their "healthy" segment while noise flips others;
``tracked`` does not depend on it for the changes, hence the default.

Where the evidence comes from: the fruit faces the camera, so ρ is below 0.01 over most
of the grown ring and the bruise's drop to ~0.7 ρ is ~0.002, about half the per-pixel
noise; the rougher bruised skin also shades ~1 % darker. Testing only the polarisation
(``change_from="polarisation"``, for scenes whose lighting changes beyond a global gain)
finds 14 % of the growth, only the intensity 82 %, both 83 %. The change block side
trades outline against power (tracked, 10 seeds): 4 px 99.6 % consistency / 63 %
coverage, 6 px 97.2 / 83, 8 px 93.7 / 92, 12 px 87.5 / 93 (a block that moves carries
its unchanged pixels along). The false-alarm rate does too: 0.01 gives 95.2 / 90,
0.0001 98.3 / 75.

Limits: days must show the same view at the same size (register them beforehand; no
registration between days is done), consecutive days are compared (a change slower
than the test can see per step is missed), and a block partly changed moves whole.
Angles are radians here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from ..errors import Cancelled, PolarsegError
from ..features import harmonics, polstats
from ..features import pca as feat
from ..graph import affinity, ncut, spectral
from ..params import PRESETS, SegmentParams
from ..pipeline import Pipeline
from ..registered import computes_block_maps
from ..stages import MAX_DENSE_BLOCKS, POLSTATS_KINDS
from ..timing import timed
from .change_test import (
    CHANGE_SOURCES,
    DEFAULT_FALSE_ALARM,
    ChangeStatistics,
    change_statistics,
    default_change_window,
)
from .timeseries_result import TimeSeriesResult
from .timeseries_segments import DaySegments, day_segments
from .tracking import block_majority

#: Ways to segment the days (see the module docstring); the first is the default.
METHODS = ("tracked", "reference", "joint")

#: Day 1's pixel labels (H, W) under a method that does not cut the block graph, from
#: day 1's pipeline and the parameters:
#: :func:`napari_polarseg.engine.methods.scene.pipeline_labels` (the analysis cannot
#: import the methods, which import it).
DayLabels = Callable[[Pipeline, SegmentParams], np.ndarray]


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
    method: str = "tracked",
    change_window: int | None = None,
    false_alarm: float = DEFAULT_FALSE_ALARM,
    change_from: str = "all",
    masks: Sequence[Any] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    day_labels: DayLabels | None = None,
) -> TimeSeriesResult:
    """Segment several days of the same view consistently and map what changed.

    Parameters
    ----------
    stacks : sequence of arrays (N_t, H, W)
        One angle stack per day, in time order; every day must be H × W.
    angles : array (N,) or sequence of arrays (N_t,)
        Polariser angles in radians: one array for all days, or one per day.
    params : SegmentParams, optional
        Parameters for every day (default: the thesis defaults). ``min_segment_blocks``
        is per day: the joint cut requires T times as many blocks of all days together.
    method : {"tracked", "reference", "joint"}
        Carry day 1's segments and move only the blocks whose polarisation changed
        significantly; cut day 1 and give every block the nearest segment mean; or one
        cut over all days' blocks (module docstring).
    change_window : int, optional
        Side of the change blocks (default :func:`default_change_window` of
        ``params.window``: 6 for w = 12).
    false_alarm : float
        Probability that a change block without change is flagged, per block and pair
        of days (default 0.001: score threshold 3.09).
    change_from : {"all", "polarisation", "intensity"}
        What the change test compares (:func:`change_statistics`).
    masks : sequence, optional
        Per-day ``mask`` for :class:`~napari_polarseg.engine.Pipeline` (region arrays
        or :class:`~napari_polarseg.engine.physics.pixel_mask.PixelMask`, None entries allowed).
    progress : callable(stage, index, total), optional
        Called after each step.
    cancel : callable() -> bool, optional
        Checked between steps; returning True raises :class:`Cancelled`.
    day_labels : callable(pipeline, params) -> labels, optional
        Day 1's labels under a method that does not cut blocks (:data:`DayLabels`).

    Returns
    -------
    TimeSeriesResult

    Raises
    ------
    PolarsegError
        Fewer than 2 days, days of different sizes, a bad method or change option, too
        many blocks for the joint affinity, a joint cut or no ``day_labels`` for a method
        that does not cut blocks, or an error of a day's pipeline (prefixed with the day).

    Examples
    --------
    >>> res = segment_timeseries([day1, day2], angles, RECOMMENDED)  # doctest: +SKIP
    >>> res.labels.shape, res.changes.shape, res.change_score.shape  # doctest: +SKIP
    ((2, 120, 130), (1, 120, 130), (1, 120, 130))
    """
    opt = _check_options(params, method, change_window, false_alarm, change_from, day_labels)
    stacks, angle_list, mask_list = _inputs(stacks, angles, masks)
    steps = _Steps(len(stacks) + 4 + int(computes_block_maps(opt.params.method)), progress, cancel)
    # 1. per-day pipelines up to the block coefficients
    pipelines, vectors, shape, grid = _day_pipelines(stacks, angle_list, mask_list, opt, steps)
    # 2. one PCA over the blocks of all days
    pca = steps.run("shared pca", _shared_pca, vectors, opt.params)
    # 3. the change test between consecutive days, from the polarisation images
    pols = [pipe.get("polarisation") for pipe in pipelines]
    change_stats = steps.run("change test", _change_tests, pols, opt)
    # 4. segments: the affinity and the cut (or day 1's labels) and every day's labels
    days = (pipelines[0], pca.features, grid, shape, opt, change_stats, steps, day_labels)
    ncut_values, segs = _segment_days(*days)
    # 5. change maps
    maps = steps.run("labels", _change_maps, segs, change_stats, shape, opt)
    return _result(opt, segs, maps, change_stats, pca, ncut_values, pipelines, steps.timings)


class _Options(NamedTuple):
    """The checked options of :func:`segment_timeseries`."""

    params: SegmentParams
    method: str
    change_window: int
    false_alarm: float
    change_from: str


def _segment_days(
    pipe: Pipeline,
    scores: np.ndarray,
    grid: tuple[int, ...],
    shape: tuple[int, ...],
    opt: _Options,
    change_stats: list[ChangeStatistics],
    steps: _Steps,
    day_labels: DayLabels | None,
) -> tuple[list[float], DaySegments]:
    """Every day's segments: from the block cut under a method that cuts blocks (steps
    "affinity" and "cut"), else from the method's labels of day 1 (step "day 1
    labels"); (Ncut values, segments)."""
    if computes_block_maps(opt.params.method):
        return _cut_days(scores, grid, shape, opt, change_stats, steps)
    day1 = (pipe, scores, grid, shape, opt, change_stats, day_labels)
    return steps.run("day 1 labels", _labelled_days, *day1)


def _cut_days(
    scores: np.ndarray,
    grid: tuple[int, ...],
    shape: tuple[int, ...],
    opt: _Options,
    change_stats: list[ChangeStatistics],
    steps: _Steps,
) -> tuple[list[float], DaySegments]:
    """Steps "affinity" and "cut": the block graph, its cut and the labels of every day;
    (Ncut values, segments)."""
    n_days = scores.shape[0] // int(np.prod(grid))
    W, min_size = steps.run("affinity", _block_graph, scores, grid, n_days, opt.params, opt.method)
    with timed(steps.timings, "cut"):
        tree = _cut_tree(W, min_size, opt.params)
        graph_labels = tree.labels(opt.params.n_segments).astype(np.int32)
        segs = day_segments(
            opt.method,
            graph_labels,
            None,
            scores,
            grid,
            shape,
            opt.params,
            change_stats,
            opt.change_window,
        )
    steps.done("cut")
    return list(tree.ncut_values), segs


def _labelled_days(
    pipe: Pipeline,
    scores: np.ndarray,
    grid: tuple[int, ...],
    shape: tuple[int, ...],
    opt: _Options,
    change_stats: list[ChangeStatistics],
    day_labels: DayLabels | None,
) -> tuple[list[float], DaySegments]:
    """Step "day 1 labels" of a method that does not cut blocks: its labels of day 1
    carried ("tracked") or, as each block's most frequent one, the segments whose means
    every day's blocks take ("reference"); (no Ncut values, segments)."""
    assert day_labels is not None  # refused without them (_check_options)
    base = np.asarray(day_labels(pipe, opt.params)).astype(np.int32)
    majority = block_majority(base, opt.params.window).ravel()
    graph_labels = np.unique(majority, return_inverse=True)[1].astype(np.int32)  # 0..k-1
    tracked = base if opt.method == "tracked" else None
    segs = day_segments(
        opt.method,
        graph_labels,
        tracked,
        scores,
        grid,
        shape,
        opt.params,
        change_stats,
        opt.change_window,
    )
    return [], segs


def _inputs(
    stacks: Sequence[np.ndarray],
    angles: Sequence[np.ndarray] | np.ndarray,
    masks: Sequence[Any] | None,
) -> tuple[list[np.ndarray], list[np.ndarray], list[Any]]:
    """The days' stacks, angles (one array per day) and masks (None entries allowed)."""
    stacks = list(stacks)
    n_days = len(stacks)
    if n_days < 2:
        raise PolarsegError(f"a time series needs at least 2 scenes, got {n_days}")
    angle_list = _as_list(angles, n_days)
    mask_list = [None] * n_days if masks is None else list(masks)
    if len(mask_list) != n_days:
        raise PolarsegError(f"{n_days} stacks but {len(mask_list)} masks")
    return stacks, angle_list, mask_list


def _change_tests(pols: list[Any], opt: _Options) -> list[ChangeStatistics]:
    """:func:`~.change_test.change_statistics` between every pair of consecutive days."""
    return [
        change_statistics(
            a, b, opt.change_window, false_alarm=opt.false_alarm, change_from=opt.change_from
        )
        for a, b in zip(pols[:-1], pols[1:], strict=True)
    ]


def _result(
    opt: _Options,
    segs: DaySegments,
    maps: dict[str, np.ndarray],
    change_stats: list[ChangeStatistics],
    pca: feat.PCAResult,
    ncut_values: list[float],
    pipelines: list[Pipeline],
    timings: dict[str, float],
) -> TimeSeriesResult:
    """The :class:`TimeSeriesResult` of the steps' outputs."""
    n_days = segs.labels.shape[0]
    return TimeSeriesResult(
        params=opt.params,
        method=opt.method,
        labels=segs.labels,
        block_labels=segs.block_labels,
        changes=maps["changes"],
        block_changes=maps["block_changes"],
        change_score=maps["change_score"],
        block_change_score=maps["block_change_score"],
        change_significant=np.stack([s.significant for s in change_stats]),
        change_statistics=change_stats,
        feature_distance=maps["feature_distance"],
        block_feature_distance=segs.distance,
        features=pca.features.reshape(n_days, segs.distance[0].size, -1),
        explained_variance_ratio=pca.explained_variance_ratio,
        components=pca.components,
        segment_means=segs.segment_means,
        ncut_values=ncut_values,
        n_base_segments=segs.k,
        changed_segments=segs.changed_segments,
        label_window=segs.label_window,
        change_window=opt.change_window,
        false_alarm=opt.false_alarm,
        change_from=opt.change_from,
        pipelines=pipelines,
        timings=timings,
    )


def _shared_pca(vectors: list[np.ndarray], params: SegmentParams) -> feat.PCAResult:
    """One PCA over the blocks of all days (polarisation statistics z-scored over all)."""
    pooled = np.concatenate(vectors, axis=0)
    if params.features in POLSTATS_KINDS:
        pooled = polstats.standardise(pooled)  # one z-score over every day's blocks
    return feat.pca_features(pooled, params.variance)


def _check_options(
    params: SegmentParams | None,
    method: str,
    change_window: int | None,
    false_alarm: float,
    change_from: str,
    day_labels: DayLabels | None,
) -> _Options:
    """Refuse bad options of :func:`segment_timeseries` (default parameters: the thesis's)."""
    params = PRESETS["thesis"] if params is None else params
    if not isinstance(params, SegmentParams):
        raise PolarsegError("params must be a SegmentParams")
    if method not in METHODS:
        raise PolarsegError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    if not computes_block_maps(params.method):
        if method == "joint":
            raise PolarsegError(
                "the joint time series cuts one block graph of all days: a method that "
                f"cuts blocks (thesis), not {params.method}; use tracked or reference"
            )
        if day_labels is None:
            raise PolarsegError(
                f"method {params.method} labels day 1 itself: give day_labels "
                "(napari_polarseg.engine.methods.scene.pipeline_labels)"
            )
    if change_from not in CHANGE_SOURCES:
        raise PolarsegError(
            f"change_from must be one of {', '.join(CHANGE_SOURCES)}; got {change_from!r}"
        )
    if not 0.0 < float(false_alarm) < 1.0:
        raise PolarsegError(f"false_alarm must be in (0, 1), got {false_alarm!r}")
    if change_window is None:
        change_window = default_change_window(params.window)
    if int(change_window) != change_window or change_window < 2:
        raise PolarsegError(f"change_window must be an integer >= 2, got {change_window!r}")
    return _Options(params, method, int(change_window), float(false_alarm), change_from)


class _Steps:
    """Progress, timings and Cancel between the steps of :func:`segment_timeseries`."""

    def __init__(
        self,
        total: int,
        progress: Callable[[str, int, int], None] | None,
        cancel: Callable[[], bool] | None,
    ) -> None:
        self.total, self.step = total, 0
        self.progress, self.cancel = progress, cancel
        self.timings: dict[str, float] = {}

    def run(self, stage: str, work: Callable[..., Any], *args: Any) -> Any:
        """``work(*args)`` as the step ``stage``: timed, reported, then Cancel checked."""
        with timed(self.timings, stage):
            out = work(*args)
        self.done(stage)
        return out

    def done(self, stage: str) -> None:
        """Report ``stage`` (timed into ``timings``), raise Cancelled if asked."""
        self.step += 1
        if self.progress is not None:
            self.progress(stage, self.step, self.total)
        if self.cancel is not None and self.step < self.total and self.cancel():
            raise Cancelled(f"cancelled after {stage!r}")


def _day_pipelines(
    stacks: list[np.ndarray],
    angle_list: list[np.ndarray],
    mask_list: list[Any],
    opt: _Options,
    steps: _Steps,
) -> tuple[list[Pipeline], list[np.ndarray], tuple[int, ...], tuple[int, ...]]:
    """Every day's pipeline up to the block coefficients, and its unstandardised block
    vectors; (pipelines, vectors, image shape, block grid). Days must share one view."""
    params, change_window = opt.params, opt.change_window
    pipelines: list[Pipeline] = []
    vectors: list[np.ndarray] = []
    shape: tuple[int, ...] | None = None
    grid: tuple[int, ...] | None = None
    for t in range(len(stacks)):
        name = f"day {t + 1} harmonics"
        with timed(steps.timings, name):
            try:
                pipe = Pipeline(np.asarray(stacks[t]), angle_list[t], params, mask=mask_list[t])
                coef = pipe.get("harmonics")
                # polarisation statistics are standardised over all days below, not per day
                vectors.append(pipe.block_vectors(standardise=False))
            except PolarsegError as exc:
                raise PolarsegError(f"day {t + 1}: {exc}") from None
            day_shape = tuple(pipe.stack.shape[1:])
            if shape is None:
                shape, grid = day_shape, tuple(coef.shape[:2])
                if change_window > min(day_shape):
                    raise PolarsegError(
                        f"change_window {change_window} is larger than the image "
                        f"({day_shape[0]} x {day_shape[1]} pixels)"
                    )
            elif day_shape != shape:
                raise PolarsegError(
                    f"day {t + 1} is {day_shape[0]} x {day_shape[1]} pixels but day 1 is "
                    f"{shape[0]} x {shape[1]}: a time series needs the same view every day"
                )
            pipelines.append(pipe)
        steps.done(name)
    assert shape is not None and grid is not None
    return pipelines, vectors, shape, grid


def _block_graph(
    scores: np.ndarray, grid: tuple[int, ...], n_days: int, params: SegmentParams, method: str
) -> tuple[np.ndarray, int]:
    """The dense affinity the cut runs on (:func:`~..graph.affinity.affinity_matrix`,
    times the spatial kernel tiled over the days) and the minimum segment size.

    ``"joint"``: every day's blocks in one graph; else day 1's blocks only.
    """
    n_blocks = int(np.prod(grid))
    if method == "joint":
        if scores.shape[0] > MAX_DENSE_BLOCKS:
            raise PolarsegError(
                f"{n_days} days of {n_blocks} blocks is too many for the joint affinity "
                f"(limit {MAX_DENSE_BLOCKS} blocks in all); use a larger window or "
                "method='tracked'"
            )
        graph_feats, min_size = scores, params.min_segment_blocks * n_days
    else:
        graph_feats, min_size = scores[:n_blocks], params.min_segment_blocks
    W = affinity.affinity_matrix(graph_feats, params.scale, params.scale_mode)
    if params.spatial_radius > 0:
        kernel = affinity.spatial_kernel(grid, params.spatial_radius, params.spatial_sigma)
        reps = W.shape[0] // n_blocks
        W *= np.tile(kernel, (reps, reps))  # the same position on any day is a neighbour
    return W, min_size


def _cut_tree(W: np.ndarray, min_size: int, params: SegmentParams) -> Any:
    """The cut of the pipeline's clustering: k-way spectral or the recursive Ncut tree."""
    if params.clustering == "kway":
        return spectral.SpectralClustering(W, min_size=min_size)
    return ncut.CutTree(W, min_size=min_size, threshold=params.ncut_threshold)


def _change_maps(
    segs: DaySegments, change_stats: list[ChangeStatistics], shape: tuple[int, ...], opt: _Options
) -> dict[str, np.ndarray]:
    """What changed between consecutive days: labels, blocks, scores and distances as maps."""
    method, window, change_window = opt.method, opt.params.window, opt.change_window
    labels, n_pairs = segs.labels, segs.labels.shape[0] - 1
    block_changes = segs.block_labels[1:] != segs.block_labels[:-1]
    if method == "tracked":
        # a block whose minority pixels moved also changed
        block_changes = np.stack(
            [_block_any(labels[t + 1] != labels[t], segs.label_window) for t in range(n_pairs)]
        )
    block_score = np.stack([s.score for s in change_stats])
    pixel_score = np.stack(
        [harmonics.upsample_block_labels(s, shape, change_window) for s in block_score]
    ).astype(np.float32)
    pixel_distance = np.stack(
        [harmonics.upsample_block_labels(d, shape, window) for d in segs.distance]
    ).astype(np.float32)
    return {
        "changes": labels[1:] != labels[:-1],
        "block_changes": block_changes,
        "change_score": pixel_score,
        "block_change_score": block_score,
        "feature_distance": pixel_distance,
    }


def _block_any(mask: np.ndarray, window: int) -> np.ndarray:
    """True for every block (rows, cols) with at least one True pixel."""
    rows, cols = harmonics.pixel_block_index(mask.shape, window)
    grid = harmonics.block_grid(mask.shape, window)
    block = (rows[:, None] * grid[1] + cols[None, :]).ravel()
    hits = np.bincount(block, weights=mask.ravel().astype(float), minlength=grid[0] * grid[1])
    return (hits > 0).reshape(grid)
