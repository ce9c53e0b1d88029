"""Direct polarisation statistics of w × w blocks: an alternative to harmonic features.

The thesis describes a block by the spherical-harmonic coefficients of Î over (θ, φ)
(eq. 4.21). Those coefficients mix the material (how ρ and Î vary with the zenith) with
the block's geometry (which zenith and azimuth it happens to cover). This module gives
the block features issue 6 asks for as "direct polarisation statistics (block
distributions of ρ, θ and their relation to Î)", computed from the polarisation image
and the Fresnel zenith without any harmonic fit:

=====================  ==================================================================
feature                meaning (per block, over its usable pixels)
=====================  ==================================================================
``log_stokes_dop``     log of the block's Stokes-averaged degree of polarisation
                       ``|Σ Î ρ e^{2iφ}| / Σ Î`` — the ρ of the block as one measurement
                       (no upward noise bias of per-pixel ρ; lowered by rough or curved
                       surfaces whose φ spreads)
``log_median_dop``     log of the median per-pixel ρ
``dop_spread``         interquartile range of ρ divided by its median (relative spread)
``phase_coherence``    ``|mean e^{2iφ}|`` — 1 when φ is the same across the block (smooth
                       flat facet), lower for rough or strongly curved surfaces
``zenith_mean``        mean Fresnel zenith θ, radians (thesis eq. 3.13 inverted)
``zenith_std``         its standard deviation, radians
``log_intensity``      log of the mean Î (fraction of full scale)
``intensity_cv``       coefficient of variation of Î (texture and shading)
``corr_intensity_dop`` Pearson correlation of Î and ρ over the block: shading and
                       polarisation are both driven by the tilt, and how they co-vary
                       depends on the material
=====================  ==================================================================

Logarithms make ratios (a material that polarises 30 % less at every tilt) into
offsets; every feature is standardised (z-score over the blocks, :func:`standardise`)
before the PCA so that no unit dominates the variance. Angles are radians inside.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import PolarsegError
from .harmonics import block_grid, blockify

#: Names of the columns :func:`block_polarisation_statistics` returns, in order.
STAT_NAMES: tuple[str, ...] = (
    "log_stokes_dop",
    "log_median_dop",
    "dop_spread",
    "phase_coherence",
    "zenith_mean",
    "zenith_std",
    "log_intensity",
    "intensity_cv",
    "corr_intensity_dop",
)

#: Floor of ρ and Î inside logarithms and ratios (below the 16-bit quantisation step).
_FLOOR = 1e-5


def _blocks(a: np.ndarray, window: int) -> np.ndarray:
    """(rows·cols, w²) pixels of the whole blocks of a 2-D array (remainder strips dropped)."""
    b = blockify(np.asarray(a), window)
    return b.reshape(-1, b.shape[-1])


def block_polarisation_statistics(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    zenith: np.ndarray,
    window: int,
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """Polarisation statistics of every whole w × w block (module docstring's table).

    Parameters
    ----------
    intensity, dop, phase : ndarray (H, W)
        Polarisation image (thesis eq. 3.14): Î (any positive unit), ρ (dimensionless),
        φ (radians).
    zenith : ndarray (H, W)
        Zenith θ from ρ (radians; thesis eq. 3.13 inverted).
    window : int
        Block side w in pixels.
    valid : ndarray (H, W) of bool, optional
        Pixels to use (default: every pixel). A block without usable pixels gets the
        mean of the other blocks (the pipeline leaves such blocks out of the graph).

    Returns
    -------
    ndarray (rows, cols, len(STAT_NAMES))
        Raw (not standardised) statistics, float64.
    """
    shape = np.shape(intensity)
    if len(shape) != 2 or any(np.shape(a) != shape for a in (dop, phase, zenith)):
        raise PolarsegError("intensity, dop, phase and zenith must be 2-D and the same shape")
    grid = block_grid(shape, window)
    use = np.ones(shape, bool) if valid is None else np.asarray(valid, bool)
    if use.shape != shape:
        raise PolarsegError(f"valid mask shape {use.shape} does not match the image {shape}")
    ok = _blocks(use, window) & np.isfinite(_blocks(intensity, window))
    ok &= np.isfinite(_blocks(dop, window)) & np.isfinite(_blocks(zenith, window))

    def take(a: np.ndarray) -> np.ndarray:
        return np.where(ok, _blocks(np.asarray(a, float), window), np.nan)

    i, r, p, t = take(intensity), take(dop), take(phase), take(zenith)
    count = ok.sum(axis=1)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        # blocks without usable pixels give all-NaN slices; they are filled in below
        warnings.simplefilter("ignore", RuntimeWarning)
        e2 = np.exp(2j * np.nan_to_num(p)) * ok
        i0 = np.nan_to_num(i)
        stokes_dop = np.abs((i0 * np.nan_to_num(r) * e2).sum(1)) / np.maximum(i0.sum(1), _FLOOR)
        coherence = np.abs(e2.sum(1)) / np.maximum(count, 1)
        q25, q50, q75 = np.nanquantile(r, (0.25, 0.5, 0.75), axis=1)
        spread = (q75 - q25) / np.maximum(q50, _FLOOR)
        i_mean, i_std = np.nanmean(i, 1), np.nanstd(i, 1)
        r_mean, r_std = np.nanmean(r, 1), np.nanstd(r, 1)
        cov = np.nanmean((i - i_mean[:, None]) * (r - r_mean[:, None]), 1)
        corr = np.where((i_std > 0) & (r_std > 0), cov / (i_std * r_std), 0.0)
        stats = np.stack(
            [
                np.log(np.maximum(stokes_dop, _FLOOR)),
                np.log(np.maximum(q50, _FLOOR)),
                spread,
                coherence,
                np.nanmean(t, 1),
                np.nanstd(t, 1),
                np.log(np.maximum(i_mean, _FLOOR)),
                i_std / np.maximum(i_mean, _FLOOR),
                corr,
            ],
            axis=1,
        )
    empty = count == 0
    if empty.all():
        raise PolarsegError("no block has a usable pixel")
    if empty.any():
        stats[empty] = np.nanmean(stats[~empty], axis=0)
    stats = np.where(np.isfinite(stats), stats, 0.0)
    return stats.reshape(grid + (len(STAT_NAMES),))


def standardise(vectors: np.ndarray) -> np.ndarray:
    """Z-score every column over the blocks (columns without variance become 0).

    Harmonic coefficients share one unit, so the thesis's PCA works on them directly;
    the statistics here have different units (log ratios, radians, correlations), and
    without this the PCA's variance share would be decided by the units.
    """
    x = np.asarray(vectors, dtype=float)
    sd = x.std(axis=0)
    return np.where(sd > 0, (x - x.mean(axis=0)) / np.where(sd > 0, sd, 1.0), 0.0)
