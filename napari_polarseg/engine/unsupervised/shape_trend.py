"""Polarisation against the trend of one smooth surface: the close-up material cue.

Diffuse polarisation (thesis eq. 3.13) at small zenith θ is ρ ≈ c θ², with c set by the
refractive index n and the depolarisation of the material, not by the tilt. Written
with the surface gradient g = p + i q (p = ∂z/∂x, q = ∂z/∂y, θ ≈ |g|, azimuth arg g),
the complex polarisation of a pixel is

    z = ρ e^{2iφ} = (S1 + i S2) / S0 ≈ c · g²,                               (1)

because φ is the azimuth of the normal (mod π). On one smooth curved surface (a fruit,
a leaf, a body part filling the frame) g is close to linear in the image position, so
z is close to a *complex quadratic* in (x, y) — and a patch of another material on it
(other n, more depolarising: a bruise) has the same g but a smaller or larger c. Its
polarisation then departs from the surface's trend by the ratio c'/c at any tilt,
where mean ρ alone follows the tilt (and ρ → 0 in the middle of the surface).

- :func:`surface_trend_share`: the share of the variance of the regions' z that the
  square of one linear field explains (weighted least squares over the regions, areas
  as weights). Close to 1 when one smooth surface fills the frame (0.90–0.93 on the
  rendered fruit close-ups), small or negative on scenes of many objects (the leaves,
  camouflage and the real frames of the benchmark, a reflecting pond).
- :func:`polarisation_over_trend`: the per-region departure
  Re(Σ z conj Q) / Σ |Q|², both sums Gaussian-weighted over the region centroids within
  ``reach`` of the frame side (a ratio of sums, not a mean of ratios: where Q → 0 in
  the middle of the surface a single ratio is noise). The trend is fitted again on the
  larger side of an Otsu split of that ratio (``iterations`` times), so a patch of
  another material does not pull the trend towards itself.

Written by hand: the trend is an ordinary weighted least-squares fit (``numpy.linalg``)
and the kernel smoothing over scattered region centroids has no direct scipy or
scikit-image counterpart (``ndimage`` filters work on grids).
"""

from __future__ import annotations

import numpy as np

from ..features.pixel_features import EPS_INTENSITY

#: Rows of region centroids per block of the kernel smoothing (memory: block × n floats).
KERNEL_BLOCK = 1024
#: Weight left to the smaller side of the Otsu split when the trend is fitted again.
OUTLIER_WEIGHT = 0.05


