"""Synthetic polarisation angle stacks with ground truth.

Renders the grey images a camera records through a linear polariser at several angles,
from physics, for scenes modelled on the thesis experiments (chapter 5): natural against
plastic leaves, a camouflage net in foliage, and a bruised fruit. Every scene comes with
its ground truth: material labels, the noise-free polarisation image (Î, ρ, φ), the true
surface normals (zenith, azimuth) and the refractive index of each pixel.

Conventions
-----------
- Polariser model (thesis eq. 3.14): ``I(α) = Î (1 + ρ cos(2α − 2φ))``.
- Angles α and φ are measured from the image's column axis (x, increasing column index)
  towards its row axis (y, increasing row index); φ lies in [0, π).
- A height field z(row, col) (in pixel units) has the surface normal
  ``n ∝ (−∂z/∂col, −∂z/∂row, 1)`` in (x = col, y = row, z = towards the camera). The
  camera is orthographic and looks along −z, so the exit (viewing) zenith of a facet is
  the zenith of its normal. Azimuth = ``atan2(n_row, n_col)``.
- Diffuse polarisation: φ equals the normal's azimuth (mod π) and ρ comes from the
  Fresnel *transmission* coefficients for light leaving the material
  (:func:`diffuse_dop_from_transmission`). This route is deliberately independent of
  the closed form (corrected eq. 3.13) in :mod:`napari_polarseg.engine.fresnel`, so the
  test suite can compare the two.
- Radians everywhere, except parameters whose name ends in ``_deg``.

Rendering model (:func:`render_surface`)
----------------------------------------
Each pixel is supersampled (``s × s`` sub-pixels, default 4 × 4). Every sub-pixel has a
macroscopic normal from the scene's height field; several facets per sub-pixel (default
4) tilt it by random micro-facet slopes of material-dependent spread (micro-roughness).
For each facet: Lambertian shading under a
distant light about 15° off the view axis (thesis section 5.1) plus a small ambient term,
times an albedo texture; ρ from the transmission coefficients at the material's
refractive index, multiplied by ``1 − d`` (material depolarisation: volume and
sub-surface scattering that leaves the material unpolarised); φ = facet azimuth. The
Stokes components ``s0 = Î, s1 = Î ρ cos 2φ, s2 = Î ρ sin 2φ`` are averaged over the
facets of a pixel, which lowers ρ and scatters φ the way real roughness does. Per-material
albedos are calibrated so that every material has the same mean Î (camouflage: the
intensity alone must not separate the materials).

Not modelled: specular highlights, cast shadows, inter-reflections, the 180° ambiguity of
the azimuth (φ is reported mod π), lens blur and sensor non-uniformity.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from ..errors import PolarsegError

__all__ = [
    "DEFAULT_ANGLES_DEG",
    "DEFAULT_NOISE_SIGMA",
    "MATERIALS",
    "SCENES",
    "Material",
    "SurfaceRender",
    "SyntheticScene",
    "diffuse_dop_from_transmission",
    "fresnel_transmission_amplitudes",
    "fresnel_transmittances",
    "make_scene",
    "scribble_strokes",
    "render_stack",
    "render_surface",
]

#: Names accepted by :func:`make_scene`.
SCENES: tuple[str, ...] = ("leaves", "camouflage", "fruit")

#: Default polariser angles in degrees: 7 angles 0..180 in 30° steps (thesis section 5.1).
DEFAULT_ANGLES_DEG: tuple[float, ...] = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0)

#: Default Gaussian read noise, as a fraction of full scale (0.3 %).
DEFAULT_NOISE_SIGMA: float = 0.003

FloatArray = NDArray[np.float64]


# --------------------------------------------------------------------------------------
# Fresnel transmission
# --------------------------------------------------------------------------------------


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


def fresnel_transmittances(zenith: ArrayLike, n: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Fresnel power transmittances for light leaving a dielectric into air.

    Parameters
    ----------
    zenith : array_like
        Exit angle θ in radians, in [0, π/2].
    n : array_like
        Refractive index of the material relative to air (dimensionless, >= 1).

    Returns
    -------
    T_s, T_p : ndarray
        ``T = (cos θ / (n cos θ_i)) |t|²`` for the s and p components (fractions of the
        power incident from inside). Both are 0 at grazing exit (θ = π/2).

    See Also
    --------
    fresnel_transmission_amplitudes
    """
    theta, n = _check_zenith_n(zenith, n)
    t_s, t_p = fresnel_transmission_amplitudes(theta, n)
    sin_i = np.sin(theta) / n
    cos_i = np.sqrt(np.clip(1.0 - sin_i**2, 0.0, None))
    factor = np.cos(theta) / (n * cos_i)
    return factor * t_s**2, factor * t_p**2


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


