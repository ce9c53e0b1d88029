"""The per-pixel fit of the transmitted-radiance sinusoid, thesis eq. 3.14.

I(α) = c0 + c1 cos 2α + c2 sin 2α, fitted per pixel: exact least squares when every
sample counts once (one pseudo-inverse for the whole stack), weighted least squares (a
closed-form 3 × 3 solve per pixel) when samples are missing, and the robust MM-type fit
(least-trimmed-squares start, then IRLS with Tukey's or Huber's weights). The method and
its reasons: :mod:`.polarimage`.
"""

from __future__ import annotations

import warnings

import numpy as np

#: Robust losses of :func:`.polarimage.polarisation_image` (``loss=``).
ROBUST_LOSSES = ("tukey", "huber")


#: Tuning constants (in units of the residual scale) for 95 % efficiency under Gaussian noise.
HUBER_C = 1.345


TUKEY_C = 4.685


def sinusoid_design(angles: np.ndarray) -> np.ndarray:
    """Design matrix (N, 3) with columns 1, cos 2α, sin 2α for angles α in radians."""
    a = np.asarray(angles, dtype=float)
    return np.stack([np.ones_like(a), np.cos(2 * a), np.sin(2 * a)], axis=1)


def unweighted_solver(
    angles: np.ndarray, groups: np.ndarray, n_groups: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The least-squares fit of eq. 3.14 when every sample counts once, as two matrices.

    The fit of the per-state means (frames at one angle modulo π averaged, each state
    weighted by its frame count, as :func:`.polarimage.average_duplicate_angles` with unit
    weights) is linear in the frames: coef = M A x and the residual of the states
    r = (A − D M A) x for a pixel's samples x, with A (G, N) the averaging, D (G, 3) the
    design and M its weighted pseudo-inverse. Returns ``to_coef`` = M A (3, N),
    ``to_residual`` = A − D M A (G, N) and the states' angles (G,), radians; applied to
    chunks of pixels by :func:`unweighted_chunk` (no (G, P) array of means or residuals).
    """
    counts = np.bincount(groups, minlength=n_groups).astype(np.float64)
    first = np.array([np.flatnonzero(groups == g)[0] for g in range(n_groups)])
    average = (groups[None, :] == np.arange(n_groups)[:, None]) / counts[:, None]  # A
    design = sinusoid_design(angles[first])
    sw = np.sqrt(counts)[:, None]
    to_coef = (np.linalg.pinv(design * sw) * sw.T) @ average  # M A (3, N)
    to_residual = average - design @ to_coef  # (G, N)
    return to_coef, to_residual, angles[first]


def unweighted_chunk(
    to_coef: np.ndarray, to_residual: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (3, Q) of eq. 3.14 and RMS residual over the G states (Q,) of the
    pixels (columns) of ``x`` (N, Q), with the matrices of :func:`unweighted_solver`."""
    coef = to_coef @ x
    r = to_residual @ x
    return coef, np.sqrt(np.einsum("ij,ij->j", r, r) / to_residual.shape[0])


def weighted_fit(design: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel weighted least squares of y ≈ design @ c.

    ``design`` (G, 3), ``y`` and ``w`` (G, Q). Solves every 3 × 3 normal system in closed
    form (adjugate over determinant, vectorised). Returns ``coef`` (3, Q) and ``ok`` (Q,):
    False where the normal matrix is singular (fewer than 3 distinct angles with positive
    weight); ``coef`` is 0 there.
    """
    pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    products = np.stack([design[:, i] * design[:, j] for i, j in pairs], axis=0)  # (6, G)
    m00, m01, m02, m11, m12, m22 = products @ w  # each (Q,)
    b0, b1, b2 = design.T @ (w * y)  # each (Q,)
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    det = m00 * c00 + m01 * c01 + m02 * c02
    trace = m00 + m11 + m22
    ok = (trace > 0) & (det > 1e-9 * (trace / 3.0) ** 3)
    inv_det = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    coef = np.stack(
        [
            (c00 * b0 + c01 * b1 + c02 * b2) * inv_det,
            (c01 * b0 + c11 * b1 + c12 * b2) * inv_det,
            (c02 * b0 + c12 * b1 + c22 * b2) * inv_det,
        ]
    )
    return coef, ok


def _trimmed_start(
    design: np.ndarray, y: np.ndarray, base: np.ndarray, coef: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Least-trimmed-squares start: per pixel the best fit that leaves out one sample.

    Returns the starting coefficients (3, Q) and the normalised median absolute residual
    of that fit over all usable samples (Q,), the pixel's noise scale.
    Pixels with fewer than 5 usable samples keep ``coef`` (no outlier is detectable).
    """
    usable = base > 0
    n_used = usable.sum(axis=0)
    best_rss = np.full(y.shape[1], np.inf)
    best = coef.copy()
    for k in range(y.shape[0]):
        w = base.copy()
        w[k] = 0.0
        trial, ok = weighted_fit(design, y, w)
        rss = np.sum(w * (y - design @ trial) ** 2, axis=0)
        better = ok & (rss < best_rss) & (n_used >= 5)
        best = np.where(better, trial, best)
        best_rss = np.where(better, rss, best_rss)
    residual = np.abs(y - design @ best)
    if usable.all():
        mad = np.median(residual, axis=0)
    else:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # pixels with no usable sample
            mad = np.nan_to_num(np.nanmedian(np.where(usable, residual, np.nan), axis=0))
    return best, 1.4826 * mad * np.sqrt(n_used / np.maximum(n_used - 3, 1))


def irls(
    design: np.ndarray,
    y: np.ndarray,
    base: np.ndarray,
    coef: np.ndarray,
    ok: np.ndarray,
    loss: str,
    iterations: int,
) -> tuple[np.ndarray, np.ndarray]:
    """M-estimate by IRLS from a trimmed start with a fixed scale (module docstring)."""
    coef, scale = _trimmed_start(design, y, base, coef)
    n_used = (base > 0).sum(axis=0)
    detectable = n_used >= 5
    pooled = float(np.median(scale[detectable])) if detectable.any() else 0.0
    floor = 1e-9 * np.abs(coef[0]) + np.finfo(float).tiny
    scale = np.maximum(np.maximum(scale, pooled), floor)
    weights = base
    for _ in range(iterations):
        residual = y - design @ coef
        if loss == "tukey":
            u = np.abs(residual) / (TUKEY_C * scale)
            rw = np.where(u < 1.0, (1.0 - np.minimum(u, 1.0) ** 2) ** 2, 0.0)
        else:
            u = np.abs(residual) / (HUBER_C * scale)
            rw = 1.0 / np.maximum(u, 1.0)
        weights = base * rw
        new, new_ok = weighted_fit(design, y, weights)
        new_ok &= ok
        step = np.where(new_ok, np.max(np.abs(new - coef), axis=0), 0.0)
        coef = np.where(new_ok, new, coef)
        if np.all(step <= 1e-9 * scale):
            break
    return coef, weights
