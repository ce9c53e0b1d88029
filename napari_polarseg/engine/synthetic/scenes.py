"""Synthetic polarisation angle stacks with ground truth.

Renders the grey images a camera records through a linear polariser at several angles,
from physics, for scenes modelled on the thesis experiments (chapter 5): natural against
plastic leaves, a camouflage net in foliage, and a bruised fruit; and for further layouts
of the benchmark families (:data:`LAYOUTS`: leaves of 2-3 materials scattered over a
board, blobs told apart by micro-texture only). Every scene comes with its ground truth:
material labels, object instances, the noise-free polarisation image (Î, ρ, φ), the true
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
  (:func:`~napari_polarseg.engine.synthetic.optics.diffuse_dop_from_transmission`). This route is
  deliberately independent of
  the closed form (corrected eq. 3.13) in :mod:`napari_polarseg.engine.physics.fresnel`, so the
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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from ..errors import PolarsegError
from .geometry import THESIS_GEOMETRIES, GeometryFunction, Grid, pixel_instances, unit_field
from .layouts import LAYOUT_GEOMETRIES
from .optics import FloatArray, render_stack
from .surface import Material, SurfaceRender, render_surface

__all__ = [
    "DEFAULT_ANGLES_DEG",
    "DEFAULT_NOISE_SIGMA",
    "GEOMETRIES",
    "LAYOUTS",
    "SCENES",
    "SyntheticScene",
    "make_scene",
    "scribble_strokes",
]

#: The thesis scenes (bundled as sample data; tests and benchmarks loop over them).
SCENES: tuple[str, ...] = ("leaves", "camouflage", "fruit")

#: Further layouts of the benchmark families (:mod:`.layouts`), also names for
#: :func:`make_scene`.
LAYOUTS: tuple[str, ...] = ("scattered_leaves", "texture_patches")

#: Geometry function of every name :func:`make_scene` accepts (:data:`SCENES` and
#: :data:`LAYOUTS`).
GEOMETRIES: dict[str, GeometryFunction] = {**THESIS_GEOMETRIES, **LAYOUT_GEOMETRIES}

#: Default polariser angles in degrees: 7 angles 0..180 in 30° steps (thesis section 5.1).
DEFAULT_ANGLES_DEG: tuple[float, ...] = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0)

#: Default Gaussian read noise, as a fraction of full scale (0.3 %).
DEFAULT_NOISE_SIGMA: float = 0.003

#: Rendering settings of :func:`make_scene` (module docstring, "Rendering model"):
#: sub-pixels per pixel side, facets per sub-pixel, the light (degrees), the ambient
#: term, the mean Î every material is calibrated to, and the albedo texture.
SUPERSAMPLE = 4
FACETS = 4
LIGHT_ZENITH_DEG = 15.0
LIGHT_AZIMUTH_DEG = 225.0
AMBIENT = 0.1
TARGET_INTENSITY = 0.4
TEXTURE_STD = 0.05
TEXTURE_SIGMA_PX = 1.0


#: Label names of the materials (a scene's ``material_names``).
LABEL_NAMES = {
    "matte_board": "background",
    "natural_leaf": "natural",
    "plastic_leaf": "plastic",
    "camouflage_net": "net",
    "fruit_skin": "fruit",
    "bruised_tissue": "bruise",
    "silk_leaf": "silk",
    "coated_board": "background",
    "stippled_coating": "stippled",
    "spatter_coating": "spatter",
}


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
    instances : ndarray of int32, shape (H, W)
        Object instance of each pixel: 0 = background (the label-0 material: board,
        foliage, healthy fruit skin), 1..n = the objects (each leaf, the net, the
        bruise, each blob); the majority instance of the sub-pixels of the pixel's
        label, so each instance lies inside one label.
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
        seed, shifts, supersampling, light, ambient, target intensity, texture, object
        size (px, None = the layout's default), the layout's own record (``"layout"``:
        counts, sizes, micro-textures), and for each material its refractive index,
        depolarisation, roughness and albedo.
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
    instances: NDArray[np.int32]
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
    object_size: float | None = None,
) -> SyntheticScene:
    """Render one of the thesis-like test scenes or benchmark layouts with ground truth.

    Parameters
    ----------
    name : str
        One of :data:`SCENES`, the thesis scenes:

        - ``"leaves"``: natural (left) and plastic (right) leaves on a matte board
          (labels background, natural_leaf, plastic_leaf), thesis figure 5.1/5.5;
        - ``"camouflage"``: a folded camouflage net with garnish cut-outs over dense
          foliage (labels foliage, camouflage_net), thesis figure 5.7;
        - ``"fruit"``: close-up of a near-spherical fruit filling the frame, with a
          bruised, slightly dented patch (labels fruit, bruise), thesis section 5.3.

        or one of :data:`LAYOUTS` (:mod:`.layouts`): ``"scattered_leaves"`` (2-3 kinds of
        leaves all over a board), ``"texture_patches"`` (blobs that differ from the
        board by their micro-texture only).
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
    object_size : float, optional
        Object size in px (>= 4) of ``"leaves"`` and the :data:`LAYOUTS`: mean leaf length
        or blob diameter; the number of objects scales to keep the covered share. None:
        the default (thesis scenes unchanged); the other scenes reject a value.

    Returns
    -------
    SyntheticScene

    Raises
    ------
    PolarsegError
        For an unknown ``name``, a bad ``shape`` or ``object_size``, or the errors of
        :func:`render_stack`.

    Examples
    --------
    >>> scene = make_scene("fruit", shape=(64, 72))
    >>> scene.stack.shape, scene.stack.dtype.name, scene.material_names
    ((7, 64, 72), 'uint16', ['fruit', 'bruise'])
    """
    h, w, angles = _scene_grid(name, shape, angles_deg)
    # Geometry, texture, roughness and noise streams.
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)]
    surf, materials, instances, layout = _scene_surface(name, (h, w), object_size, rngs[:3])
    sensor = {"noise_sigma": noise_sigma, "bit_depth": bit_depth, "full_scale": 1.0}
    stack = render_stack(
        surf.intensity, surf.dop, surf.phase, angles, rng=rngs[3], shifts=shifts, **sensor
    )
    params = _scene_params(name, (h, w), angles_deg, bit_depth, noise_sigma, seed, shifts)
    params.update(object_size=None if object_size is None else float(object_size), layout=layout)
    return _scene(surf, stack, angles, materials, instances, params)


def _scene(
    surf: SurfaceRender,
    stack: NDArray,
    angles: FloatArray,
    materials: list[Material],
    instances: NDArray[np.int32],
    params: dict[str, Any],
) -> SyntheticScene:
    """The :class:`SyntheticScene` of a rendered surface and its stack; adds the
    materials' record to ``params``."""
    names = [LABEL_NAMES.get(m.name, m.name) for m in materials]
    params["materials"] = _material_params(names, materials, surf.albedo)
    truth = ("intensity", "dop", "phase", "zenith", "azimuth", "refractive_index")
    return SyntheticScene(
        stack=stack,
        angles=angles,
        labels=surf.labels,
        material_names=names,
        instances=instances,
        params=params,
        **{key: getattr(surf, key) for key in truth},
    )