# --------------------------------------------------------------------------------------
# Angle stacks
# --------------------------------------------------------------------------------------


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
    alpha = np.asarray(angles, dtype=np.float64)
    if alpha.ndim != 1 or alpha.size == 0:
        raise PolarsegError(f"angles must be a non-empty 1-D array, got shape {alpha.shape}")
    if not np.isfinite(noise_sigma) or noise_sigma < 0:
        raise PolarsegError(f"noise_sigma must be >= 0, got {noise_sigma!r}")
    if not np.isfinite(full_scale) or full_scale <= 0:
        raise PolarsegError(f"full_scale must be > 0, got {full_scale!r}")
    if bit_depth is not None and (int(bit_depth) != bit_depth or not 1 <= bit_depth <= 16):
        raise PolarsegError(f"bit_depth must be an integer in 1..16 or None, got {bit_depth!r}")

    a = alpha[:, None, None]
    stack = i_arr[None] * (1.0 + rho[None] * np.cos(2.0 * a - 2.0 * phi[None]))

    if shifts is not None:
        sh = np.asarray(shifts, dtype=np.float64)
        if sh.shape != (alpha.size, 2) or not np.all(np.isfinite(sh)):
            raise PolarsegError(
                f"shifts must be finite with shape ({alpha.size}, 2), got {sh.shape}"
            )
        for k in range(alpha.size):
            if np.any(sh[k] != 0.0):
                stack[k] = ndimage.shift(stack[k], sh[k], order=3, mode="nearest")

    if noise_sigma > 0:
        gen = np.random.default_rng(rng)
        stack = stack + gen.normal(0.0, noise_sigma * full_scale, size=stack.shape)

    if bit_depth is None:
        return stack
    top = 2 ** int(bit_depth) - 1
    codes = np.clip(np.rint(stack / full_scale * top), 0, top)
    return codes.astype(np.uint8 if bit_depth <= 8 else np.uint16)


# --------------------------------------------------------------------------------------
# Materials and surface rendering
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Material:
    """Optical properties of a surface material for the diffuse polarisation model.

    Parameters
    ----------
    name : str
        Short identifier (used as the material name of a label).
    refractive_index : float
        Refractive index relative to air (dimensionless, > 1).
    depolarisation : float
        Fraction d in [0, 1) of the remitted light that leaves unpolarised (volume and
        sub-surface scattering, surface hairs/fibres); the Fresnel ρ is multiplied by
        ``1 − d``.
    roughness_deg : float
        Micro-roughness: standard deviation of the sub-pixel facet slope, as an angle in
        degrees (each slope component ``∂z/∂x``, ``∂z/∂y`` gets Gaussian noise of standard
        deviation ``tan(roughness_deg)``).
    description : str
        What the material stands for and why these values.
    """

    name: str
    refractive_index: float
    depolarisation: float
    roughness_deg: float
    description: str = ""

    def __post_init__(self) -> None:
        if not np.isfinite(self.refractive_index) or self.refractive_index <= 1.0:
            raise PolarsegError(f"refractive_index of {self.name!r} must be > 1")
        if not 0.0 <= self.depolarisation < 1.0:
            raise PolarsegError(f"depolarisation of {self.name!r} must be in [0, 1)")
        if not 0.0 <= self.roughness_deg < 90.0:
            raise PolarsegError(f"roughness_deg of {self.name!r} must be in [0, 90)")


#: Material library used by the scenes (plausible, not measured, values; see the
#: descriptions).
MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material(
            "matte_board",
            1.50,
            0.60,
            25.0,
            "matte painted board / paper background (cellulose, binder n ~ 1.5); strong "
            "volume scattering and a rough surface leave it almost unpolarised",
        ),
        Material(
            "natural_leaf",
            1.45,
            0.30,
            12.0,
            "leaf cuticle wax n ~ 1.42-1.47 (thesis default 1.45); epicuticular wax "
            "crystals, trichomes and veins roughen it, mesophyll scattering depolarises",
        ),
        Material(
            "plastic_leaf",
            1.54,
            0.15,
            6.0,
            "moulded PVC / polyethylene leaf (n ~ 1.51-1.55), pigmented, semi-gloss "
            "moulded surface: smoother and less depolarising than a real leaf",
        ),
        Material(
            "foliage",
            1.45,
            0.30,
            12.0,
            "natural foliage, same optics as natural_leaf",
        ),
        Material(
            "camouflage_net",
            1.58,
            0.10,
            15.0,
            "polyester fabric net with a PU/PVC coating (n ~ 1.55-1.60): the coating gives "
            "a smooth dielectric surface over the weave, so less volume scattering and "
            "depolarisation than foliage. (An uncoated net that depolarises as much as "
            "the leaves would have the same degree of polarisation as the foliage and "
            "no polarisation method could tell them apart.)",
        ),
        Material(
            "fruit_skin",
            1.42,
            0.20,
            6.0,
            "healthy fruit skin: smooth waxy cuticle over watery tissue (n ~ 1.38-1.45)",
        ),
        Material(
            "bruised_tissue",
            1.38,
            0.35,
            10.0,
            "bruised fruit before it shows: ruptured cells release juice (n ~ 1.35) into "
            "the tissue under the cuticle, the skin loses turgor and wrinkles finely; "
            "direction and size of these changes are plausible guesses, not measurements",
        ),
    )
}


