"""The change test between two days of the same view (module docstring of :mod:`.timeseries`,
"The change test"): per change block, the Stokes means of the two days compared against
their noise, as a score (normal deviate) and a significance at a false-alarm rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from ..errors import PolarsegError
from ..features import harmonics

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


def _both_valid(before: Any, after: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Pixels valid on both days (an image without ``invalid`` counts as all valid)."""
    valid = np.ones(shape, dtype=bool)
    for img in (before, after):
        if getattr(img, "invalid", None) is not None:
            valid &= ~np.asarray(img.invalid, dtype=bool)
    return valid


def _hotelling_scores(
    m: np.ndarray, c: np.ndarray, n: np.ndarray, tested: np.ndarray, false_alarm: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Hotelling's T² of the block mean changes ``m`` (B, p) with covariances ``c`` over
    ``n`` pixels, calibrated by the noise inflation: (score, p-value, inflation)."""
    p = m.shape[1]
    ridge = 1e-12 * np.einsum("bkk->b", c) / p + 1e-300
    c = c + ridge[:, None, None] * np.eye(p)
    t2 = n * np.einsum("bk,bk->b", m, np.linalg.solve(c, m[..., None])[..., 0])
    f = np.where(tested, t2 * (n - p) / (p * np.maximum(n - 1.0, 1.0)), 0.0)
    pv = stats.f.sf(f, p, np.maximum(n - p, 1.0))
    x = stats.chi2.isf(np.clip(pv, 1e-300, 1.0), p)  # the same evidence as a χ²(p)
    lam = _noise_inflation(x[tested], p, false_alarm) if tested.any() else 1.0
    pv = np.where(tested, stats.chi2.sf(x / lam, p), 1.0)
    score = np.clip(stats.norm.isf(np.clip(pv, 1e-300, 1.0)), 0.0, MAX_SCORE)
    return score, pv, lam


def _block_differences(
    dlog: np.ndarray,
    before: tuple[np.ndarray, np.ndarray],
    after: tuple[np.ndarray, np.ndarray],
    valid: np.ndarray,
    window: int,
) -> tuple[np.ndarray, ...]:
    """Per change block: (pixels n, tested, log gain, mean change (B, 3), its covariance
    (B, 3, 3), t values (B, 3)) of log Î (less the global gain) and of the Stokes change
    along / across the block's mean polarisation direction."""
    grid = harmonics.block_grid(dlog.shape, window)
    (qa, ua), (qb, ub) = before, after
    blocks = lambda a: harmonics.blockify(a, window).reshape(grid[0] * grid[1], -1)  # noqa: E731
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
    return n, tested, gain, mean, cov, t


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
        valid = _both_valid(before, after, ia.shape)
    valid = np.asarray(valid, dtype=bool) & (ia > 0) & (ib > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        dlog = np.where(valid, np.log(np.where(valid, ib, 1.0) / np.where(valid, ia, 1.0)), 0.0)
    qa, ua = _stokes(before, valid)
    qb, ub = _stokes(after, valid)
    n, tested, gain, mean, cov, t = _block_differences(dlog, (qa, ua), (qb, ub), valid, window)

    comps = CHANGE_SOURCES[change_from]
    tested &= n > len(comps) + 1
    score, pv, lam = _hotelling_scores(
        mean[:, comps], cov[:, comps][:, :, comps], n, tested, false_alarm
    )
    return ChangeStatistics(
        score=score.reshape(grid),
        pvalue=pv.reshape(grid),
        significant=(tested & (pv < false_alarm)).reshape(grid),
        mean=mean.reshape(*grid, 3),
        t=t.reshape(*grid, 3),
        n_pixels=n.astype(np.int64).reshape(grid),
        window=window,
        components=comps,
        gain=float(np.exp(gain)),
        inflation=float(lam),
        false_alarm=float(false_alarm),
        threshold=float(stats.norm.isf(false_alarm)),
    )
