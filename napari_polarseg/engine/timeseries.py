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
2. **Segments**, by ``method``:

   - ``"tracked"`` (default): day 1 is cut alone (the usual affinity and cut on its
     blocks, in the shared basis); each later day starts as a copy of the day before
     and only the change blocks flagged by the test move, to the segment of the
     material they changed into (:func:`track_labels`): a changed segment is a kind of
     change, described by the signs of the components significant over its blocks
     (the fruit's bruise: Î down, ρ down); a flagged block joins the changed segment
     whose signs it does not contradict, stays in it when its change goes on the same
     way, goes back to its former segment when it undoes the change, or starts a new
     changed segment. Unchanged blocks keep their segment by construction.
   - ``"reference"``: day 1 is cut alone; every block of every day, day 1 included,
     takes the segment whose mean (over day 1) is nearest in the shared whitened basis.
   - ``"joint"``: one affinity over the blocks of all days and one cut of that graph
     (a material that day 1 does not show can get a segment of its own; the dense
     affinity over T × the blocks of one day is limited to
     :data:`~.pipeline.MAX_DENSE_BLOCKS`);

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

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from . import features as feat
from . import harmonics, ncut, polstats
from .errors import Cancelled, PolarsegError
from .params import SegmentParams
from .pipeline import Pipeline
from .stages import MAX_DENSE_BLOCKS, POLSTATS_KINDS

#: Ways to segment the days (see the module docstring); the first is the default.
METHODS = ("tracked", "reference", "joint")
#: Per-pixel change between two days: log Î (after the global gain), and the change of
#: the normalised Stokes vector ρ·e^{2iφ} along and across the block's mean direction.
CHANGE_COMPONENTS = ("log_intensity", "dop_parallel", "dop_perpendicular")
#: Which components the change test uses (``change_from``).
CHANGE_SOURCES = {"all": (0, 1, 2), "polarisation": (1, 2), "intensity": (0,)}
#: Default probability that an unchanged change block is flagged (per block and pair).
DEFAULT_FALSE_ALARM = 1e-3
#: Fewest usable pixels for a change block to be tested.
MIN_CHANGE_PIXELS = 8
#: Fewest tested blocks to estimate the noise inflation from (else it stays 1).
MIN_CALIBRATION_BLOCKS = 10
#: Largest reported change score (the normal deviate of a p-value of ~1e-300).
MAX_SCORE = 37.0


def default_change_window(window: int) -> int:
    """Side of the change blocks for segmentation blocks of side ``window``: half the
    window, but at least 6 pixels (36 pixels per block test) and at most the window.

    Smaller change blocks follow a changed region's outline more closely (fewer
    unchanged pixels in a block that moves); larger ones detect weaker changes. 6 px
    for w = 8 to 12 (module docstring for the figures).
    """
    return min(int(window), max(6, int(window) // 2))


@dataclass
class ChangeStatistics:
    """Per-block test of whether the polarisation image changed between two days.

    Arrays are over the blocks of side ``window`` (rows, cols); remainder strips belong to
    their nearest block (:func:`~.harmonics.pixel_block_index`) but take no part in the
    test.

    Attributes
    ----------
    score : ndarray float
        Change score: the one-sided normal deviate of the block's p-value (0 = no evidence
        of change, 3.09 = p 0.001; capped at :data:`MAX_SCORE`). Untested blocks get 0.
    pvalue : ndarray float
        Probability of a change at least this large from the noise alone (after the
        noise inflation).
    significant : ndarray bool
        ``pvalue < false_alarm``.
    mean : ndarray (rows, cols, 3)
        Mean change per :data:`CHANGE_COMPONENTS` (log Î after the gain; ρ along and
        across the block's polarisation direction).
    t : ndarray (rows, cols, 3)
        Each mean divided by its standard error (from the block's own pixel scatter).
    n_pixels : ndarray int
        Usable pixels of each block (both days).
    window : int
    components : tuple of int
        Indices into :data:`CHANGE_COMPONENTS` the test used.
    gain : float
        Intensity ratio (after / before) of the whole image, divided out before the test.
    inflation : float
        Noise inflation λ >= 1 by which the χ² statistics were divided (1 = the pixel
        noise is as independent as the test assumes).
    false_alarm : float
    threshold : float
        Score above which a block is significant, ``Φ⁻¹(1 − false_alarm)``.
    """

    score: np.ndarray
    pvalue: np.ndarray
    significant: np.ndarray
    mean: np.ndarray
    t: np.ndarray
    n_pixels: np.ndarray
    window: int
    components: tuple[int, ...]
    gain: float
    inflation: float
    false_alarm: float
    threshold: float


def _stokes(image: Any, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised Stokes components ρ cos 2φ, ρ sin 2φ (0 outside ``valid``)."""
    rho = np.where(valid, np.asarray(image.dop, dtype=float), 0.0)
    two_phi = 2.0 * np.where(valid, np.asarray(image.phase, dtype=float), 0.0)
    return rho * np.cos(two_phi), rho * np.sin(two_phi)


def _robust_gain(block_mean: np.ndarray, block_var: np.ndarray) -> float:
    """Common offset of the block means of log Î: the median, then the precision-
    weighted mean of the blocks within 3 standard errors of it (repeated), so that the
    blocks that really changed do not pull the estimate."""
    if block_mean.size == 0:
        return 0.0
    g = float(np.median(block_mean))
    weight = 1.0 / (block_var + 1e-300)
    for _ in range(20):
        keep = (block_mean - g) ** 2 <= 9.0 * block_var
        if not keep.any():
            break
        new = float(np.sum(block_mean[keep] * weight[keep]) / np.sum(weight[keep]))
        if abs(new - g) <= 1e-15:
            break
        g = new
    return g


def _noise_inflation(x: np.ndarray, dof: int, false_alarm: float) -> float:
    """λ >= 1 such that the χ² statistics of the blocks not flagged look like the
    truncated χ²(dof) of no change: the median of ``x`` below ``λ·t`` over the median of
    χ² truncated at ``t`` (``t`` the threshold), iterated to its fixed point. Spatially
    correlated noise (e.g. interpolated demosaicing) makes the block means vary more
    than their pixel scatter predicts; λ measures that. Changed blocks beyond the
    threshold are left out, so they do not inflate it."""
    t = stats.chi2.isf(false_alarm, dof)
    m0 = stats.chi2.ppf(stats.chi2.cdf(t, dof) / 2.0, dof)
    lam = 1.0
    for _ in range(50):
        keep = x < lam * t
        if np.count_nonzero(keep) < MIN_CALIBRATION_BLOCKS:
            break
        new = max(1.0, float(np.median(x[keep])) / m0)
        if abs(new - lam) < 1e-9:
            break
        lam = new
    return lam


def change_statistics(
    before: Any,
    after: Any,
    window: int,
    *,
    valid: np.ndarray | None = None,
    false_alarm: float = DEFAULT_FALSE_ALARM,
    change_from: str = "all",
) -> ChangeStatistics:
    """Test every w × w block for a change of the polarisation image between two days.

    The view is the same on both days, so every pixel sees the same surface geometry:
    the per-pixel differences of log Î and of the normalised Stokes vector ρ·e^{2iφ}
    cancel the tilt that dominates Î and ρ and keep the change of material (and the
    noise). Per block, Hotelling's T² tests whether the mean of these differences is
    zero against their scatter over the block's pixels (paired, multivariate: the
    F(p, n − p) law under independent Gaussian pixel noise), with the scatter estimated
    from the block itself. The image-wide intensity gain (illumination, exposure) is
    removed first, and a noise inflation λ (:func:`_noise_inflation`) keeps the false-
    alarm rate when the pixel noise is spatially correlated.

    Parameters
    ----------
    before, after : PolarisationImage (or anything with ``intensity``, ``dop``, ``phase``
        and optionally ``invalid``)
        The two days, same shape.
    window : int
        Side of the change blocks in pixels.
    valid : ndarray (H, W) bool, optional
        Pixels to use (default: those valid on both days).
    false_alarm : float
        Probability in (0, 1) that a block without change is flagged.
    change_from : {"all", "polarisation", "intensity"}
        Components of the test (:data:`CHANGE_SOURCES`): ``"polarisation"`` ignores Î
        (use it when the lighting differs between days beyond a global gain).

    Returns
    -------
    ChangeStatistics
    """
    if change_from not in CHANGE_SOURCES:
        raise PolarsegError(
            f"change_from must be one of {', '.join(CHANGE_SOURCES)}; got {change_from!r}"
        )
    if not 0.0 < false_alarm < 1.0:
        raise PolarsegError(f"false_alarm must be in (0, 1), got {false_alarm!r}")
    ia = np.asarray(before.intensity, dtype=float)
    ib = np.asarray(after.intensity, dtype=float)
    if ia.shape != ib.shape or ia.ndim != 2:
        raise PolarsegError(f"polarisation images of {ia.shape} and {ib.shape} cannot be compared")
    window = int(window)
    grid = harmonics.block_grid(ia.shape, window)
    if valid is None:
        valid = np.ones(ia.shape, dtype=bool)
        for img in (before, after):
            if getattr(img, "invalid", None) is not None:
                valid &= ~np.asarray(img.invalid, dtype=bool)
    valid = np.asarray(valid, dtype=bool) & (ia > 0) & (ib > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        dlog = np.where(valid, np.log(np.where(valid, ib, 1.0) / np.where(valid, ia, 1.0)), 0.0)
    qa, ua = _stokes(before, valid)
    qb, ub = _stokes(after, valid)
    blocks = lambda a: harmonics._blockify(a, window).reshape(grid[0] * grid[1], -1)  # noqa: E731
    v = blocks(valid.astype(float))
    n = v.sum(axis=1)
    tested = n >= MIN_CHANGE_PIXELS
    n_safe = np.maximum(n, 2.0)

    # global gain from the blocks' mean log Î change
    dl = blocks(dlog)
    ml = (dl * v).sum(axis=1) / n_safe
    var_l = (((dl - ml[:, None]) * v) ** 2).sum(axis=1) / (n_safe - 1.0) / n_safe
    gain = _robust_gain(ml[tested], var_l[tested])

    # the polarisation change along / across the block's mean direction (both days)
    psi = np.arctan2(blocks(ua + ub).sum(axis=1), blocks(qa + qb).sum(axis=1))[:, None]
    dq, du = blocks(qb - qa), blocks(ub - ua)
    par = dq * np.cos(psi) + du * np.sin(psi)
    perp = du * np.cos(psi) - dq * np.sin(psi)
    d = np.stack([(dl - gain) * v, par, perp], axis=-1)  # (B, n, 3), 0 where unusable
    mean = d.sum(axis=1) / n_safe[:, None]
    resid = (d - mean[:, None, :]) * v[..., None]
    cov = np.einsum("bik,bil->bkl", resid, resid) / (n_safe - 1.0)[:, None, None]
    se = np.sqrt(np.einsum("bkk->bk", cov) / n_safe[:, None])
    t = np.divide(mean, se, out=np.zeros_like(mean), where=se > 0)

    comps = CHANGE_SOURCES[change_from]
    p = len(comps)
    tested &= n > p + 1
    m = mean[:, comps]
    c = cov[:, comps][:, :, comps]
    ridge = 1e-12 * np.einsum("bkk->b", c) / p + 1e-300
    c = c + ridge[:, None, None] * np.eye(p)
    t2 = n * np.einsum("bk,bk->b", m, np.linalg.solve(c, m[..., None])[..., 0])
    f = np.where(tested, t2 * (n - p) / (p * np.maximum(n - 1.0, 1.0)), 0.0)
    pv = stats.f.sf(f, p, np.maximum(n - p, 1.0))
    x = stats.chi2.isf(np.clip(pv, 1e-300, 1.0), p)  # the same evidence as a χ²(p)
    lam = _noise_inflation(x[tested], p, false_alarm) if tested.any() else 1.0
    pv = np.where(tested, stats.chi2.sf(x / lam, p), 1.0)
    score = np.clip(stats.norm.isf(np.clip(pv, 1e-300, 1.0)), 0.0, MAX_SCORE)
    shape = grid
    return ChangeStatistics(
        score=score.reshape(shape),
        pvalue=pv.reshape(shape),
        significant=(tested & (pv < false_alarm)).reshape(shape),
        mean=mean.reshape(*shape, 3),
        t=t.reshape(*shape, 3),
        n_pixels=n.astype(np.int64).reshape(shape),
        window=window,
        components=comps,
        gain=float(np.exp(gain)),
        inflation=float(lam),
        false_alarm=float(false_alarm),
        threshold=float(stats.norm.isf(false_alarm)),
    )


@dataclass
class TimeSeriesResult:
    """Segments of several days of one view, consistent over time, and their changes.

    Attributes
    ----------
    params : SegmentParams
        Parameters used for every day.
    method : {"tracked", "reference", "joint"}
        How the blocks were segmented (module docstring).
    labels : ndarray (T, H, W) int32
        Segment of every pixel on each day; segment k means the same material on every
        day (0 = first segment; for ``tracked``, 0 … ``n_base_segments`` − 1 are day 1's
        segments and the later ones the materials blocks changed into).
    block_labels : ndarray (T, rows, cols) int32
        Segment of every block of the label grid (side ``label_window``: the w × w
        segmentation blocks for ``reference`` and ``joint``, the change blocks for
        ``tracked``; the majority of the block's pixels).
    changes : ndarray (T − 1, H, W) bool
        ``changes[t]``: the pixel is in another segment on day t + 1 than on day t (the
        change map; block-shaped).
    block_changes : ndarray (T − 1, rows, cols) bool
        The same per block of the label grid.
    change_score : ndarray (T − 1, H, W) float32
        Graded change map: the change score of the pixel's change block
        (:class:`ChangeStatistics`; 3.09 = the evidence of a p-value of 0.001 that the
        polarisation image changed), whatever the segments did.
    block_change_score : ndarray (T − 1, rows_c, cols_c)
        The same per change block (side ``change_window``).
    change_significant : ndarray (T − 1, rows_c, cols_c) bool
        Change blocks whose change is significant at ``false_alarm``; for ``tracked``
        these are the blocks that moved to a changed segment (or stayed in one).
    change_statistics : list of ChangeStatistics
        The full test of each pair of consecutive days.
    feature_distance : ndarray (T − 1, H, W) float32
        Mahalanobis distance (covariance of all days' blocks) between the shared-basis
        features of the pixel's segmentation block on day t and on day t + 1 (the older,
        weaker graded measure, kept for comparison).
    block_feature_distance : ndarray (T − 1, rows_w, cols_w)
        The same per segmentation block.
    features : ndarray (T, n_blocks, n_components)
        Block features of every day in the shared PCA basis.
    explained_variance_ratio : ndarray (n_components,)
        Share of the variance (over all days' blocks) each kept component explains.
    components : ndarray (n_components, n_features)
        The shared principal axes.
    segment_means : ndarray (K, n_components)
        Mean feature vector of each segment (``joint``: over all days' blocks;
        ``reference``: over day 1's; ``tracked``: over the pixels of all days, each with
        its segmentation block's features).
    ncut_values : list of float
        Ncut value of each split.
    n_base_segments : int
        Segments of the cut (day 1 for ``tracked`` and ``reference``).
    changed_segments : list of dict
        ``tracked`` only: for every segment after the base ones, the day it first
        appears, its change blocks and their mean change (:data:`CHANGE_COMPONENTS`).
    label_window, change_window : int
        Sides of the label-grid and change blocks.
    false_alarm : float
        Per-block false-alarm probability of the change test.
    change_from : {"all", "polarisation", "intensity"}
        What the change test compared (:func:`change_statistics`).
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
    change_score: np.ndarray
    block_change_score: np.ndarray
    change_significant: np.ndarray
    change_statistics: list[ChangeStatistics]
    feature_distance: np.ndarray
    block_feature_distance: np.ndarray
    features: np.ndarray
    explained_variance_ratio: np.ndarray
    components: np.ndarray
    segment_means: np.ndarray
    ncut_values: list[float]
    n_base_segments: int
    changed_segments: list[dict[str, Any]]
    label_window: int
    change_window: int
    false_alarm: float
    change_from: str
    pipelines: list[Pipeline] = field(default_factory=list, repr=False)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def n_days(self) -> int:
        return int(self.labels.shape[0])

    @property
    def n_segments(self) -> int:
        return int(self.labels.max()) + 1

    def changed_fraction(self) -> np.ndarray:
        """Share of the pixels that changed segment between each pair of consecutive days."""
        if self.changes.shape[0] == 0:
            return np.zeros(0)
        return self.changes.reshape(self.changes.shape[0], -1).mean(axis=1)

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures: segments per day, changes per pair of days, PCA, timings."""
        k = self.n_segments
        return {
            "method": self.method,
            "n_days": self.n_days,
            "n_segments": k,
            "n_base_segments": self.n_base_segments,
            "changed_segments": [dict(s) for s in self.changed_segments],
            "segment_pixels": [
                np.bincount(day.ravel(), minlength=k).tolist() for day in self.labels
            ],
            "label_window": self.label_window,
            "block_grid": list(self.block_labels.shape[1:]),
            "changed_blocks": [int(c.sum()) for c in self.block_changes],
            "changed_pixels": [int(c.sum()) for c in self.changes],
            "changed_pixel_fraction": [float(v) for v in self.changed_fraction()],
            "change_window": self.change_window,
            "change_grid": list(self.block_change_score.shape[1:]),
            "false_alarm": self.false_alarm,
            "change_from": self.change_from,
            "score_threshold": float(stats.norm.isf(self.false_alarm)),
            "significant_change_blocks": [int(s.sum()) for s in self.change_significant],
            "max_change_score": [float(s.max(initial=0.0)) for s in self.block_change_score],
            "intensity_gain": [s.gain for s in self.change_statistics],
            "noise_inflation": [s.inflation for s in self.change_statistics],
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


def _block_slices(shape: tuple[int, int], window: int) -> tuple[list[slice], list[slice]]:
    """Pixel rows and columns of every block row and column (remainder strips included)."""
    rows, cols = harmonics.pixel_block_index(shape, window)

    def spans(index: np.ndarray) -> list[slice]:
        edges = np.flatnonzero(np.diff(index)) + 1
        starts = np.concatenate([[0], edges])
        stops = np.concatenate([edges, [index.size]])
        return [slice(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]

    return spans(rows), spans(cols)


def _block_majority(labels: np.ndarray, window: int) -> np.ndarray:
    """Most frequent label of every block (rows, cols), remainder strips included."""
    shape = labels.shape
    rows, cols = harmonics.pixel_block_index(shape, window)
    grid = harmonics.block_grid(shape, window)
    block = (rows[:, None] * grid[1] + cols[None, :]).ravel()
    k = int(labels.max()) + 1
    counts = np.bincount(block * k + labels.ravel(), minlength=grid[0] * grid[1] * k)
    return counts.reshape(grid[0] * grid[1], k).argmax(axis=1).reshape(grid).astype(np.int32)


def _signs(t: np.ndarray, threshold: float) -> np.ndarray:
    """Sign of every component whose |t| exceeds ``threshold`` (else 0)."""
    return np.where(np.abs(t) > threshold, np.sign(t), 0.0)


@dataclass
class _ChangedSegment:
    """A material blocks changed into: the sum of its blocks' t-vectors and mean changes."""

    t_sum: np.ndarray
    change_sum: np.ndarray
    blocks: int = 0
    first_day: int = 0

    def signs(self, threshold: float) -> np.ndarray:
        # the combined evidence of the members: Σt / √n is a t-value again
        return _signs(self.t_sum / np.sqrt(max(self.blocks, 1)), threshold)


def track_labels(
    base: np.ndarray, statistics: Sequence[ChangeStatistics]
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Carry day 1's labels through the days, moving only the blocks that changed.

    Day t + 1 starts as day t. Every change block flagged by ``statistics[t]`` (in order
    of decreasing score) moves to the segment of the material it changed into. A change
    is described by the signs of its tested components (:data:`CHANGE_COMPONENTS`: Î,
    ρ along and across the polarisation direction) that are significant on their own
    (|t| above the score threshold); a changed segment by the signs significant over
    all its blocks together (Σt / √n). A block is *compatible* with a changed segment
    when no sign of one contradicts a sign of the other:

    - a block in a changed segment whose significant signs all contradict that segment's
      goes back to the segment its pixels had before (the change was undone);
    - else it joins the compatible changed segment that shares the most signs with it
      (ties: the closest mean direction); a block already there stays, its change went
      on the same way;
    - else it starts a new changed segment, numbered after all existing ones.

    Blocks not flagged keep their segment. The sign rule groups the blocks of one
    material change although which component carries the evidence depends on the tilt
    (the intensity change dominates where ρ is small, the ρ change at grazing tilt).

    Returns the labels (T, H, W) and one dict per changed segment: ``segment``,
    ``first_day`` (1-based), ``blocks`` (change blocks that joined it) and
    ``mean_change`` (their mean change per component).
    """
    base = np.asarray(base, dtype=np.int32)
    k0 = int(base.max()) + 1
    labels = [base]
    origin = base.copy()  # the segment each pixel had before its latest move
    segments: list[_ChangedSegment] = []
    for day, st in enumerate(statistics):
        lab = labels[-1].copy()
        rows, cols = _block_slices(lab.shape, st.window)
        tvec = st.t[..., list(st.components)]
        flagged = np.argwhere(st.significant)
        order = np.argsort(-st.score[st.significant], kind="stable")
        for r, c in flagged[order]:
            sl = (rows[r], cols[c])
            t = tvec[r, c]
            own = _signs(t, st.threshold)
            cur = lab[sl]
            values, counts = np.unique(cur, return_counts=True)
            major = int(values[np.argmax(counts)])
            if major >= k0:
                theirs = segments[major - k0].signs(st.threshold)
                both = (own != 0) & (theirs != 0)
                if both.any() and np.all(own[both] != theirs[both]):
                    back = cur == major
                    cur[back] = origin[sl][back]
                    origin[sl][back] = cur[back]
                    continue
            best, best_key = -1, (-1, -2.0)
            for j, seg in enumerate(segments):
                theirs = seg.signs(st.threshold)
                both = (own != 0) & (theirs != 0)
                if np.any(own[both] != theirs[both]):
                    continue
                cos = float(_unit(t) @ _unit(seg.t_sum))
                key = (int(both.sum()), cos)
                if key > best_key:
                    best, best_key = j, key
            if best < 0 or (best_key[0] == 0 and best_key[1] <= 0.0):
                best = len(segments)
                segments.append(
                    _ChangedSegment(np.zeros_like(t), np.zeros(len(CHANGE_COMPONENTS)), 0, day + 2)
                )
            seg = segments[best]
            seg.t_sum += t
            seg.change_sum += st.mean[r, c]
            seg.blocks += 1
            moved = cur != k0 + best
            origin[sl][moved] = cur[moved]
            cur[...] = k0 + best
        labels.append(lab)
    info = [
        {
            "segment": k0 + j,
            "first_day": seg.first_day,
            "blocks": seg.blocks,
            "mean_change": {
                name: float(v)
                for name, v in zip(CHANGE_COMPONENTS, seg.change_sum / seg.blocks, strict=True)
            },
        }
        for j, seg in enumerate(segments)
    ]
    return np.stack(labels).astype(np.int32), info


def _unit(v: np.ndarray) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


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
        Fewer than 2 days, days of different sizes, a bad method or change option, too
        many blocks for the dense joint affinity, or any error of the per-day pipeline
        (prefixed with the day).

    Examples
    --------
    >>> res = segment_timeseries([day1, day2], angles, RECOMMENDED)  # doctest: +SKIP
    >>> res.labels.shape, res.changes.shape, res.change_score.shape  # doctest: +SKIP
    ((2, 120, 130), (1, 120, 130), (1, 120, 130))
    """
    params = SegmentParams() if params is None else params
    if not isinstance(params, SegmentParams):
        raise PolarsegError("params must be a SegmentParams")
    if params.clustering == "superpixels":
        raise PolarsegError(
            "the time series cuts one block graph of all days; clustering must be "
            "recursive or kway, not superpixels"
        )
    if method not in METHODS:
        raise PolarsegError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
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
    change_window = int(change_window)
    stacks = list(stacks)
    n_days = len(stacks)
    if n_days < 2:
        raise PolarsegError(f"a time series needs at least 2 scenes, got {n_days}")
    angle_list = _as_list(angles, n_days)
    mask_list = [None] * n_days if masks is None else list(masks)
    if len(mask_list) != n_days:
        raise PolarsegError(f"{n_days} stacks but {len(mask_list)} masks")

    total = n_days + 5
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
        done(f"day {t + 1} harmonics", t0)
    assert shape is not None and grid is not None
    n_blocks = int(np.prod(grid))

    # 2. one PCA over the blocks of all days
    t0 = time.perf_counter()
    pooled = np.concatenate(vectors, axis=0)
    if params.features in POLSTATS_KINDS:
        pooled = polstats.standardise(pooled)  # one z-score over every day's blocks
    pca = feat.pca_features(pooled, params.variance)
    scores = pca.features
    done("shared pca", t0)

    # 3. the change test between consecutive days, from the polarisation images
    t0 = time.perf_counter()
    pols = [pipe.get("polarisation") for pipe in pipelines]
    change_stats = [
        change_statistics(
            pols[t], pols[t + 1], change_window, false_alarm=false_alarm, change_from=change_from
        )
        for t in range(n_days - 1)
    ]
    done("change test", t0)

    # 4. segments
    t0 = time.perf_counter()
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
    W = feat.affinity_matrix(graph_feats, params.scale, params.scale_mode)
    if params.spatial_radius > 0:
        kernel = feat.spatial_kernel(grid, params.spatial_radius, params.spatial_sigma)
        reps = W.shape[0] // n_blocks
        W *= np.tile(kernel, (reps, reps))  # the same position on any day is a neighbour
    done("affinity", t0)

    t0 = time.perf_counter()
    if params.clustering == "kway":
        from .spectral import SpectralClustering

        tree: Any = SpectralClustering(W, min_size=min_size)
    else:
        tree = ncut.CutTree(W, min_size=min_size, threshold=params.ncut_threshold)
    graph_labels = tree.labels(params.n_segments).astype(np.int32)
    k = int(graph_labels.max()) + 1
    # Mahalanobis distance under the covariance of all days' blocks = Euclidean on z
    z = feat.whiten(scores)
    changed_segments: list[dict[str, Any]] = []
    if method == "tracked":
        base = harmonics.upsample_block_labels(graph_labels.reshape(grid), shape, params.window)
        labels, changed_segments = track_labels(base, change_stats)
        segment_means = _pixel_segment_means(labels, scores, grid, params.window)
        label_window = change_window
        block_labels = np.stack([_block_majority(day, label_window) for day in labels])
    else:
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
        label_window = params.window
        block_labels = flat.reshape(n_days, *grid).astype(np.int32)
        labels = np.stack(
            [harmonics.upsample_block_labels(b, shape, params.window) for b in block_labels]
        ).astype(np.int32)
    zd = z.reshape(n_days, n_blocks, -1)
    distance = np.sqrt(((zd[1:] - zd[:-1]) ** 2).sum(-1)).reshape(n_days - 1, *grid)
    done("cut", t0)

    # 5. change maps
    t0 = time.perf_counter()
    block_changes = block_labels[1:] != block_labels[:-1]
    if method == "tracked":
        # a block whose minority pixels moved also changed
        block_changes = np.stack(
            [_block_any(labels[t + 1] != labels[t], label_window) for t in range(n_days - 1)]
        )
    changes = labels[1:] != labels[:-1]
    block_score = np.stack([s.score for s in change_stats])
    pixel_score = np.stack(
        [harmonics.upsample_block_labels(s, shape, change_window) for s in block_score]
    ).astype(np.float32)
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
        change_score=pixel_score,
        block_change_score=block_score,
        change_significant=np.stack([s.significant for s in change_stats]),
        change_statistics=change_stats,
        feature_distance=pixel_distance,
        block_feature_distance=distance,
        features=scores.reshape(n_days, n_blocks, -1),
        explained_variance_ratio=pca.explained_variance_ratio,
        components=pca.components,
        segment_means=segment_means,
        ncut_values=list(tree.ncut_values),
        n_base_segments=k,
        changed_segments=changed_segments,
        label_window=label_window,
        change_window=change_window,
        false_alarm=float(false_alarm),
        change_from=change_from,
        pipelines=pipelines,
        timings=timings,
    )


def _block_any(mask: np.ndarray, window: int) -> np.ndarray:
    """True for every block (rows, cols) with at least one True pixel."""
    rows, cols = harmonics.pixel_block_index(mask.shape, window)
    grid = harmonics.block_grid(mask.shape, window)
    block = (rows[:, None] * grid[1] + cols[None, :]).ravel()
    hits = np.bincount(block, weights=mask.ravel().astype(float), minlength=grid[0] * grid[1])
    return (hits > 0).reshape(grid)


def _segment_means(x: np.ndarray, labels: np.ndarray, k: int) -> np.ndarray:
    """Mean row of ``x`` per label 0..k−1 (vectorised with bincount-style sums)."""
    counts = np.bincount(labels, minlength=k).astype(float)
    sums = np.zeros((k, x.shape[1]))
    np.add.at(sums, labels, x)
    return sums / np.maximum(counts, 1.0)[:, None]


def _pixel_segment_means(
    labels: np.ndarray, scores: np.ndarray, grid: tuple[int, ...], window: int
) -> np.ndarray:
    """Mean feature per segment over the pixels of all days (each pixel with its
    segmentation block's features)."""
    n_days, h, w = labels.shape
    k = int(labels.max()) + 1
    n_blocks = int(np.prod(grid))
    rows, cols = harmonics.pixel_block_index((h, w), window)
    block = (rows[:, None] * grid[1] + cols[None, :]).ravel()
    x = scores.reshape(n_days, n_blocks, -1)
    sums = np.zeros((k, x.shape[-1]))
    counts = np.zeros(k)
    for t in range(n_days):
        m = np.bincount(labels[t].ravel() * n_blocks + block, minlength=k * n_blocks)
        m = m.reshape(k, n_blocks).astype(float)
        sums += m @ x[t]
        counts += m.sum(axis=1)
    return sums / np.maximum(counts, 1.0)[:, None]