class SurfaceRender(NamedTuple):
    """Pixel-level result of :func:`render_surface` (all arrays shape (H, W)).

    Attributes
    ----------
    intensity, dop, phase : ndarray
        Noise-free polarisation image: Î (fraction of full scale), ρ (dimensionless),
        φ (radians, [0, π)).
    zenith, azimuth : ndarray
        Macroscopic (pixel-averaged, roughness-free) surface normal: zenith in radians
        [0, π/2], azimuth ``atan2(n_row, n_col)`` in radians [0, 2π).
    labels : ndarray of int
        Majority material index of the pixel's sub-pixels.
    refractive_index : ndarray
        Refractive index of each pixel's label.
    albedo : ndarray, shape (K,)
        Albedo factor used for each material (NaN for materials absent from the map).
    """

    intensity: FloatArray
    dop: FloatArray
    phase: FloatArray
    zenith: FloatArray
    azimuth: FloatArray
    labels: NDArray[np.intp]
    refractive_index: FloatArray
    albedo: FloatArray


def _block_mean(a: NDArray, s: int) -> FloatArray:
    h, w = a.shape[0] // s, a.shape[1] // s
    return a.reshape(h, s, w, s).mean(axis=(1, 3))


def render_surface(
    slope_col: ArrayLike,
    slope_row: ArrayLike,
    material_map: ArrayLike,
    materials: Sequence[Material],
    *,
    supersample: int = 4,
    texture: ArrayLike | None = None,
    light_zenith_deg: float = 15.0,
    light_azimuth_deg: float = 225.0,
    ambient: float = 0.1,
    target_intensity: float | None = 0.4,
    albedo_groups: Sequence[int] | None = None,
    facets: int = 4,
    rng: np.random.Generator | int | None = None,
) -> SurfaceRender:
    """Render the noise-free polarisation image of a height-field surface.

    All inputs are given on the supersampled grid (``s·H × s·W``); outputs are per pixel.

    Parameters
    ----------
    slope_col, slope_row : array_like, shape (s·H, s·W)
        Height-field slopes ``∂z/∂col`` and ``∂z/∂row`` (z in pixel units), i.e. the
        macroscopic normal is ``(−slope_col, −slope_row, 1)`` normalised.
    material_map : array_like of int, shape (s·H, s·W)
        Index into ``materials`` of every sub-pixel.
    materials : sequence of Material
        The K materials.
    supersample : int, optional
        Sub-pixels per pixel side, s >= 1.
    texture : array_like, shape (s·H, s·W), optional
        Positive multiplicative albedo texture (default: uniform 1).
    light_zenith_deg : float, optional
        Angle between the distant light and the view axis, degrees.
    light_azimuth_deg : float, optional
        Azimuth of the direction towards the light, degrees, measured from the column
        axis towards the row axis (225° = from the upper left of the image).
    ambient : float, optional
        Ambient share of the illumination in [0, 1): shading is
        ``(1 − ambient) max(0, n·l) + ambient``.
    target_intensity : float or None, optional
        If given, each material's albedo is chosen so that its mean Î over its
        sub-pixels equals this value (fraction of full scale): matched albedo. If None,
        every albedo is 1.
    albedo_groups : sequence of int, optional
        One group number per material; materials of one group share a single albedo,
        calibrated on their combined sub-pixels (e.g. healthy and bruised skin of one
        fruit: same pigment, so no intensity edge between them; their mean Î then
        differ only by shading). Default: every material its own group.
    facets : int, optional
        Random micro-facets per sub-pixel (>= 1); a pixel averages ``s² · facets`` facets.
        More facets approach the many-facet limit of real micro-roughness, which lowers ρ
        at large zenith but leaves little random ρ on flat surfaces.
    rng : numpy.random.Generator or int or None, optional
        Source of the micro-facet slopes.

    Returns
    -------
    SurfaceRender
        Polarisation image, normals, labels, refractive index and albedos.

    Raises
    ------
    PolarsegError
        On mismatched shapes, a grid not divisible by ``supersample``, or material
        indices out of range.
    """
    p = np.asarray(slope_col, dtype=np.float64)
    q = np.asarray(slope_row, dtype=np.float64)
    mat = np.asarray(material_map)
    s = int(supersample)
    if s < 1:
        raise PolarsegError(f"supersample must be >= 1, got {supersample!r}")
    n_facets = int(facets)
    if n_facets < 1:
        raise PolarsegError(f"facets must be >= 1, got {facets!r}")
    if p.ndim != 2 or p.shape != q.shape or p.shape != mat.shape:
        raise PolarsegError("slope_col, slope_row and material_map must be 2-D, same shape")
    if p.shape[0] % s or p.shape[1] % s:
        raise PolarsegError(f"grid shape {p.shape} is not divisible by supersample={s}")
    if not np.issubdtype(mat.dtype, np.integer):
        raise PolarsegError("material_map must hold integers")
    k_mat = len(materials)
    if mat.size and (mat.min() < 0 or mat.max() >= k_mat):
        raise PolarsegError(f"material_map values must be in 0..{k_mat - 1}")
    if not 0.0 <= ambient < 1.0:
        raise PolarsegError(f"ambient must be in [0, 1), got {ambient!r}")
    groups = np.arange(k_mat) if albedo_groups is None else np.asarray(albedo_groups)
    if groups.shape != (k_mat,):
        raise PolarsegError(f"albedo_groups must have one entry per material ({k_mat})")
    tex = np.ones_like(p) if texture is None else np.asarray(texture, dtype=np.float64)
    if tex.shape != p.shape or np.any(tex <= 0):
        raise PolarsegError("texture must be positive with the shape of slope_col")
    gen = np.random.default_rng(rng)

    n_idx = np.array([m.refractive_index for m in materials])
    depol = np.array([m.depolarisation for m in materials])
    tan_rough = np.tan(np.deg2rad([m.roughness_deg for m in materials]))

    # Micro-roughness: `facets` random facet slopes per sub-pixel are added to the
    # macroscopic slope; every facet is shaded and polarised, and its Stokes vector
    # (s0, s1, s2) is accumulated.
    sig = tan_rough[mat]
    n_sub = n_idx[mat]
    keep = 1.0 - depol[mat]
    lz = np.deg2rad(light_zenith_deg)
    la = np.deg2rad(light_azimuth_deg)
    light = (np.sin(lz) * np.cos(la), np.sin(lz) * np.sin(la), np.cos(lz))
    s0 = np.zeros_like(p)
    s1 = np.zeros_like(p)
    s2 = np.zeros_like(p)
    for _ in range(n_facets):
        pf = p + sig * gen.standard_normal(p.shape)
        qf = q + sig * gen.standard_normal(p.shape)
        norm = np.sqrt(1.0 + pf**2 + qf**2)
        nx, ny, nz = -pf / norm, -qf / norm, 1.0 / norm
        lambert = np.clip(nx * light[0] + ny * light[1] + nz * light[2], 0.0, None)
        e0 = tex * ((1.0 - ambient) * lambert + ambient)
        rho_f = diffuse_dop_from_transmission(np.arccos(np.clip(nz, 0.0, 1.0)), n_sub) * keep
        two_phi = 2.0 * np.arctan2(ny, nx)
        s0 += e0
        s1 += e0 * rho_f * np.cos(two_phi)
        s2 += e0 * rho_f * np.sin(two_phi)

    # Albedo: every Stokes component is proportional to it.
    counts = np.bincount(mat.ravel(), minlength=k_mat)
    present = counts > 0
    albedo = np.where(present, 1.0, np.nan)
    if target_intensity is not None:
        sums = np.bincount(mat.ravel(), weights=s0.ravel() / n_facets, minlength=k_mat)
        for g in np.unique(groups):
            members = (groups == g) & present
            if members.any():
                albedo[members] = target_intensity * counts[members].sum() / sums[members].sum()
    scale = np.where(present, albedo, 0.0)[mat] / n_facets
    s0, s1, s2 = s0 * scale, s1 * scale, s2 * scale

    S0, S1, S2 = (_block_mean(c, s) for c in (s0, s1, s2))
    intensity = S0
    with np.errstate(invalid="ignore", divide="ignore"):
        dop = np.where(S0 > 0, np.hypot(S1, S2) / S0, 0.0)
    phase = np.mod(0.5 * np.arctan2(S2, S1), np.pi)

    # Macroscopic normal (no roughness), averaged over the pixel.
    mnorm = np.sqrt(1.0 + p**2 + q**2)
    mx, my, mz = (_block_mean(c, s) for c in (-p / mnorm, -q / mnorm, 1.0 / mnorm))
    mlen = np.sqrt(mx**2 + my**2 + mz**2)
    zenith = np.arccos(np.clip(mz / mlen, 0.0, 1.0))
    azimuth = np.mod(np.arctan2(my, mx), 2.0 * np.pi)

    frac = np.stack([_block_mean((mat == k).astype(np.float64), s) for k in range(k_mat)])
    labels = np.argmax(frac, axis=0).astype(np.intp)
    return SurfaceRender(
        intensity=intensity,
        dop=dop,
        phase=phase,
        zenith=zenith,
        azimuth=azimuth,
        labels=labels,
        refractive_index=n_idx[labels],
        albedo=albedo,
    )