def region_polarisation(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    regions: np.ndarray,
    stokes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Complex polarisation z = ΣS1 + iΣS2 over ΣS0 of every region (eq. 1), its pixel
    count and its centroid (row, column), pixels. ``stokes``: the float64 maps S0 = Î,
    S1 = Î ρ cos 2φ, S2 = Î ρ sin 2φ when already made (else computed here).

    Returns
    -------
    z : complex array (n,)
    count : float array (n,)
    centroid : float array (n, 2)
    """
    flat = regions.ravel()
    n = int(flat.max()) + 1
    count = np.maximum(np.bincount(flat, minlength=n), 1).astype(np.float64)
    if stokes is None:
        i = intensity.astype(np.float64).ravel()
        two_phi = 2.0 * phase.astype(np.float64).ravel()
        stokes = (i, i * dop.ravel() * np.cos(two_phi), i * dop.ravel() * np.sin(two_phi))
    sums = [np.bincount(flat, weights=v.ravel(), minlength=n) for v in stokes]
    z = (sums[1] + 1j * sums[2]) / np.maximum(sums[0], EPS_INTENSITY)
    return z, count, region_centroids(regions, count)


def region_centroids(regions: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(n, 2) float64: mean row and column of every region, pixels."""
    h, w = regions.shape
    flat = regions.ravel()
    rows, cols = np.divmod(np.arange(flat.size), w)
    n = count.size
    return np.stack(
        [np.bincount(flat, weights=v, minlength=n) / count for v in (rows, cols)], axis=1
    )


def trend_basis(centroid: np.ndarray, shape: tuple[int, int], degree: int) -> np.ndarray:
    """(n, m) monomials x^a y^b, a + b ≤ ``degree``, of the centroids in units of the
    frame's longer side, centred on the frame."""
    h, w = shape
    side = float(max(h, w))
    y = (centroid[:, 0] - h / 2.0) / side
    x = (centroid[:, 1] - w / 2.0) / side
    return np.stack([x**a * y**b for a in range(degree + 1) for b in range(degree + 1 - a)], 1)


def fit_trend(z: np.ndarray, basis: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The weighted least-squares fit of complex ``z`` on ``basis``, at every region."""
    sw = np.sqrt(weight)[:, None]
    coef = np.linalg.lstsq(basis * sw, z * sw[:, 0], rcond=None)[0]
    return basis @ coef


def surface_trend_share(
    z: np.ndarray, count: np.ndarray, centroid: np.ndarray, shape: tuple[int, int]
) -> float:
    """Share (≤ 1; 1 = a perfect fit) of the area-weighted variance of z explained by
    the square of one linear field, z ≈ (a x + b y + e)² with complex a, b, e: eq. 1 for
    one smooth surface whose gradient g is linear over the frame (a sphere, an
    ellipsoid, a cylinder at small slopes).

    Fitted as the complex quadratic a₂₀x² + a₁₁xy + a₀₂y² + a₁₀x + a₀₁y + a₀₀ (weighted
    least squares over the regions), reduced to its nearest perfect square — the
    rank-1 part σ₁u₁v₁ᴴ of its symmetric 3 × 3 matrix in (x, y, 1) — and rescaled by
    the complex factor that fits z best. A plain quadratic also fits a linear
    polarisation gradient (a reflecting water surface) or a scene of concentric
    bands; its perfect square does not.
    """
    basis = trend_basis(centroid, shape, 2)  # columns 1, y, y², x, xy, x²
    sw = np.sqrt(count)[:, None]
    coef = np.linalg.lstsq(basis * sw, z * sw[:, 0], rcond=None)[0]
    one, y, yy, x, xy, xx = coef
    m = np.array([[xx, xy / 2, x / 2], [xy / 2, yy, y / 2], [x / 2, y / 2, one]])
    u, sv, vh = np.linalg.svd(m)
    square = sv[0] * np.outer(u[:, 0], vh[0])
    v = basis[:, [3, 1, 0]]  # (x, y, 1)
    q = np.einsum("ni,ij,nj->n", v, square, v)
    scale = np.sum(count * z * np.conj(q)) / max(float(np.sum(count * np.abs(q) ** 2)), 1e-300)
    mean = np.average(z, weights=count)
    total = float(np.sum(count * np.abs(z - mean) ** 2))
    if total <= 0:
        return 0.0
    return float(min(1.0 - np.sum(count * np.abs(z - scale * q) ** 2) / total, 1.0))


def kernel_smooth(centroid: np.ndarray, values: np.ndarray, sigma: float) -> np.ndarray:
    """Σ_j exp(−|c_i − c_j|² / 2σ²) v_j for every region i (columns of ``values``
    smoothed alike); σ in pixels."""
    n = centroid.shape[0]
    out = np.empty_like(values, dtype=np.float64)
    for start in range(0, n, KERNEL_BLOCK):
        part = slice(start, min(n, start + KERNEL_BLOCK))
        d2 = np.sum((centroid[part, None, :] - centroid[None, :, :]) ** 2, axis=-1)
        out[part] = np.exp(-d2 / (2.0 * sigma * sigma)) @ values
    return out


def polarisation_over_trend(
    z: np.ndarray,
    count: np.ndarray,
    centroid: np.ndarray,
    shape: tuple[int, int],
    degree: int = 2,
    reach: float = 0.08,
    iterations: int = 2,
) -> np.ndarray:
    """Per-region ratio Re(Σ z conj Q) / Σ |Q|² of the polarisation to the surface
    trend Q (module docstring), dimensionless: ≈ 1 on the surface's main material,
    c'/c on a patch of another.

    Parameters
    ----------
    z, count, centroid
        From :func:`region_polarisation`.
    shape : (H, W)
        The frame's shape, pixels.
    degree : int
        Degree of the trend polynomial (2: a smooth convex or saddle surface).
    reach : float
        σ of the Gaussian weights as a share of √(H·W).
    iterations : int
        Refits of the trend on the larger side of an Otsu split of the ratio.
    """
    from skimage.filters import threshold_otsu

    basis = trend_basis(centroid, shape, degree)
    sigma = max(reach * float(np.sqrt(shape[0] * shape[1])), 1e-6)
    weight = count.copy()
    ratio = np.ones(z.size)
    for step in range(int(iterations) + 1):
        q = fit_trend(z, basis, weight)
        parts = np.stack([(z * np.conj(q)).real, np.abs(q) ** 2], axis=1) * count[:, None]
        sums = kernel_smooth(centroid, parts, sigma)
        ratio = sums[:, 0] / np.maximum(sums[:, 1], 1e-30)
        if step == iterations or np.ptp(ratio) <= 0:
            break
        above = ratio > threshold_otsu(ratio)
        main = above if count[above].sum() >= count[~above].sum() else ~above
        weight = count * np.where(main, 1.0, OUTLIER_WEIGHT)
    return ratio
