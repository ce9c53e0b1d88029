"""Fresnel theory: degree of polarisation against zenith angle, and its inverse.

Thesis section 3.3–3.5. All angles are radians; ``n`` is the refractive index of the
dielectric relative to air (dimensionless, > 1).

Corrections to the thesis (see DESIGN.md):

- eq. 3.13 as printed has ``(1 + 1/n)² sin²θ`` where ``(n + 1/n)² sin²θ`` is right. The
  corrected closed form is :func:`diffuse_dop`; :func:`diffuse_dop_fresnel` evaluates the
  same quantity through eq. 3.12 from the Fresnel coefficients and Snell's law, and the
  two agree to round-off.
- Diffuse ρ has a ceiling (n² − 1)/(n² + 1) at θ = 90°; measured ρ above it (noise,
  specular highlights) maps to θ = 90° and is counted, not turned into NaN.
- Specular ρ is not monotonic: it rises from 0 to 1 at Brewster's angle arctan n and
  falls back to 0 at 90°. :func:`zenith_from_specular_dop` takes the branch explicitly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PolarsegError

ArrayLike = np.ndarray | float


def _check_n(n: float) -> float:
    n = float(n)
    if not np.isfinite(n) or n <= 1.0:
        raise PolarsegError(f"refractive index must be a finite number > 1, got {n!r}")
    return n


def fresnel_reflectance(n_ratio: float, theta_i: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Fresnel intensity reflection coefficients R⊥ and R∥ (thesis eqs. 3.3–3.5).

    Parameters
    ----------
    n_ratio : float
        Relative refractive index n_t / n_i of the interface (n for air → dielectric,
        1/n for dielectric → air).
    theta_i : array
        Angle of incidence, radians in [0, π/2].

    Returns
    -------
    R_perp, R_par : arrays
        r⊥² and r∥²; both are 1 beyond the critical angle (total internal reflection).
    """
    theta_i = np.asarray(theta_i, dtype=float)
    sin_t = np.sin(theta_i) / n_ratio  # Snell's law, eq. 3.1
    tir = sin_t > 1.0
    cos_t = np.sqrt(np.clip(1.0 - sin_t**2, 0.0, None))
    cos_i = np.cos(theta_i)
    r_perp = (cos_i - n_ratio * cos_t) / (cos_i + n_ratio * cos_t)
    r_par = (n_ratio * cos_i - cos_t) / (cos_t + n_ratio * cos_i)
    R_perp = np.where(tir, 1.0, r_perp**2)
    R_par = np.where(tir, 1.0, r_par**2)
    return R_perp, R_par


def diffuse_dop_ceiling(n: float) -> float:
    """Largest diffuse degree of polarisation, (n² − 1)/(n² + 1), reached at θ = 90°."""
    n = _check_n(n)
    return (n * n - 1.0) / (n * n + 1.0)


def diffuse_dop(zenith: ArrayLike, n: float) -> np.ndarray:
    """Diffuse degree of polarisation, corrected thesis eq. 3.13.

    ρ_d = (n − 1/n)² sin²θ / (2 + 2n² − (n + 1/n)² sin²θ + 4 cos θ √(n² − sin²θ))

    Parameters
    ----------
    zenith : array
        Zenith angle θ of the surface normal, radians in [0, π/2].
    n : float
        Refractive index (> 1).
    """
    n = _check_n(n)
    s2 = np.sin(np.asarray(zenith, dtype=float)) ** 2
    num = (n - 1.0 / n) ** 2 * s2
    den = 2 + 2 * n * n - (n + 1.0 / n) ** 2 * s2 + 4 * np.cos(zenith) * np.sqrt(n * n - s2)
    return num / den


def diffuse_dop_fresnel(zenith: ArrayLike, n: float) -> np.ndarray:
    """Diffuse degree of polarisation from the Fresnel coefficients, thesis eq. 3.12.

    ρ_d = (R⊥(1/n, θ'_i) − R∥(1/n, θ'_i)) / (2 − R⊥(1/n, θ'_i) − R∥(1/n, θ'_i)), with the
    internal angle θ'_i from Snell's law sin θ'_i = sin θ / n. Used to check eq. 3.13.
    """
    n = _check_n(n)
    theta_int = np.arcsin(np.sin(np.asarray(zenith, dtype=float)) / n)
    R_perp, R_par = fresnel_reflectance(1.0 / n, theta_int)
    return (R_perp - R_par) / (2.0 - R_perp - R_par)


def specular_dop(zenith: ArrayLike, n: float) -> np.ndarray:
    """Specular degree of polarisation, thesis eq. 3.11.

    ρ_s = 2 sin²θ cos θ √(n² − sin²θ) / (n² − sin²θ − n² sin²θ + 2 sin⁴θ)
    """
    n = _check_n(n)
    z = np.asarray(zenith, dtype=float)
    s2 = np.sin(z) ** 2
    num = 2 * s2 * np.cos(z) * np.sqrt(n * n - s2)
    den = n * n - s2 - n * n * s2 + 2 * s2 * s2
    return num / den


def specular_dop_fresnel(zenith: ArrayLike, n: float) -> np.ndarray:
    """Specular degree of polarisation from the Fresnel coefficients, thesis eq. 3.10."""
    n = _check_n(n)
    R_perp, R_par = fresnel_reflectance(n, np.asarray(zenith, dtype=float))
    return (R_perp - R_par) / (R_perp + R_par)


def brewster_angle(n: float) -> float:
    """Brewster's angle arctan n (radians), where specular ρ reaches 1."""
    return float(np.arctan(_check_n(n)))