# --------------------------------------------------------------------------------------
# Scene geometry (all on the supersampled grid, lengths in pixels)
# --------------------------------------------------------------------------------------


@dataclass
class _Grid:
    """Supersampled grid: sub-pixel centre coordinates in pixel units."""

    shape: tuple[int, int]  # pixel shape (H, W)
    s: int
    ys: FloatArray = field(init=False)
    xs: FloatArray = field(init=False)
    scale: float = field(init=False)  # lengths scale with min(H, W) / 120

    def __post_init__(self) -> None:
        h, w = self.shape
        self.ys = (np.arange(h * self.s) + 0.5) / self.s - 0.5
        self.xs = (np.arange(w * self.s) + 0.5) / self.s - 0.5
        self.scale = min(h, w) / 120.0

    @property
    def ss_shape(self) -> tuple[int, int]:
        return (self.shape[0] * self.s, self.shape[1] * self.s)


def _unit_field(rng: np.random.Generator, grid: _Grid, sigma_px: float) -> FloatArray:
    """Smoothed Gaussian random field with zero mean and unit standard deviation."""
    f = ndimage.gaussian_filter(
        rng.standard_normal(grid.ss_shape), sigma_px * grid.s, mode="reflect"
    )
    return (f - f.mean()) / f.std()


def _random_slopes(
    rng: np.random.Generator, grid: _Grid, sigma_px: float, rms_slope: float
) -> tuple[FloatArray, FloatArray]:
    """Slopes (∂z/∂col, ∂z/∂row) of a smooth random height field with given rms slope."""
    h = _unit_field(rng, grid, sigma_px)
    gy, gx = np.gradient(h)
    k = rms_slope / np.sqrt(0.5 * np.mean(gx**2 + gy**2))
    return k * gx, k * gy


