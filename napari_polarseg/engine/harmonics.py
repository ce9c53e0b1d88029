"""Real spherical harmonics of intensity over (zenith, azimuth), per image block.

Thesis eqs. 4.15–4.21. Angles are radians: θ is the zenith (polar angle from the view
axis, [0, π/2] for visible surfaces) and φ the azimuth.

Normalisation (stated because the thesis leaves it open)
--------------------------------------------------------
The real harmonics are orthonormal over the whole sphere, ∫ Y_lm Y_l'm' dΩ = δ_ll' δ_mm',
built from scipy's spherical Legendre functions (which carry the Condon–Shortley phase
(−1)^m) with that phase removed again:

    Y_l0  = Ȳ_l^0(θ)
    Y_lm  = √2 (−1)^m Ȳ_l^m(θ) cos(mφ)      m > 0
    Y_l−m = √2 (−1)^m Ȳ_l^m(θ) sin(mφ)      m > 0

where Ȳ_l^m(θ) = Y_l^m(θ, 0) is ``scipy.special.sph_legendre_p``. The coefficient vector
is ordered as the thesis's A = [a00, a1−1, a10, a11, a2−2, …]: index l² + l + m.

Estimators
----------
- ``"thesis"`` (eq. 4.21): a_lm = (1/M) Σ_i Î_i Y_lm(θ_i, φ_i) over the M pixels of a
  block. This is the inner product under the *empirical* measure of the block's samples,
  not a projection onto the orthonormal basis: only if the samples covered the sphere
  uniformly would it equal a_lm/(4π) of eq. 4.17. With the block Gram matrix
  G = (1/M) Yᵀ Y, the reconstruction consistent with it is Î ≈ Y (G + λI)⁻¹ a, which is
  the ridge fit below.
- ``"ridge"``: per-block ridge least squares, argmin ‖Y a − Î‖² + λ' ‖a‖² with
  λ' = ``ridge`` · M/(4π) (``ridge`` is relative to the mean diagonal of Yᵀ Y, which
  is M/(4π) for any sample positions).
"""

from __future__ import annotations

import numpy as np
from scipy.special import sph_legendre_p_all

from .errors import PolarsegError

#: Bytes of harmonic values evaluated at once (chunking bounds peak memory).
CHUNK_BYTES = 64 * 2**20


def n_coefficients(degree: int) -> int:
    """Length (L + 1)² of the coefficient vector for degree L."""
    return (degree + 1) ** 2


def coefficient_index(l: int, m: int) -> int:  # noqa: E741 - thesis notation
    """Position of a_lm in the thesis vector A (eq. 4.21 ordering): l² + l + m."""
    if not (l >= 0 and -l <= m <= l):
        raise PolarsegError(f"need l >= 0 and -l <= m <= l, got l={l}, m={m}")
    return l * l + l + m