def scribble_strokes(
    truth: NDArray, seed: int = 0, per_material: int = 6, length: int = 16
) -> NDArray[np.int32]:
    """Short straight strokes (1 px wide) inside each material, as a user would paint.

    The fixed, small set of strokes used to evaluate scribble-guided segmentation
    (``classifier.scribbles.scribble_result``) on the synthetic scenes: ``per_material`` strokes of
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


def _scene_grid(
    name: str, shape: tuple[int, int], angles_deg: Sequence[float]
) -> tuple[int, int, FloatArray]:
    """(H, W, angles in radians) of :func:`make_scene`, after checking its arguments."""
    if name not in GEOMETRIES:
        raise PolarsegError(f"name must be one of {', '.join(GEOMETRIES)}; got {name!r}")
    try:
        h, w = (int(v) for v in shape)
    except (TypeError, ValueError) as exc:
        raise PolarsegError(f"shape must be two integers (H, W), got {shape!r}") from exc
    if h < 32 or w < 32:
        raise PolarsegError(f"shape must be at least (32, 32), got {shape!r}")
    angles = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    if angles.ndim != 1 or angles.size == 0 or not np.all(np.isfinite(angles)):
        raise PolarsegError("angles_deg must be a non-empty sequence of finite numbers")
    return h, w, angles


def _scene_surface(
    name: str,
    shape: tuple[int, int],
    object_size: float | None,
    rngs: Sequence[np.random.Generator],
) -> tuple[SurfaceRender, list[Material], NDArray[np.int32], dict[str, Any]]:
    """The scene's geometry and albedo texture, rendered (:func:`.surface.render_surface`),
    with its materials, pixel instances and the layout's record; ``rngs``: the geometry,
    texture and roughness streams."""
    geo_rng, tex_rng, rough_rng = rngs
    h, w = shape
    grid = Grid((h, w), SUPERSAMPLE)
    geo = GEOMETRIES[name](geo_rng, grid, object_size)
    p, q, mat, materials, groups = geo
    texture = np.clip(1.0 + TEXTURE_STD * unit_field(tex_rng, grid, TEXTURE_SIGMA_PX), 0.5, None)
    surf = render_surface(
        p,
        q,
        mat,
        materials,
        supersample=SUPERSAMPLE,
        texture=texture,
        light_zenith_deg=LIGHT_ZENITH_DEG,
        light_azimuth_deg=LIGHT_AZIMUTH_DEG,
        ambient=AMBIENT,
        target_intensity=TARGET_INTENSITY,
        albedo_groups=groups,
        facets=FACETS,
        rng=rough_rng,
    )
    instances = pixel_instances(geo.instances, mat, surf.labels, SUPERSAMPLE)
    return surf, materials, instances, geo.info


def _scene_params(
    name: str,
    shape: tuple[int, int],
    angles_deg: Sequence[float],
    bit_depth: int | None,
    noise_sigma: float,
    seed: int | None,
    shifts: Any,
) -> dict[str, Any]:
    """The ``params`` record of a scene, without its materials."""
    h, w = shape
    return {
        "scene": name,
        "shape": [h, w],
        "angles_deg": [float(a) for a in np.asarray(angles_deg, dtype=np.float64)],
        "bit_depth": bit_depth,
        "full_scale": 1.0,
        "noise_sigma": float(noise_sigma),
        "seed": seed,
        "shifts": None if shifts is None else np.asarray(shifts, dtype=float).tolist(),
        "supersample": SUPERSAMPLE,
        "facets_per_subpixel": FACETS,
        "light_zenith_deg": LIGHT_ZENITH_DEG,
        "light_azimuth_deg": LIGHT_AZIMUTH_DEG,
        "ambient": AMBIENT,
        "target_intensity": TARGET_INTENSITY,
        "texture_std": TEXTURE_STD,
        "texture_sigma_px": TEXTURE_SIGMA_PX,
    }


def _material_params(
    names: list[str], materials: list[Material], albedo: Sequence[float]
) -> dict[str, dict[str, Any]]:
    """Per label, its material's parameters and albedo (``params["materials"]``)."""
    return {
        label: {
            "material": m.name,
            "refractive_index": m.refractive_index,
            "depolarisation": m.depolarisation,
            "roughness_deg": m.roughness_deg,
            "albedo": float(a),
            "description": m.description,
        }
        for label, m, a in zip(names, materials, albedo, strict=True)
    }