@dataclass
class _Leaf:
    cy: float
    cx: float
    a: float  # half length, px
    b: float  # half width, px
    theta: float  # orientation of the long axis, radians
    tilt_u: float  # plane slope along the leaf
    tilt_v: float  # plane slope across the leaf
    curv_u: float  # z -= curv_u u^2
    curv_v: float  # z -= curv_v v^2
    fold: float  # z += fold |v| (smoothed): V-shaped midrib


def _random_leaf(
    rng: np.random.Generator,
    cy: float,
    cx: float,
    length: tuple[float, float],
    tilt_sd: float,
) -> _Leaf:
    a = rng.uniform(*length)
    b = a * rng.uniform(0.35, 0.5)
    edge = rng.uniform(0.2, 0.9) * rng.choice([1.0, -1.0], p=[0.7, 0.3])
    along = rng.uniform(-0.2, 0.5)
    return _Leaf(
        cy=cy,
        cx=cx,
        a=a,
        b=b,
        theta=rng.uniform(0.0, 2.0 * np.pi),
        tilt_u=rng.normal(0.0, tilt_sd),
        tilt_v=rng.normal(0.0, tilt_sd),
        curv_u=along / (2.0 * a),
        curv_v=edge / (2.0 * b),
        fold=rng.uniform(-0.25, 0.25),
    )


def _paint_leaf(
    p: FloatArray, q: FloatArray, mat: NDArray[np.intp], grid: _Grid, leaf: _Leaf, mid: int
) -> None:
    """Draw a leaf over what is there (painter's algorithm), in place."""
    r0 = np.searchsorted(grid.ys, leaf.cy - leaf.a)
    r1 = np.searchsorted(grid.ys, leaf.cy + leaf.a, side="right")
    c0 = np.searchsorted(grid.xs, leaf.cx - leaf.a)
    c1 = np.searchsorted(grid.xs, leaf.cx + leaf.a, side="right")
    if r1 <= r0 or c1 <= c0:
        return
    dy = grid.ys[r0:r1, None] - leaf.cy
    dx = grid.xs[None, c0:c1] - leaf.cx
    c, s = np.cos(leaf.theta), np.sin(leaf.theta)
    u = dx * c + dy * s
    v = -dx * s + dy * c
    half_width = leaf.b * np.clip(1.0 - (u / leaf.a) ** 2, 0.0, None) ** 0.7
    inside = (np.abs(u) < leaf.a) & (np.abs(v) < half_width)
    dz_du = leaf.tilt_u - 2.0 * leaf.curv_u * u
    dz_dv = leaf.tilt_v - 2.0 * leaf.curv_v * v + leaf.fold * np.tanh(v / 0.5)
    gx = dz_du * c - dz_dv * s
    gy = dz_du * s + dz_dv * c
    sub = (slice(r0, r1), slice(c0, c1))
    p[sub][inside] = gx[inside]
    q[sub][inside] = gy[inside]
    mat[sub][inside] = mid


# slope_col, slope_row, material map, materials, albedo group of each material
Geometry = tuple[FloatArray, FloatArray, NDArray[np.intp], list[Material], list[int]]


def _leaves_geometry(rng: np.random.Generator, grid: _Grid) -> Geometry:
    """Natural leaves (left) and plastic leaves (right) on a matte board."""
    h, w = grid.shape
    materials = [MATERIALS["matte_board"], MATERIALS["natural_leaf"], MATERIALS["plastic_leaf"]]
    # Background: a board with a slight tilt and gentle undulation.
    p, q = _random_slopes(rng, grid, sigma_px=10.0, rms_slope=0.04)
    p += rng.normal(0.0, 0.03)
    q += rng.normal(0.0, 0.03)
    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    # Leaves: identical shape statistics for both kinds (camouflage: only the material
    # differs); natural in the left ~55 %, plastic in the right ~55 %, overlapping.
    n_each = max(2, round(17 * grid.scale**2))
    leaves: list[tuple[_Leaf, int]] = []
    length = (15.0 * grid.scale, 24.0 * grid.scale)
    for mid, (x0, x1) in ((1, (0.05, 0.55)), (2, (0.45, 0.95))):
        for _ in range(n_each):
            cy = rng.uniform(0.08, 0.92) * h
            cx = rng.uniform(x0, x1) * w
            leaves.append((_random_leaf(rng, cy, cx, length, tilt_sd=0.4), mid))
    order = rng.permutation(len(leaves))
    for i in order:
        leaf, mid = leaves[i]
        _paint_leaf(p, q, mat, grid, leaf, mid)
    # Fine waviness (veins, uneven lamina), same statistics on every leaf.
    wx, wy = _random_slopes(rng, grid, sigma_px=2.0, rms_slope=0.12)
    on_leaf = mat > 0
    p[on_leaf] += wx[on_leaf]
    q[on_leaf] += wy[on_leaf]
    return p, q, mat, materials, [0, 1, 2]


