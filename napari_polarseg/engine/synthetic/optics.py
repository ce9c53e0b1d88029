"""Fresnel transmission and the angle stack a polariser camera records (thesis eq. 3.14).

ρ of diffuse reflection from the Fresnel *transmission* coefficients of light leaving
the material, independent of the closed form in :mod:`napari_polarseg.engine.physics.fresnel`
(the tests compare the two); :func:`render_stack` turns Î, ρ, φ into frames. Radians.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from ..errors import PolarsegError

FloatArray = NDArray[np.float64]


def _check_zenith_n(zenith: ArrayLike, n: ArrayLike) -> tuple[FloatArray, FloatArray]:
    zenith = np.asarray(zenith, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    if not np.all(np.isfinite(n)) or np.any(n < 1.0):
        raise PolarsegError("n (refractive index) must be finite and >= 1")
    if not np.all(np.isfinite(zenith)):
        raise PolarsegError("zenith must be finite")
    tol = 1e-9
    if np.any(zenith < -tol) or np.any(zenith > np.pi / 2 + tol):
        raise PolarsegError("zenith must lie in [0, pi/2] radians")
    return np.clip(zenith, 0.0, np.pi / 2), n


def fresnel_transmission_amplitudes(
    zenith: ArrayLike, n: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Fresnel amplitude transmission coefficients for light leaving a dielectric.

    Light inside a medium of refractive index ``n`` meets the surface at the internal
    angle θ_i and leaves into air at the exit angle θ (the zenith of the surface normal
    seen from the camera), with Snell's law ``sin θ_i = sin θ / n``.

    Parameters
    ----------
    zenith : array_like
        Exit angle θ in radians, in [0, π/2].
    n : array_like
        Refractive index of the material relative to air (dimensionless, >= 1).
        Broadcast against ``zenith``.

    Returns
    -------
    t_s, t_p : ndarray
        Amplitude coefficients perpendicular (s) and parallel (p) to the plane of
        incidence: ``t_s = 2 n cos θ_i / (n cos θ_i + cos θ)`` and
        ``t_p = 2 n cos θ_i / (cos θ_i + n cos θ)``.

    Raises
    ------
    PolarsegError
        If ``zenith`` is outside [0, π/2] or ``n`` < 1.
    """
    theta, n = _check_zenith_n(zenith, n)
    sin_i = np.sin(theta) / n
    cos_i = np.sqrt(np.clip(1.0 - sin_i**2, 0.0, None))
    cos_t = np.cos(theta)
    t_s = 2.0 * n * cos_i / (n * cos_i + cos_t)
    t_p = 2.0 * n * cos_i / (cos_i + n * cos_t)
    return t_s, t_p


def diffuse_dop_from_transmission(zenith: ArrayLike, n: ArrayLike) -> FloatArray:
    """Diffuse degree of polarisation from the Fresnel transmission coefficients.

    ``ρ = (T_p − T_s) / (T_p + T_s)`` for initially unpolarised light inside the material
    leaving through the surface at the exit angle θ = zenith (thesis eq. 3.12 written with
    transmittances ``T = 1 − R``). The obliquity factor ``cos θ / (n cos θ_i)`` is common
    to ``T_s`` and ``T_p`` and cancels, so ρ is evaluated as
    ``(t_p² − t_s²) / (t_p² + t_s²)``; this keeps the grazing limit θ → π/2 finite, where
    ρ reaches its ceiling ``(n² − 1) / (n² + 1)``.

    This is computed independently of the closed form (corrected thesis eq. 3.13).

    Parameters
    ----------
    zenith : array_like
        Zenith angle θ of the surface normal (= exit angle), radians in [0, π/2].
    n : array_like
        Refractive index relative to air (dimensionless, >= 1), broadcast against
        ``zenith``.

    Returns
    -------
    ndarray
        Degree of polarisation ρ in [0, (n² − 1)/(n² + 1)], dimensionless.

    Examples
    --------
    >>> round(float(diffuse_dop_from_transmission(np.deg2rad(60.0), 1.45)), 4)
    0.0851
    """
    t_s, t_p = fresnel_transmission_amplitudes(zenith, n)
    a_s, a_p = t_s**2, t_p**2
    return (a_p - a_s) / (a_p + a_s)