def degree_order(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Arrays (l, m) for every entry of the coefficient vector, in thesis order."""
    ls = np.concatenate([np.full(2 * l + 1, l) for l in range(degree + 1)])  # noqa: E741
    ms = np.concatenate([np.arange(-l, l + 1) for l in range(degree + 1)])  # noqa: E741
    return ls, ms


def real_sph_harm(degree: int, zenith: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """Real orthonormal spherical harmonics Y_lm up to ``degree`` (see module docstring).

    Parameters
    ----------
    degree : int
        Highest degree L (>= 0).
    zenith, azimuth : arrays of the same shape S
        Polar angle θ and azimuth φ, radians.

    Returns
    -------
    ndarray, shape S + ((L + 1)²,)
        Y_lm(θ, φ) in thesis order a00, a1−1, a10, a11, a2−2, …
    """
    if degree < 0:
        raise PolarsegError(f"degree must be >= 0, got {degree}")
    zenith = np.asarray(zenith, dtype=float)
    azimuth = np.asarray(azimuth, dtype=float)
    if zenith.shape != azimuth.shape:
        raise PolarsegError(
            f"zenith and azimuth must have the same shape, got {zenith.shape} and {azimuth.shape}"
        )
    L = degree
    shape = zenith.shape
    # p[l, m] for m = 0..L at index m and m = -L..-1 at negative indices; only m >= 0 used
    p = sph_legendre_p_all(L, L, zenith.ravel())[0]
    out = np.empty((n_coefficients(L), zenith.size), dtype=float)
    ms = np.arange(1, L + 1)
    cos_m = np.cos(ms[:, None] * azimuth.reshape(1, -1))
    sin_m = np.sin(ms[:, None] * azimuth.reshape(1, -1))
    sign = np.where(ms % 2 == 0, 1.0, -1.0) * np.sqrt(2.0)
    for l in range(L + 1):  # noqa: E741 - a loop over degrees, vectorised over points
        base = l * l + l
        out[base] = p[l, 0]
        if l:
            pm = sign[:l, None] * p[l, 1 : l + 1]
            out[base + 1 : base + l + 1] = pm * cos_m[:l]
            out[base - l : base][::-1] = pm * sin_m[:l]
    return np.moveaxis(out, 0, -1).reshape(shape + (out.shape[0],))


def block_grid(shape: tuple[int, int], window: int) -> tuple[int, int]:
    """Number of whole w × w blocks along rows and columns (remainder strips excluded)."""
    h, w = shape
    if window > h or window > w:
        raise PolarsegError(f"window size {window} is larger than the image ({h} x {w} pixels)")
    return h // window, w // window


def _blockify(a: np.ndarray, window: int) -> np.ndarray:
    """(R*w, C*w, ...) -> (R, C, w*w, ...) without copying more than once."""
    r, c = a.shape[0] // window, a.shape[1] // window
    rest = a.shape[2:]
    a = a[: r * window, : c * window].reshape((r, window, c, window) + rest)
    return np.moveaxis(a, 2, 1).reshape((r, c, window * window) + rest)


def _row_chunks(n_block_rows: int, cols: int, window: int, k: int) -> int:
    per_row = max(window * window * cols * k * 8, 1)
    return max(1, min(n_block_rows, CHUNK_BYTES // per_row))


def block_coefficients(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    method: str = "thesis",
    ridge: float = 1e-3,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Spherical-harmonic coefficients of Î(θ, φ) per non-overlapping w × w block.

    Parameters
    ----------
    intensity, zenith, azimuth : arrays (H, W)
        Î, θ and φ (radians) per pixel.
    window : int
        Block side w in pixels. Only whole blocks are used; the remainder strips (when
        H or W is not a multiple of w) are labelled from their nearest block later.
    degree : int
        Highest degree L.
    method : {"thesis", "ridge"}
        Eq. 4.21 mean estimator, or per-block ridge least squares (module docstring).
    ridge : float
        Relative ridge penalty for ``method="ridge"``.
    weights : array (H, W) of {0, 1}, optional
        Pixels to use (1) or ignore (0), e.g. saturated or invalid pixels.

    Returns
    -------
    ndarray (H // w, W // w, (L + 1)²)
    """
    if method not in ("thesis", "ridge"):
        raise PolarsegError(f"coefficient method must be 'thesis' or 'ridge', got {method!r}")
    nby, nbx = block_grid(intensity.shape, window)
    k = n_coefficients(degree)
    out = np.empty((nby, nbx, k))
    step = _row_chunks(nby, nbx, window, k)
    for r0 in range(0, nby, step):
        r1 = min(nby, r0 + step)
        rows = slice(r0 * window, r1 * window)
        cols = slice(0, nbx * window)
        f = _blockify(intensity[rows, cols], window)  # (R, C, M)
        wts = None if weights is None else _blockify(weights[rows, cols].astype(float), window)
        Y = real_sph_harm(
            degree, _blockify(zenith[rows, cols], window), _blockify(azimuth[rows, cols], window)
        )  # (R, C, M, K)
        if method == "thesis":
            if wts is None:
                out[r0:r1] = np.einsum("rcm,rcmk->rck", f, Y) / f.shape[-1]
            else:
                count = np.maximum(wts.sum(-1), 1.0)
                out[r0:r1] = np.einsum("rcm,rcmk->rck", f * wts, Y) / count[..., None]
        else:
            out[r0:r1] = _ridge_fit(Y, f, ridge, wts)
    return out


def _ridge_fit(Y: np.ndarray, f: np.ndarray, ridge: float, wts: np.ndarray | None) -> np.ndarray:
    """Batched ridge solve per block; uses the M × M (dual) form when M < K."""
    m, k = Y.shape[-2], Y.shape[-1]
    lam = ridge * m / (4 * np.pi)
    if wts is not None:
        Y = Y * wts[..., None]
        f = f * wts
    if m < k:
        gram = np.einsum("...ik,...jk->...ij", Y, Y)
        gram[..., np.arange(m), np.arange(m)] += lam
        alpha = np.linalg.solve(gram, f[..., None])[..., 0]
        return np.einsum("...mk,...m->...k", Y, alpha)
    gram = np.einsum("...mi,...mj->...ij", Y, Y)
    gram[..., np.arange(k), np.arange(k)] += lam
    rhs = np.einsum("...mk,...m->...k", Y, f)
    return np.linalg.solve(gram, rhs[..., None])[..., 0]


def pixel_block_index(shape: tuple[int, int], window: int) -> tuple[np.ndarray, np.ndarray]:
    """Block row and column of every pixel row and column, remainder strips included.

    Pixels in the remainder strips (when the size is not a multiple of w) belong to the
    nearest whole block, so that labels and reconstructions cover the full image.
    """
    nby, nbx = block_grid(shape, window)
    rows = np.minimum(np.arange(shape[0]) // window, nby - 1)
    cols = np.minimum(np.arange(shape[1]) // window, nbx - 1)
    return rows, cols


def upsample_block_labels(
    block_labels: np.ndarray, shape: tuple[int, int], window: int
) -> np.ndarray:
    """Pixel-resolution labels (H, W) from block labels, covering every input pixel."""
    rows, cols = pixel_block_index(shape, window)
    return block_labels[rows[:, None], cols[None, :]]


def reconstruct_intensity(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    ridge: float = 1e-3,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Î rebuilt per pixel from its block's harmonic expansion (thesis section 5.5).

    Uses the reconstruction consistent with both estimators: the ridge least-squares
    coefficients of each block (equal to (G + λI)⁻¹ a_thesis, see module docstring),
    evaluated at every pixel's own (θ, φ). Remainder-strip pixels use the nearest
    block's coefficients. Returns an (H, W) array in the units of ``intensity``.
    """
    coef = block_coefficients(
        intensity, zenith, azimuth, window, degree, method="ridge", ridge=ridge, weights=weights
    )
    rows, cols = pixel_block_index(intensity.shape, window)
    h, w = intensity.shape
    k = coef.shape[-1]
    out = np.empty((h, w))
    step = max(1, CHUNK_BYTES // max(w * k * 8, 1))
    for r0 in range(0, h, step):
        r1 = min(h, r0 + step)
        Y = real_sph_harm(degree, zenith[r0:r1], azimuth[r0:r1])  # (r, W, K)
        c = coef[rows[r0:r1][:, None], cols[None, :]]  # (r, W, K)
        out[r0:r1] = np.einsum("rwk,rwk->rw", Y, c)
    return out