def _camouflage_geometry(rng: np.random.Generator, grid: _Grid) -> Geometry:
    """A draped, folded camouflage net with garnish cut-outs over dense foliage."""
    h, w = grid.shape
    materials = [MATERIALS["foliage"], MATERIALS["camouflage_net"]]
    # Foliage: a deep layer of randomly oriented leaves over a chaotic base layer.
    p, q = _random_slopes(rng, grid, sigma_px=3.0, rms_slope=0.5)
    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    n_leaves = max(10, round(260 * grid.scale**2))
    length = (6.0 * grid.scale, 12.0 * grid.scale)
    for _ in range(n_leaves):
        leaf = _random_leaf(
            rng, rng.uniform(-0.05, 1.05) * h, rng.uniform(-0.05, 1.05) * w, length, 0.45
        )
        _paint_leaf(p, q, mat, grid, leaf, 0)
    # Net: an irregular blob centred right of the middle.
    cy = h * rng.uniform(0.4, 0.6)
    cx = w * rng.uniform(0.55, 0.65)
    ry, rx = 0.36 * h, 0.30 * w
    r = np.hypot((grid.ys[:, None] - cy) / ry, (grid.xs[None, :] - cx) / rx)
    net = r + 0.18 * _unit_field(rng, grid, 7.0 * grid.scale) < 1.0
    # Garnish cut-outs: small holes through which the foliage shows.
    n_holes = max(3, round(30 * grid.scale**2))
    yy, xx = grid.ys[:, None], grid.xs[None, :]
    for _ in range(n_holes):
        hy = cy + rng.uniform(-1.0, 1.0) * ry
        hx = cx + rng.uniform(-1.0, 1.0) * rx
        a, b = rng.uniform(1.2, 3.0, size=2) * grid.scale
        t = rng.uniform(0.0, np.pi)
        u = (xx - hx) * np.cos(t) + (yy - hy) * np.sin(t)
        v = -(xx - hx) * np.sin(t) + (yy - hy) * np.cos(t)
        net &= (u / a) ** 2 + (v / b) ** 2 >= 1.0
    # Net surface: large folds (sum of a few sinusoids) plus garnish flaps.
    fp = np.zeros(grid.ss_shape)
    fq = np.zeros(grid.ss_shape)
    for _ in range(3):
        wavelength = rng.uniform(18.0, 40.0) * grid.scale
        direction = rng.uniform(0.0, np.pi)
        slope_amp = rng.uniform(0.3, 0.6)
        kx, ky = np.cos(direction), np.sin(direction)
        ph = rng.uniform(0.0, 2.0 * np.pi)
        arg = 2.0 * np.pi * (xx * kx + yy * ky) / wavelength + ph
        fp += slope_amp * kx * np.cos(arg)
        fq += slope_amp * ky * np.cos(arg)
    gx, gy = _random_slopes(rng, grid, sigma_px=1.5, rms_slope=0.4)
    p = np.where(net, fp + gx, p)
    q = np.where(net, fq + gy, q)
    mat[net] = 1
    return p, q, mat, materials, [0, 1]


def _fruit_geometry(rng: np.random.Generator, grid: _Grid) -> Geometry:
    """Close-up of a large near-spherical fruit with a bruised patch (inspection crop).

    As in the thesis's 240 × 240 fruit sections, the fruit fills the frame: the task is
    healthy against bruised skin, not fruit against background (which intensity alone
    separates trivially).
    """
    h, w = grid.shape
    materials = [MATERIALS["fruit_skin"], MATERIALS["bruised_tissue"]]
    yy, xx = grid.ys[:, None], grid.xs[None, :]

    # The frame's corners stay inside the fruit's outline (zenith there ~ 50-65°).
    radius = 0.62 * np.hypot(h, w) * rng.uniform(0.97, 1.03)
    cy = h * (0.5 + rng.uniform(-0.05, 0.05))
    cx = w * (0.5 + rng.uniform(-0.05, 0.05))
    ry = radius * rng.uniform(0.94, 1.0)
    rx = radius * rng.uniform(0.94, 1.0)
    dy, dx = (yy - cy) / ry, (xx - cx) / rx
    r2 = dx**2 + dy**2
    # Ellipsoid z = R sqrt(1 - r²).
    root = np.sqrt(np.clip(1.0 - r2, 1e-3, None))
    p = -radius * dx / rx / root
    q = -radius * dy / ry / root
    # Uneven shape (a fruit is not a sphere) and skin texture.
    ux, uy = _random_slopes(rng, grid, sigma_px=8.0 * grid.scale, rms_slope=0.08)
    tx, ty = _random_slopes(rng, grid, sigma_px=1.5, rms_slope=0.05)
    p += ux + tx
    q += uy + ty

    # Bruise: an irregular, slightly dented patch away from the frame centre.
    direction = rng.uniform(0.0, 2.0 * np.pi)
    offset = rng.uniform(0.18, 0.28) * min(h, w)
    by = cy + offset * np.sin(direction)
    bx = cx + offset * np.cos(direction)
    rb = rng.uniform(0.20, 0.26) * min(h, w)
    rr = np.hypot(yy - by, xx - bx)
    bruise = rr / rb + 0.15 * _unit_field(rng, grid, 3.0 * grid.scale) < 1.0
    depth = 0.08 * rb
    sd = 0.6 * rb
    # Height -depth·exp(-r²/2sd²): its slope is depth·exp(...)·(x - bx)/sd² (and rows).
    dent = depth * np.exp(-(rr**2) / (2.0 * sd**2)) / sd**2
    p += dent * (xx - bx)
    q += dent * (yy - by)

    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    mat[bruise] = 1
    # Healthy and bruised skin share one albedo: the bruise does not show yet.
    return p, q, mat, materials, [0, 0]


