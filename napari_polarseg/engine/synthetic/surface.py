"""Materials and the supersampled, faceted rendering of a surface (module docstring of
:mod:`.scenes`, "Rendering model").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import PolarsegError
from .optics import FloatArray, diffuse_dop_from_transmission


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
        Material(
            "silk_leaf",
            1.60,
            0.45,
            16.0,
            "artificial 'silk' leaf of woven polyester fabric (fibre n ~ 1.57-1.65): the "
            "weave and fibre bundles scatter in the volume and roughen the surface, so it "
            "depolarises more than a moulded plastic leaf",
        ),
        Material(
            "coated_board",
            1.52,
            0.10,
            8.0,
            "board under a roller-applied lacquer coat (acrylic/alkyd binder, n ~ 1.5, "
            "little volume scattering): its micro-relief is an orange peel of rms slope "
            "0.50 and correlation 3 px (layouts.MICRO_TEXTURES)",
        ),
        Material(
            "stippled_coating",
            1.52,
            0.10,
            8.0,
            "the coated_board lacquer (same n, depolarisation and facet roughness) "
            "applied with a stipple brush: a fine relief, correlation 1 px, rms slope "
            "0.55 so that its mean degree of polarisation matches the board's; only the "
            "polarisation texture tells them apart",
        ),
        Material(
            "spatter_coating",
            1.52,
            0.10,
            8.0,
            "the coated_board lacquer as a spatter finish: relief of correlation 2 px, rms "
            "slope 0.51 (mean degree of polarisation matched to the board's)",
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
    light_zenith_deg, light_azimuth_deg, ambient : float, optional
        The distant light: its angle from the view axis and its azimuth (degrees; from
        the column axis towards the row axis, 225° = from the upper left), and the
        ambient share of the illumination in [0, 1): shading is
        ``(1 − ambient) max(0, n·l) + ambient``.
    target_intensity : float or None, optional
        Matched albedo: each albedo group's mean Î over its sub-pixels is this value
        (fraction of full scale); None: every albedo is 1.
    albedo_groups : sequence of int, optional
        One group number per material; the materials of a group share one albedo,
        calibrated on their combined sub-pixels (healthy and bruised skin of one fruit:
        no intensity edge, mean Î differing by shading only). Default: a group each.
    facets : int, optional
        Random micro-facets per sub-pixel (>= 1; a pixel averages ``s² · facets``): more
        approach real micro-roughness, lowering ρ at large zenith but leaving little
        random ρ on flat surfaces.
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
    checks = (supersample, facets, ambient, albedo_groups, texture)
    p, q, mat, tex, groups = _checked_surface(
        slope_col, slope_row, material_map, len(materials), *checks
    )
    s, n_facets, k_mat = int(supersample), int(facets), len(materials)
    gen = np.random.default_rng(rng)

    light = (light_zenith_deg, light_azimuth_deg, ambient)
    s0, s1, s2 = _facet_stokes(p, q, mat, materials, tex, light, n_facets, gen)

    # Albedo: every Stokes component is proportional to it.
    albedo, present = _albedo(mat, s0, groups, k_mat, target_intensity, n_facets)
    scale = np.where(present, albedo, 0.0)[mat] / n_facets
    return _pixel_render((s0 * scale, s1 * scale, s2 * scale), p, q, mat, s, materials, albedo)


def _pixel_render(
    stokes: tuple[FloatArray, FloatArray, FloatArray],
    p: FloatArray,
    q: FloatArray,
    mat: NDArray,
    s: int,
    materials: Sequence[Material],
    albedo: FloatArray,
) -> SurfaceRender:
    """The :class:`SurfaceRender` of sub-pixel Stokes sums (s0, s1, s2) with the albedo
    applied: pixel means, the polarisation image, normals and majority labels."""
    S0, S1, S2 = (_block_mean(c, s) for c in stokes)
    with np.errstate(invalid="ignore", divide="ignore"):
        dop = np.where(S0 > 0, np.hypot(S1, S2) / S0, 0.0)
    phase = np.mod(0.5 * np.arctan2(S2, S1), np.pi)

    # Macroscopic normal (no roughness), averaged over the pixel.
    zenith, azimuth = _pixel_normal(p, q, s)

    frac = np.stack([_block_mean((mat == k).astype(np.float64), s) for k in range(len(materials))])
    labels = np.argmax(frac, axis=0).astype(np.intp)
    n_idx = np.array([m.refractive_index for m in materials])
    return SurfaceRender(
        intensity=S0,
        dop=dop,
        phase=phase,
        zenith=zenith,
        azimuth=azimuth,
        labels=labels,
        refractive_index=n_idx[labels],
        albedo=albedo,
    )


def _checked_surface(
    slope_col: ArrayLike,
    slope_row: ArrayLike,
    material_map: ArrayLike,
    k_mat: int,
    supersample: int,
    facets: int,
    ambient: float,
    albedo_groups: Sequence[int] | None,
    texture: ArrayLike | None,
) -> tuple[FloatArray, FloatArray, NDArray, FloatArray, NDArray]:
    """(slopes p, q, material map, texture, albedo groups) of :func:`render_surface`,
    after checking its arguments."""
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
    return p, q, mat, tex, groups


def _facet_stokes(
    p: FloatArray,
    q: FloatArray,
    mat: NDArray,
    materials: Sequence[Material],
    tex: FloatArray,
    light: tuple[float, float, float],
    n_facets: int,
    gen: np.random.Generator,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Stokes sums (s0, s1, s2) over ``n_facets`` rough facets per sub-pixel, unit albedo.

    ``light``: zenith and azimuth (degrees) of the distant light and the ambient term.
    """
    light_zenith_deg, light_azimuth_deg, ambient = light
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

    return s0, s1, s2


def _albedo(
    mat: NDArray,
    s0: FloatArray,
    groups: NDArray,
    k_mat: int,
    target_intensity: float | None,
    n_facets: int,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Albedo of every material (NaN if absent) and which are present: one per group,
    calibrated so that the group's mean Î is ``target_intensity`` (1 when None)."""
    counts = np.bincount(mat.ravel(), minlength=k_mat)
    present = counts > 0
    albedo = np.where(present, 1.0, np.nan)
    if target_intensity is not None:
        sums = np.bincount(mat.ravel(), weights=s0.ravel() / n_facets, minlength=k_mat)
        for g in np.unique(groups):
            members = (groups == g) & present
            if members.any():
                albedo[members] = target_intensity * counts[members].sum() / sums[members].sum()
    return albedo, present


def _pixel_normal(p: FloatArray, q: FloatArray, s: int) -> tuple[FloatArray, FloatArray]:
    """Zenith and azimuth (radians) of the macroscopic normal averaged over each pixel."""
    mnorm = np.sqrt(1.0 + p**2 + q**2)
    mx, my, mz = (_block_mean(c, s) for c in (-p / mnorm, -q / mnorm, 1.0 / mnorm))
    mlen = np.sqrt(mx**2 + my**2 + mz**2)
    zenith = np.arccos(np.clip(mz / mlen, 0.0, 1.0))
    azimuth = np.mod(np.arctan2(my, mx), 2.0 * np.pi)

    return zenith, azimuth