@dataclass(frozen=True)
class ZenithEstimate:
    """Zenith angles recovered from ρ, with the pixels that had to be clamped.

    Attributes
    ----------
    zenith : ndarray
        θ, radians in [0, π/2].
    clamped : ndarray of bool
        Pixels whose ρ was above what the model allows at this n (diffuse: above the
        ceiling, mapped to 90°; specular: above 1, mapped to Brewster's angle).
    """

    zenith: np.ndarray
    clamped: np.ndarray

    @property
    def n_clamped(self) -> int:
        return int(np.count_nonzero(self.clamped))


def zenith_from_diffuse_dop(dop: ArrayLike, n: float) -> ZenithEstimate:
    """Invert the corrected eq. 3.13 in closed form.

    Isolating the square-root term of eq. 3.13 and squaring gives a quadratic in
    s = sin²θ (written out here because no library inverts eq. 3.13):

        [(C + ρB)² − 16ρ²] s² − 4ρ(1 + n²)(C + ρB − 4ρ) s + 4ρ²(n² − 1)² = 0,

    with B = (n + 1/n)² and C = (n − 1/n)². The root taken is the one that satisfies the
    unsquared equation; it is evaluated in the cancellation-free form. ρ at or above the
    ceiling (n² − 1)/(n² + 1) gives θ = π/2 and is flagged in ``clamped``.

    Parameters
    ----------
    dop : array
        Degree of polarisation ρ (values < 0 are treated as 0).
    n : float
        Refractive index (> 1).
    """
    n = _check_n(n)
    rho = np.clip(np.asarray(dop, dtype=float), 0.0, None)
    ceiling = diffuse_dop_ceiling(n)
    clamped = rho >= ceiling
    r = np.where(clamped, ceiling, rho)
    B = (n + 1.0 / n) ** 2
    C = (n - 1.0 / n) ** 2
    a = (C + r * B) ** 2 - 16 * r * r
    b = -4 * r * (1 + n * n) * (C + r * B - 4 * r)
    c = 4 * r * r * (n * n - 1) ** 2
    q = 0.5 * (-b + np.sqrt(np.clip(b * b - 4 * a * c, 0.0, None)))
    s = np.clip(q / a, 0.0, 1.0)
    zenith = np.arctan2(np.sqrt(s), np.sqrt(1.0 - s))
    zenith = np.where(clamped, np.pi / 2, zenith)
    return ZenithEstimate(zenith=zenith, clamped=clamped)


def _invert_monotonic(func, values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Invert a monotonic scalar function on [lo, hi] for many values at once.

    A 4097-point table brackets each value; 40 vectorised bisection steps inside the
    bracket bring the error below 1e-12 rad. (scipy's root finders work one scalar at a
    time; this keeps the work vectorised over all pixels.)
    """
    grid = np.linspace(lo, hi, 4097)
    table = func(grid)
    increasing = table[-1] >= table[0]
    if not increasing:
        grid, table = grid[::-1], table[::-1]
    idx = np.clip(np.searchsorted(table, values), 1, grid.size - 1)
    a = grid[idx - 1].copy()
    b = grid[idx].copy()
    for _ in range(40):
        mid = 0.5 * (a + b)
        below = func(mid) < values
        a = np.where(below, mid, a)
        b = np.where(below, b, mid)
    return 0.5 * (a + b)


def zenith_from_specular_dop(
    dop: ArrayLike, n: float, branch: str = "below-brewster"
) -> ZenithEstimate:
    """Invert eq. 3.11 on one branch.

    Parameters
    ----------
    dop : array
        Specular degree of polarisation ρ in [0, 1].
    n : float
        Refractive index (> 1).
    branch : {"below-brewster", "above-brewster"}
        ρ_s takes every value in (0, 1) twice: once for θ in [0, θ_B] and once for θ in
        [θ_B, π/2], with θ_B = arctan n. Choose which solution to return.
    """
    n = _check_n(n)
    if branch not in ("below-brewster", "above-brewster"):
        raise PolarsegError(
            f"specular branch must be 'below-brewster' or 'above-brewster', got {branch!r}"
        )
    rho = np.clip(np.asarray(dop, dtype=float), 0.0, None)
    clamped = rho > 1.0
    r = np.minimum(rho, 1.0)
    tb = brewster_angle(n)
    lo, hi = (0.0, tb) if branch == "below-brewster" else (tb, np.pi / 2)
    shape = r.shape
    flat = r.ravel()
    sign = 1.0 if branch == "below-brewster" else -1.0
    # bisection on an increasing function: negate the decreasing branch
    zen = _invert_monotonic(lambda z: sign * specular_dop(z, n), sign * flat, lo, hi)
    return ZenithEstimate(zenith=zen.reshape(shape), clamped=clamped)


def azimuth_from_phase(phase: ArrayLike, model: str = "diffuse") -> np.ndarray:
    """Azimuth of the surface normal from the polarisation phase φ (radians).

    Diffuse: azimuth = φ. Specular: azimuth = φ + π/2 (the polariser passes most light
    at 90° to the plane of incidence). The 180° ambiguity is left unresolved as in the
    thesis, so the result is in [0, π).
    """
    phase = np.asarray(phase, dtype=float)
    if model == "diffuse":
        return np.mod(phase, np.pi)
    if model == "specular":
        return np.mod(phase + np.pi / 2, np.pi)
    raise PolarsegError(f"model must be 'diffuse' or 'specular', got {model!r}")


def zenith_from_dop(
    dop: ArrayLike, n: float, model: str = "diffuse", branch: str = "below-brewster"
) -> ZenithEstimate:
    """Zenith from ρ under the chosen Fresnel model (see the two functions above)."""
    if model == "diffuse":
        return zenith_from_diffuse_dop(dop, n)
    if model == "specular":
        return zenith_from_specular_dop(dop, n, branch)
    raise PolarsegError(f"model must be 'diffuse' or 'specular', got {model!r}")