_GEOMETRIES: dict[str, Callable[[np.random.Generator, _Grid], Geometry]] = {
    "leaves": _leaves_geometry,
    "camouflage": _camouflage_geometry,
    "fruit": _fruit_geometry,
}

_SUPERSAMPLE = 4
_FACETS = 4
_LIGHT_ZENITH_DEG = 15.0
_LIGHT_AZIMUTH_DEG = 225.0
_AMBIENT = 0.1
_TARGET_INTENSITY = 0.4
_TEXTURE_STD = 0.05
_TEXTURE_SIGMA_PX = 1.0


# --------------------------------------------------------------------------------------
# Scenes
# --------------------------------------------------------------------------------------


@dataclass
class SyntheticScene:
    """A rendered angle stack with its ground truth.

    Attributes
    ----------
    stack : ndarray, shape (N, H, W)
        The images through the polariser (uint16 / uint8 when quantised, else float64;
        full scale = 1.0 or ``2**bit_depth − 1``).
    angles : ndarray, shape (N,)
        Polariser angles in radians.
    labels : ndarray of int, shape (H, W)
        Ground-truth material of each pixel, 0..K−1 (majority of its sub-pixels).
    material_names : list of str
        Name of each label.
    intensity, dop, phase : ndarray, shape (H, W)
        Noise-free polarisation image: Î (fraction of full scale), ρ, φ (radians, [0, π)).
        The stack is rendered from exactly these (before shifts, noise, quantisation).
    zenith, azimuth : ndarray, shape (H, W)
        True macroscopic surface normal: zenith radians in [0, π/2], azimuth
        ``atan2(n_row, n_col)`` radians in [0, 2π) (φ equals it mod π where the surface
        is smooth).
    refractive_index : ndarray, shape (H, W)
        Refractive index of each pixel's material.
    params : dict
        Every parameter used: scene name, shape, angles in degrees, bit depth, noise,
        seed, shifts, supersampling, light, ambient, target intensity, texture, and for
        each material its refractive index, depolarisation, roughness and albedo.
    """

    stack: NDArray
    angles: FloatArray
    labels: NDArray[np.intp]
    material_names: list[str]
    intensity: FloatArray
    dop: FloatArray
    phase: FloatArray
    zenith: FloatArray
    azimuth: FloatArray
    refractive_index: FloatArray
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def angles_deg(self) -> FloatArray:
        """Polariser angles in degrees (exactly as given to :func:`make_scene`)."""
        given = self.params.get("angles_deg")
        if given is not None and len(given) == len(self.angles):
            return np.asarray(given, dtype=np.float64)
        return np.rad2deg(self.angles)


