"""Further scene layouts for the benchmark families (diffuse regime; lengths in pixels,
angles in radians): many leaves of 2-3 materials scattered over a board, and blobs that
differ from the board only by their micro-texture.

Both follow the conventions of :mod:`napari_polarseg.engine.synthetic.geometry`: a
function ``(rng, grid, object_size=None)`` returning a
:class:`~napari_polarseg.engine.synthetic.geometry.SceneGeometry` on the supersampled
grid, with one instance per object. As in the thesis scenes, the materials differ only
in refractive index, depolarisation and micro-roughness or micro-texture; every material
is rendered at the same mean intensity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .geometry import (
    GeometryFunction,
    Grid,
    SceneGeometry,
    checked_object_size,
    paint_leaf,
    random_leaf,
    random_slopes,
)
from .optics import FloatArray
from .surface import MATERIALS

#: Leaf materials of ``scattered_leaves``: the first 2 or 3 are used (a draw per scene).
LEAF_MATERIALS: tuple[str, ...] = ("natural_leaf", "plastic_leaf", "silk_leaf")

#: Materials of ``texture_patches``: the board, then 1 or 2 blob materials (a draw per
#: scene). All have the same refractive index, depolarisation and facet roughness.
PATCH_MATERIALS: tuple[str, ...] = ("coated_board", "stippled_coating", "spatter_coating")

#: Micro-texture of the ``texture_patches`` materials: (rms slope of each component,
#: dimensionless; correlation length of the height field, px). It is a random height
#: field on the supersampled grid added to the board's shape, so it varies from pixel to
#: pixel. The correlation lengths differ; the rms slopes are set so that every material
#: has the same mean ρ (within about 2 %; a finer relief is averaged more within a
#: pixel), so the local spread of ρ and φ tells them apart, not their level. Under the
#: oblique light the relief's shading also gives each material its own intensity texture
#: (local spread of Î about 10-15 %, larger for the finer relief): physics, not avoided.
MICRO_TEXTURES: dict[str, tuple[float, float]] = {
    "coated_board": (0.50, 3.0),
    "stippled_coating": (0.55, 1.0),
    "spatter_coating": (0.51, 2.0),
}

#: Default object sizes as a fraction of min(H, W): leaf length of ``scattered_leaves``,
#: blob diameter of ``texture_patches``.
DEFAULT_LEAF_LENGTH = 0.30
DEFAULT_BLOB_DIAMETER = 0.15


@dataclass(frozen=True)
class Blob:
    """An irregular blob: a circle of ``radius`` (px) at (cy, cx) px whose boundary radius
    is modulated by angular harmonics 2, 3, ... (relative amplitudes, phases in radians).
    """

    cy: float
    cx: float
    radius: float
    amplitudes: tuple[float, ...]
    phases: tuple[float, ...]


def random_blob(rng: np.random.Generator, cy: float, cx: float, radius: float) -> Blob:
    """A random :class:`Blob` centred at (cy, cx) px with mean radius ``radius`` px:
    harmonics 2-5 with amplitudes falling from 0.12 (ellipticity) to 0.06."""
    amplitudes = rng.normal(0.0, 1.0, size=4) * np.array([0.12, 0.10, 0.08, 0.06])
    phases = rng.uniform(0.0, 2.0 * np.pi, size=4)
    return Blob(cy, cx, radius, tuple(amplitudes.tolist()), tuple(phases.tolist()))


def paint_blob(
    mat: NDArray[np.intp], instances: NDArray[np.int32], grid: Grid, blob: Blob, mid: int, iid: int
) -> None:
    """Draw a blob of material ``mid`` and instance ``iid`` over what is there, in place."""
    amps = np.asarray(blob.amplitudes)
    extent = blob.radius * (1.0 + np.abs(amps).sum())
    r0 = np.searchsorted(grid.ys, blob.cy - extent)
    r1 = np.searchsorted(grid.ys, blob.cy + extent, side="right")
    c0 = np.searchsorted(grid.xs, blob.cx - extent)
    c1 = np.searchsorted(grid.xs, blob.cx + extent, side="right")
    if r1 <= r0 or c1 <= c0:
        return
    dy = grid.ys[r0:r1, None] - blob.cy
    dx = grid.xs[None, c0:c1] - blob.cx
    angle = np.arctan2(dy, dx)[..., None]
    orders = np.arange(2, 2 + amps.size)
    wobble = np.cos(orders * angle + np.asarray(blob.phases)) @ amps
    boundary = blob.radius * np.clip(1.0 + wobble, 0.3, None)
    inside = np.hypot(dy, dx) < boundary
    sub = (slice(r0, r1), slice(c0, c1))
    mat[sub][inside] = mid
    instances[sub][inside] = iid


def _board(rng: np.random.Generator, grid: Grid) -> tuple[FloatArray, FloatArray]:
    """Slopes of a board with a slight tilt and gentle undulation (as in ``leaves``)."""
    p, q = random_slopes(rng, grid, sigma_px=10.0, rms_slope=0.04)
    p += rng.normal(0.0, 0.03)
    q += rng.normal(0.0, 0.03)
    return p, q


def scattered_leaves_geometry(
    rng: np.random.Generator, grid: Grid, object_size: float | None = None
) -> SceneGeometry:
    """Leaves of 2 or 3 materials (natural, plastic, silk) mixed all over a matte board.

    20-60 leaves at the default size, centred anywhere (also just outside the frame),
    touching and overlapping in random order, any orientation, plane tilts of standard
    deviation 0.5 (about 27°), bent and folded as in ``leaves``; the same shape
    statistics and fine waviness for every material, materials dealt out in turn.

    ``object_size``: the mean leaf length in px (None: 0.3 × min(H, W)); lengths vary
    ±23 % around it. The number of leaves scales with ``1 / object_size²`` (at least 20),
    so the covered share stays about that of the default.
    """
    h, w = grid.shape
    n_kinds = int(rng.integers(2, 4))
    materials = [MATERIALS["matte_board"], *(MATERIALS[m] for m in LEAF_MATERIALS[:n_kinds])]
    p, q = _board(rng, grid)
    default = DEFAULT_LEAF_LENGTH * min(h, w)
    size = default if object_size is None else checked_object_size(object_size)
    n_leaves = max(20, round(int(rng.integers(20, 61)) * (default / size) ** 2))
    kinds = 1 + rng.permutation(np.arange(n_leaves) % n_kinds)
    length = (size * 15.0 / 39.0, size * 24.0 / 39.0)  # half lengths, mean size / 2
    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    instances = np.zeros(grid.ss_shape, dtype=np.int32)
    for i in range(n_leaves):
        cy, cx = rng.uniform(-0.05, 1.05) * h, rng.uniform(-0.05, 1.05) * w
        leaf = random_leaf(rng, cy, cx, length, tilt_sd=0.5)
        paint_leaf(p, q, mat, grid, leaf, int(kinds[i]), instances, i + 1)
    # Fine waviness (veins, uneven lamina), same statistics on every leaf.
    wx, wy = random_slopes(rng, grid, sigma_px=2.0, rms_slope=0.12)
    on_leaf = mat > 0
    p[on_leaf] += wx[on_leaf]
    q[on_leaf] += wy[on_leaf]
    info = {"leaves": n_leaves, "leaf_length_px": size}
    return SceneGeometry(p, q, mat, materials, list(range(n_kinds + 1)), instances, info)


def texture_patches_geometry(
    rng: np.random.Generator, grid: Grid, object_size: float | None = None
) -> SceneGeometry:
    """Irregular blobs of 1 or 2 coatings on a coated board, told apart by texture only.

    Board and blobs share one refractive index, depolarisation and facet roughness
    (:data:`PATCH_MATERIALS`); each material has its own micro-relief
    (:data:`MICRO_TEXTURES`: rms slope and correlation length at the 1-3 px scale), laid
    over the board's common tilt and undulation. The blobs (flush with the board) cover
    about 40-65 % of the frame, overlapping in random order; with two blob materials
    they are dealt out in turn.

    ``object_size``: the mean blob diameter in px (None: 0.15 × min(H, W)); radii vary
    ±25 % and the number of blobs scales with ``1 / object_size²``.
    """
    h, w = grid.shape
    n_classes = int(rng.integers(2, 4))
    materials = [MATERIALS[m] for m in PATCH_MATERIALS[:n_classes]]
    p, q = _board(rng, grid)
    default = DEFAULT_BLOB_DIAMETER * min(h, w)
    size = default if object_size is None else checked_object_size(object_size)
    density = rng.uniform(0.6, 1.0)  # summed blob area / frame area
    n_blobs = max(3, round(density * h * w / (np.pi * (size / 2.0) ** 2)))
    kinds = 1 + rng.permutation(np.arange(n_blobs) % (n_classes - 1))
    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    instances = np.zeros(grid.ss_shape, dtype=np.int32)
    for i in range(n_blobs):
        cy, cx = rng.uniform(-0.05, 1.05) * h, rng.uniform(-0.05, 1.05) * w
        blob = random_blob(rng, cy, cx, 0.5 * size * rng.uniform(0.75, 1.25))
        paint_blob(mat, instances, grid, blob, int(kinds[i]), i + 1)
    for k, m in enumerate(materials):
        rms_slope, corr_px = MICRO_TEXTURES[m.name]
        tx, ty = random_slopes(rng, grid, sigma_px=corr_px, rms_slope=rms_slope)
        sel = mat == k
        p[sel] += tx[sel]
        q[sel] += ty[sel]
    textures = {m.name: list(MICRO_TEXTURES[m.name]) for m in materials}
    info = {"blobs": n_blobs, "blob_diameter_px": size, "micro_textures": textures}
    return SceneGeometry(p, q, mat, materials, list(range(n_classes)), instances, info)


#: The layouts of this module by scene name.
LAYOUT_GEOMETRIES: dict[str, GeometryFunction] = {
    "scattered_leaves": scattered_leaves_geometry,
    "texture_patches": texture_patches_geometry,
}