def _polarisation_maps(
    intensity: ArrayLike, dop: ArrayLike, phase: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Î, ρ, φ as float64 maps of one 2-D shape (broadcast), or PolarsegError."""
    try:
        i_arr, rho, phi = np.broadcast_arrays(
            np.asarray(intensity, dtype=np.float64),
            np.asarray(dop, dtype=np.float64),
            np.asarray(phase, dtype=np.float64),
        )
    except ValueError as exc:
        raise PolarsegError("intensity, dop and phase must have the same shape") from exc
    if i_arr.ndim != 2:
        raise PolarsegError(f"intensity, dop and phase must be 2-D, got shape {i_arr.shape}")
    return i_arr, rho, phi


def _shift_frames(stack: FloatArray, shifts: ArrayLike) -> None:
    """Translate every frame of ``stack`` in place by its (rows, cols) shift (cubic)."""
    n = stack.shape[0]
    sh = np.asarray(shifts, dtype=np.float64)
    if sh.shape != (n, 2) or not np.all(np.isfinite(sh)):
        raise PolarsegError(f"shifts must be finite with shape ({n}, 2), got {sh.shape}")
    for k in range(n):
        if np.any(sh[k] != 0.0):
            stack[k] = ndimage.shift(stack[k], sh[k], order=3, mode="nearest")


def render_stack(
    intensity: ArrayLike,
    dop: ArrayLike,
    phase: ArrayLike,
    angles: ArrayLike,
    *,
    noise_sigma: float = 0.0,
    bit_depth: int | None = None,
    full_scale: float = 1.0,
    rng: np.random.Generator | int | None = None,
    shifts: ArrayLike | None = None,
) -> NDArray:
    """Render the images seen through a linear polariser at several angles.

    ``I_k = Î (1 + ρ cos(2 α_k − 2 φ))`` (thesis eq. 3.14), then, in this order: optional
    sub-pixel translation of each frame (scene motion between exposures), optional
    additive Gaussian noise (sensor), optional quantisation.

    Parameters
    ----------
    intensity : array_like, shape (H, W)
        Mean intensity Î, in the same units as ``full_scale``.
    dop : array_like, shape (H, W)
        Degree of polarisation ρ (dimensionless, [0, 1]).
    phase : array_like, shape (H, W)
        Polarisation phase φ in radians, measured from the column axis towards the row
        axis.
    angles : array_like, shape (N,)
        Polariser angles α_k in radians, same frame as ``phase``.
    noise_sigma : float, optional
        Standard deviation of additive Gaussian noise, as a fraction of ``full_scale``.
    bit_depth : int or None, optional
        If given (1..16), values are scaled so that ``full_scale`` maps to
        ``2**bit_depth − 1``, rounded, clipped to [0, 2**bit_depth − 1] and returned as
        ``uint8`` (bit_depth <= 8) or ``uint16``. If None, float64 is returned unclipped.
    full_scale : float, optional
        Intensity that maps to the largest code value (and the unit of ``noise_sigma``).
    rng : numpy.random.Generator or int or None, optional
        Source of the noise (a seed or a Generator); only used if ``noise_sigma > 0``.
    shifts : array_like, shape (N, 2), optional
        Per-frame translation (rows, cols) in pixels. Frame k's content moves by
        ``shifts[k]`` (``scipy.ndimage.shift`` with cubic splines, edges extended by the
        nearest value).

    Returns
    -------
    ndarray, shape (N, H, W)
        float64, or uint8 / uint16 when ``bit_depth`` is given.

    Raises
    ------
    PolarsegError
        On arrays of mismatched shape, non-1-D ``angles``, negative ``noise_sigma``,
        non-positive ``full_scale``, ``bit_depth`` outside 1..16 or ``shifts`` not N × 2.

    Examples
    --------
    >>> stack = render_stack(np.full((2, 2), 0.5), np.full((2, 2), 0.2),
    ...                      np.zeros((2, 2)), np.deg2rad([0, 45, 90]))
    >>> stack[:, 0, 0].round(6).tolist()
    [0.6, 0.5, 0.4]
    """
    i_arr, rho, phi = _polarisation_maps(intensity, dop, phase)
    alpha = _checked_angles(angles, noise_sigma, full_scale, bit_depth)

    a = alpha[:, None, None]
    stack = i_arr[None] * (1.0 + rho[None] * np.cos(2.0 * a - 2.0 * phi[None]))

    if shifts is not None:
        _shift_frames(stack, shifts)

    if noise_sigma > 0:
        gen = np.random.default_rng(rng)
        stack = stack + gen.normal(0.0, noise_sigma * full_scale, size=stack.shape)

    return stack if bit_depth is None else _quantised(stack, full_scale, int(bit_depth))


def _checked_angles(
    angles: ArrayLike, noise_sigma: float, full_scale: float, bit_depth: int | None
) -> FloatArray:
    """The angles of :func:`render_stack` as float64 after checking its options."""
    alpha = np.asarray(angles, dtype=np.float64)
    if alpha.ndim != 1 or alpha.size == 0:
        raise PolarsegError(f"angles must be a non-empty 1-D array, got shape {alpha.shape}")
    if not np.isfinite(noise_sigma) or noise_sigma < 0:
        raise PolarsegError(f"noise_sigma must be >= 0, got {noise_sigma!r}")
    if not np.isfinite(full_scale) or full_scale <= 0:
        raise PolarsegError(f"full_scale must be > 0, got {full_scale!r}")
    if bit_depth is not None and (int(bit_depth) != bit_depth or not 1 <= bit_depth <= 16):
        raise PolarsegError(f"bit_depth must be an integer in 1..16 or None, got {bit_depth!r}")
    return alpha


def _quantised(stack: FloatArray, full_scale: float, bit_depth: int) -> NDArray:
    """Integer codes of a ``bit_depth`` sensor (uint8 up to 8 bits, else uint16)."""
    top = 2**bit_depth - 1
    codes = np.clip(np.rint(stack / full_scale * top), 0, top)
    return codes.astype(np.uint8 if bit_depth <= 8 else np.uint16)
