"""Polarisation image (Î, ρ, φ) from an angle stack.

Implements the transmitted-radiance sinusoid, thesis eq. 3.14,

    I(α) = Î (1 + ρ cos(2α − 2φ)) = c0 + c1 cos 2α + c2 sin 2α,

by exact linear least squares for any set of N >= 3 distinct polariser angles (modulo π):
one 3 × N pseudo-inverse applied to the whole stack. Then Î = c0, ρ = √(c1² + c2²)/c0 and
φ = ½ atan2(c2, c1) mod π. This replaces the thesis moment estimators (eqs. 4.8–4.12),
which mix up a mean with an integral (ρ off by √π, a spurious 2π in eq. 4.11) and whose
arccos folds φ into [0, π/2]. For Gaussian noise the least-squares fit *is* the
Levenberg–Marquardt optimum the thesis refines towards.

Angles are radians, measured from the image's column axis towards its row axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import PolarsegError

#: Two polariser angles closer than this (radians, modulo π) are the same state.
ANGLE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class PolarisationImage:
    """The polarisation image of thesis eq. 4.18 plus fit diagnostics.

    Attributes
    ----------
    intensity : ndarray (H, W)
        Mean intensity Î (units of the input).
    dop : ndarray (H, W)
        Degree of polarisation ρ in [0, 1].
    phase : ndarray (H, W)
        Phase φ, radians in [0, π).
    residual : ndarray (H, W)
        Root-mean-square residual of the sinusoid fit (units of the input).
    invalid : ndarray (H, W) of bool
        Pixels with Î <= 0 (ρ and φ are set to 0 there).
    """

    intensity: np.ndarray
    dop: np.ndarray
    phase: np.ndarray
    residual: np.ndarray
    invalid: np.ndarray


def distinct_angle_count(angles: np.ndarray) -> int:
    """Number of distinct polariser states among ``angles`` (radians, modulo π)."""
    a = np.mod(np.asarray(angles, dtype=float), np.pi)
    a = np.sort(a)
    if a.size == 0:
        return 0
    gaps = np.diff(np.concatenate([a, [a[0] + np.pi]]))
    # states separated by less than the tolerance (including across the 0/π wrap) merge
    return max(int(np.count_nonzero(gaps > ANGLE_TOLERANCE)), 1)


def sinusoid_design(angles: np.ndarray) -> np.ndarray:
    """Design matrix (N, 3) with columns 1, cos 2α, sin 2α for angles α in radians."""
    a = np.asarray(angles, dtype=float)
    return np.stack([np.ones_like(a), np.cos(2 * a), np.sin(2 * a)], axis=1)


def check_stack(stack: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate an angle stack; return it as float64 (N, H, W) and angles as float64 (N,).

    Raises :class:`PolarsegError` for a wrong shape, a count mismatch between frames and
    angles, fewer than 3 distinct angles modulo π, non-finite angles, or data that has no
    finite value at all.
    """
    stack = np.asarray(stack)
    angles = np.asarray(angles, dtype=float).ravel()
    if stack.ndim != 3:
        raise PolarsegError(
            f"angle stack must have 3 dimensions (angles, rows, columns), got shape {stack.shape}"
        )
    if stack.shape[0] != angles.size:
        raise PolarsegError(
            f"the stack has {stack.shape[0]} frames but {angles.size} angles were given"
        )
    if stack.shape[1] < 1 or stack.shape[2] < 1:
        raise PolarsegError(f"angle stack has an empty frame: shape {stack.shape}")
    if not np.all(np.isfinite(angles)):
        raise PolarsegError("polariser angles must be finite numbers")
    n_distinct = distinct_angle_count(angles)
    if n_distinct < 3:
        raise PolarsegError(
            f"need at least 3 distinct polariser angles (modulo 180 degrees), got {n_distinct}"
        )
    if not np.issubdtype(stack.dtype, np.number) or np.issubdtype(stack.dtype, np.complexfloating):
        raise PolarsegError(f"angle stack must hold real numbers, got dtype {stack.dtype}")
    data = stack.astype(np.float64, copy=False)
    if not np.any(np.isfinite(data)):
        raise PolarsegError("the angle stack has no finite values (all NaN or infinite)")
    return data, angles


def polarisation_image(stack: np.ndarray, angles: np.ndarray) -> PolarisationImage:
    """Fit thesis eq. 3.14 at every pixel by linear least squares.

    Parameters
    ----------
    stack : array (N, H, W)
        Grey images through a linear polariser at the N ``angles``.
    angles : array (N,)
        Polariser angles in radians (any N >= 3 distinct angles modulo π; repeated angles
        are allowed and simply weigh more).

    Returns
    -------
    PolarisationImage
        Î, ρ ∈ [0, 1], φ ∈ [0, π) radians, the RMS fit residual and the invalid mask.
        A pixel with a non-finite sample in any frame is marked invalid (Î, ρ, φ = 0).

    Examples
    --------
    >>> import numpy as np
    >>> a = np.deg2rad([0, 45, 90, 135])
    >>> stack = (2.0 * (1 + 0.3 * np.cos(2 * a - 2 * 0.5)))[:, None, None]
    >>> p = polarisation_image(stack, a)
    >>> round(float(p.intensity[0, 0]), 6), round(float(p.dop[0, 0]), 6)
    (2.0, 0.3)
    """
    data, angles = check_stack(stack, angles)
    n, h, w = data.shape
    design = sinusoid_design(angles)
    pinv = np.linalg.pinv(design)  # (3, N): the exact least-squares solve for every pixel
    flat = data.reshape(n, -1)
    finite = np.all(np.isfinite(flat), axis=0)
    if not finite.all():
        flat = np.where(np.isfinite(flat), flat, 0.0)
    coef = pinv @ flat  # (3, P)
    c0, c1, c2 = coef
    fitted = design @ coef
    residual = np.sqrt(np.mean((flat - fitted) ** 2, axis=0))
    amp = np.hypot(c1, c2)
    invalid = (c0 <= 0) | ~finite
    with np.errstate(divide="ignore", invalid="ignore"):
        dop = np.where(invalid, 0.0, amp / np.where(invalid, 1.0, c0))
    dop = np.clip(dop, 0.0, 1.0)
    phase = np.mod(0.5 * np.arctan2(c2, c1), np.pi)
    phase = np.where(invalid, 0.0, phase)
    # mod can return π itself for tiny negative inputs in floating point
    phase[phase >= np.pi] = 0.0
    intensity = np.where(finite, c0, 0.0)
    return PolarisationImage(
        intensity=intensity.reshape(h, w),
        dop=dop.reshape(h, w),
        phase=phase.reshape(h, w),
        residual=np.where(finite, residual, 0.0).reshape(h, w),
        invalid=invalid.reshape(h, w),
    )