def make_scene(
    name: str,
    *,
    shape: tuple[int, int] = (120, 130),
    angles_deg: Sequence[float] = DEFAULT_ANGLES_DEG,
    bit_depth: int | None = 12,
    noise_sigma: float = DEFAULT_NOISE_SIGMA,
    seed: int = 0,
    shifts: ArrayLike | None = None,
) -> SyntheticScene:
    """Render one of the thesis-like test scenes with ground truth.

    Parameters
    ----------
    name : str
        One of :data:`SCENES`:

        - ``"leaves"``: natural (left) and plastic (right) leaves on a matte board
          (labels background, natural_leaf, plastic_leaf), thesis figure 5.1/5.5;
        - ``"camouflage"``: a folded camouflage net with garnish cut-outs over dense
          foliage (labels foliage, camouflage_net), thesis figure 5.7;
        - ``"fruit"``: close-up of a near-spherical fruit filling the frame, with a
          bruised, slightly dented patch (labels fruit, bruise), thesis section 5.3.
    shape : tuple of int, optional
        Image size (H, W) in pixels, each >= 32. Shapes scale with ``min(H, W) / 120``.
    angles_deg : sequence of float, optional
        Polariser angles in degrees (default 0..180 in 30° steps).
    bit_depth : int or None, optional
        Quantisation (default 12 bits, returned as uint16); None gives float64.
    noise_sigma : float, optional
        Gaussian noise standard deviation as a fraction of full scale (default 0.3 %;
        the mean intensity of every material is 40 % of full scale).
    seed : int, optional
        Seed; the same seed gives identical output. Geometry, texture, roughness and
        noise use separate streams, so changing the noise leaves the scene unchanged.
    shifts : array_like, shape (N, 2), optional
        Per-frame translations (rows, cols) in pixels, see :func:`render_stack`; the
        ground truth stays in the unshifted frame.

    Returns
    -------
    SyntheticScene

    Raises
    ------
    PolarsegError
        For an unknown ``name``, a bad ``shape`` or the errors of :func:`render_stack`.

    Examples
    --------
    >>> scene = make_scene("fruit", shape=(64, 72))
    >>> scene.stack.shape, scene.stack.dtype.name, scene.material_names
    ((7, 64, 72), 'uint16', ['fruit', 'bruise'])
    """
    if name not in _GEOMETRIES:
        raise PolarsegError(f"name must be one of {', '.join(SCENES)}; got {name!r}")
    try:
        h, w = (int(v) for v in shape)
    except (TypeError, ValueError) as exc:
        raise PolarsegError(f"shape must be two integers (H, W), got {shape!r}") from exc
    if h < 32 or w < 32:
        raise PolarsegError(f"shape must be at least (32, 32), got {shape!r}")
    angles = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    if angles.ndim != 1 or angles.size == 0 or not np.all(np.isfinite(angles)):
        raise PolarsegError("angles_deg must be a non-empty sequence of finite numbers")

    geo_rng, tex_rng, rough_rng, noise_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)
    )
    grid = _Grid((h, w), _SUPERSAMPLE)
    p, q, mat, materials, groups = _GEOMETRIES[name](geo_rng, grid)
    texture = np.clip(1.0 + _TEXTURE_STD * _unit_field(tex_rng, grid, _TEXTURE_SIGMA_PX), 0.5, None)
    surf = render_surface(
        p,
        q,
        mat,
        materials,
        supersample=_SUPERSAMPLE,
        texture=texture,
        light_zenith_deg=_LIGHT_ZENITH_DEG,
        light_azimuth_deg=_LIGHT_AZIMUTH_DEG,
        ambient=_AMBIENT,
        target_intensity=_TARGET_INTENSITY,
        albedo_groups=groups,
        facets=_FACETS,
        rng=rough_rng,
    )
    stack = render_stack(
        surf.intensity,
        surf.dop,
        surf.phase,
        angles,
        noise_sigma=noise_sigma,
        bit_depth=bit_depth,
        full_scale=1.0,
        rng=noise_rng,
        shifts=shifts,
    )
    label_names = {
        "matte_board": "background",
        "natural_leaf": "natural",
        "plastic_leaf": "plastic",
        "camouflage_net": "net",
        "fruit_skin": "fruit",
        "bruised_tissue": "bruise",
    }
    names = [label_names.get(m.name, m.name) for m in materials]
    params: dict[str, Any] = {
        "scene": name,
        "shape": [h, w],
        "angles_deg": [float(a) for a in np.asarray(angles_deg, dtype=np.float64)],
        "bit_depth": bit_depth,
        "full_scale": 1.0,
        "noise_sigma": float(noise_sigma),
        "seed": seed,
        "shifts": None if shifts is None else np.asarray(shifts, dtype=float).tolist(),
        "supersample": _SUPERSAMPLE,
        "facets_per_subpixel": _FACETS,
        "light_zenith_deg": _LIGHT_ZENITH_DEG,
        "light_azimuth_deg": _LIGHT_AZIMUTH_DEG,
        "ambient": _AMBIENT,
        "target_intensity": _TARGET_INTENSITY,
        "texture_std": _TEXTURE_STD,
        "texture_sigma_px": _TEXTURE_SIGMA_PX,
        "materials": {
            label: {
                "material": m.name,
                "refractive_index": m.refractive_index,
                "depolarisation": m.depolarisation,
                "roughness_deg": m.roughness_deg,
                "albedo": float(a),
                "description": m.description,
            }
            for label, m, a in zip(names, materials, surf.albedo, strict=True)
        },
    }
    return SyntheticScene(
        stack=stack,
        angles=angles,
        labels=surf.labels,
        material_names=names,
        intensity=surf.intensity,
        dop=surf.dop,
        phase=surf.phase,
        zenith=surf.zenith,
        azimuth=surf.azimuth,
        refractive_index=surf.refractive_index,
        params=params,
    )


def scribble_strokes(
    truth: NDArray, seed: int = 0, per_material: int = 6, length: int = 16
) -> NDArray[np.int32]:
    """Short straight strokes (1 px wide) inside each material, as a user would paint.

    The fixed, small set of strokes used to evaluate scribble-guided segmentation
    (``Pipeline.scribble_result``) on the synthetic scenes: ``per_material`` strokes of
    ``length`` pixels at random positions and angles (seeded), each at least 2 px
    inside its material of ``truth``; stroke value = material index + 1, 0 elsewhere.
    About 1-2 % of the pixels of a 120 × 130 scene.
    """
    rng = np.random.default_rng(seed)
    strokes = np.zeros(truth.shape, dtype=np.int32)
    for i, material in enumerate(np.unique(truth)):
        inner = ndimage.binary_erosion(truth == material, iterations=2)
        points = np.argwhere(inner)
        drawn = 0
        for _ in range(1000):
            if drawn == per_material:
                break
            p = points[rng.integers(len(points))]
            angle = rng.uniform(0, np.pi)
            t = np.arange(length) - length / 2
            rr = np.round(p[0] + t * np.sin(angle)).astype(int)
            cc = np.round(p[1] + t * np.cos(angle)).astype(int)
            inside = (rr >= 0) & (rr < truth.shape[0]) & (cc >= 0) & (cc < truth.shape[1])
            if not inside.all() or not inner[rr, cc].all():
                continue
            strokes[rr, cc] = i + 1
            drawn += 1
    return strokes
