"""Scene geometry on the supersampled grid: height-field slopes, material maps and object
instances of the leaves, camouflage and fruit scenes (lengths in pixels, angles in
radians).

A geometry function takes ``(rng, grid, object_size=None)`` and returns a
:class:`SceneGeometry`; it still unpacks as the older 5-tuple
``(slope_col, slope_row, material_map, materials, albedo_groups)``. The further layouts
of the benchmark families live in :mod:`napari_polarseg.engine.synthetic.layouts`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from ..errors import PolarsegError
from .optics import FloatArray
from .surface import MATERIALS, Material


@dataclass
class Grid:
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


def unit_field(rng: np.random.Generator, grid: Grid, sigma_px: float) -> FloatArray:
    """Smoothed Gaussian random field with zero mean and unit standard deviation."""
    f = ndimage.gaussian_filter(
        rng.standard_normal(grid.ss_shape), sigma_px * grid.s, mode="reflect"
    )
    return (f - f.mean()) / f.std()


def random_slopes(
    rng: np.random.Generator, grid: Grid, sigma_px: float, rms_slope: float
) -> tuple[FloatArray, FloatArray]:
    """Slopes (∂z/∂col, ∂z/∂row) of a smooth random height field on the supersampled grid.

    The field is :func:`unit_field` with correlation ``sigma_px`` (px); its gradient is
    scaled so that each slope component has the root-mean-square ``rms_slope``
    (dimensionless, tan of the tilt).
    """
    h = unit_field(rng, grid, sigma_px)
    gy, gx = np.gradient(h)
    k = rms_slope / np.sqrt(0.5 * np.mean(gx**2 + gy**2))
    return k * gx, k * gy


@dataclass
class Leaf:
    """One leaf: an outline tapering to both tips, a curved, tilted, folded lamina."""

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


def random_leaf(
    rng: np.random.Generator,
    cy: float,
    cx: float,
    length: tuple[float, float],
    tilt_sd: float,
) -> Leaf:
    """A random :class:`Leaf` centred at (cy, cx) px: half length uniform in ``length``
    (px), width 0.35–0.5 of the length, any orientation, plane slopes of standard
    deviation ``tilt_sd``, random bending and midrib fold."""
    a = rng.uniform(*length)
    b = a * rng.uniform(0.35, 0.5)
    edge = rng.uniform(0.2, 0.9) * rng.choice([1.0, -1.0], p=[0.7, 0.3])
    along = rng.uniform(-0.2, 0.5)
    return Leaf(
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


def paint_leaf(
    p: FloatArray,
    q: FloatArray,
    mat: NDArray[np.intp],
    grid: Grid,
    leaf: Leaf,
    mid: int,
    instances: NDArray[np.int32] | None = None,
    iid: int = 0,
) -> None:
    """Draw a leaf of material ``mid`` over what is there (painter's algorithm), in place;
    with ``instances``, its sub-pixels also get the instance id ``iid``."""
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
    if instances is not None:
        instances[sub][inside] = iid


@dataclass
class SceneGeometry:
    """What a geometry function draws, on the supersampled grid (``s·H × s·W``).

    Attributes
    ----------
    slope_col, slope_row : ndarray of float
        Height-field slopes ``∂z/∂col`` and ``∂z/∂row`` (z in px, dimensionless).
    material_map : ndarray of int
        Index into ``materials`` of every sub-pixel.
    materials : list of Material
        The scene's materials; index 0 is the background.
    albedo_groups : list of int
        Albedo group of each material (see :func:`.surface.render_surface`).
    instances : ndarray of int32
        Object instance of every sub-pixel: 0 = background (material 0), 1.. = objects;
        every object is of one material.
    info : dict
        Layout parameters worth recording (object size in px, counts, textures).

    Unpacking gives the older 5-tuple ``(slope_col, slope_row, material_map, materials,
    albedo_groups)``, so callers written before instances keep working.
    """

    slope_col: FloatArray
    slope_row: FloatArray
    material_map: NDArray[np.intp]
    materials: list[Material]
    albedo_groups: list[int]
    instances: NDArray[np.int32]
    info: dict[str, Any] = field(default_factory=dict)

    def __iter__(self) -> Iterator[Any]:
        """The older 5-tuple (slopes, material map, materials, albedo groups)."""
        return iter(
            (self.slope_col, self.slope_row, self.material_map, self.materials, self.albedo_groups)
        )


#: A scene's geometry function: (geometry rng, grid, object size in px or None).
GeometryFunction = Callable[[np.random.Generator, Grid, float | None], SceneGeometry]


def checked_object_size(object_size: float) -> float:
    """``object_size`` (px) as a float, if it is finite and at least 4 px."""
    try:
        size = float(object_size)
    except (TypeError, ValueError) as exc:
        raise PolarsegError(f"object_size must be a number of pixels, got {object_size!r}") from exc
    if not np.isfinite(size) or size < 4.0:
        raise PolarsegError(f"object_size must be a finite size >= 4 px, got {object_size!r}")
    return size


def pixel_instances(
    instances: NDArray, material_map: NDArray, labels: NDArray, s: int
) -> NDArray[np.int32]:
    """Instance map on the pixel grid, consistent with the pixel ``labels``.

    Each pixel takes the most frequent instance id among its ``s × s`` sub-pixels whose
    material is the pixel's label (the majority material); ties go to the smaller id.
    So an instance never straddles two labels and 0 (background) is exactly label 0
    where material 0 is the background's only material. Ids are renumbered 1..n in
    their original order (objects no pixel keeps are dropped).
    """
    h, w = labels.shape
    lab = np.repeat(np.repeat(labels, s, axis=0), s, axis=1)
    ids = np.where(np.asarray(material_map) == lab, np.asarray(instances, dtype=np.int32), -1)
    blocks = np.sort(ids.reshape(h, s, w, s).transpose(0, 2, 1, 3).reshape(h, w, s * s), axis=-1)
    # Sorted: equal ids form runs; each entry's count is its run's length.
    change = blocks[..., 1:] != blocks[..., :-1]
    edge = np.ones(blocks.shape[:2] + (1,), dtype=bool)
    idx = np.arange(s * s, dtype=np.int32)
    first = np.maximum.accumulate(np.where(np.concatenate([edge, change], -1), idx, 0), -1)
    last_rev = np.where(np.concatenate([change, edge], -1), idx, s * s)[..., ::-1]
    counts = np.minimum.accumulate(last_rev, -1)[..., ::-1] - first + 1
    counts[blocks < 0] = 0
    best = np.take_along_axis(blocks, np.argmax(counts, axis=-1)[..., None], axis=-1)[..., 0]
    kept, inverse = np.unique(best, return_inverse=True)
    renumber = np.arange(kept.size) + (1 if kept[0] > 0 else 0)
    return renumber[inverse].reshape(h, w).astype(np.int32)


def _no_object_size(name: str, object_size: float | None) -> None:
    if object_size is not None:
        raise PolarsegError(f"the {name} scene has no object_size knob (got {object_size!r})")


def leaves_geometry(
    rng: np.random.Generator, grid: Grid, object_size: float | None = None
) -> SceneGeometry:
    """Natural leaves (left) and plastic leaves (right) on a matte board.

    ``object_size``: the mean leaf length in px (None: 39 px × min(H, W) / 120); lengths
    vary ±23 % around it and the number of leaves scales with ``1 / object_size²`` so
    the covered share stays that of the default.
    """
    h, w = grid.shape
    materials = [MATERIALS["matte_board"], MATERIALS["natural_leaf"], MATERIALS["plastic_leaf"]]
    # Background: a board with a slight tilt and gentle undulation.
    p, q = random_slopes(rng, grid, sigma_px=10.0, rms_slope=0.04)
    p += rng.normal(0.0, 0.03)
    q += rng.normal(0.0, 0.03)
    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    instances = np.zeros(grid.ss_shape, dtype=np.int32)
    # Leaves: identical shape statistics for both kinds (camouflage: only the material
    # differs); natural in the left ~55 %, plastic in the right ~55 %, overlapping.
    default_length = 39.0 * grid.scale
    if object_size is None:
        n_each = max(2, round(17 * grid.scale**2))
        length = (15.0 * grid.scale, 24.0 * grid.scale)
    else:
        size = checked_object_size(object_size)
        n_each = max(2, round(17 * grid.scale**2 * (default_length / size) ** 2))
        length = (size * 15.0 / 39.0, size * 24.0 / 39.0)
    leaves: list[tuple[Leaf, int]] = []
    for mid, (x0, x1) in ((1, (0.05, 0.55)), (2, (0.45, 0.95))):
        for _ in range(n_each):
            cy = rng.uniform(0.08, 0.92) * h
            cx = rng.uniform(x0, x1) * w
            leaves.append((random_leaf(rng, cy, cx, length, tilt_sd=0.4), mid))
    order = rng.permutation(len(leaves))
    for i in order:
        leaf, mid = leaves[i]
        paint_leaf(p, q, mat, grid, leaf, mid, instances, int(i) + 1)
    # Fine waviness (veins, uneven lamina), same statistics on every leaf.
    wx, wy = random_slopes(rng, grid, sigma_px=2.0, rms_slope=0.12)
    on_leaf = mat > 0
    p[on_leaf] += wx[on_leaf]
    q[on_leaf] += wy[on_leaf]
    info = {"leaves": 2 * n_each, "leaf_length_px": float(np.mean(length)) * 2.0}
    return SceneGeometry(p, q, mat, materials, [0, 1, 2], instances, info)


def camouflage_geometry(
    rng: np.random.Generator, grid: Grid, object_size: float | None = None
) -> SceneGeometry:
    """A draped, folded camouflage net with garnish cut-outs over dense foliage (one
    instance: the net). No ``object_size`` knob (it must be None)."""
    _no_object_size("camouflage", object_size)
    h, w = grid.shape
    materials = [MATERIALS["foliage"], MATERIALS["camouflage_net"]]
    # Foliage: a deep layer of randomly oriented leaves over a chaotic base layer.
    p, q = random_slopes(rng, grid, sigma_px=3.0, rms_slope=0.5)
    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    n_leaves = max(10, round(260 * grid.scale**2))
    length = (6.0 * grid.scale, 12.0 * grid.scale)
    for _ in range(n_leaves):
        leaf = random_leaf(
            rng, rng.uniform(-0.05, 1.05) * h, rng.uniform(-0.05, 1.05) * w, length, 0.45
        )
        paint_leaf(p, q, mat, grid, leaf, 0)
    # Net: an irregular blob centred right of the middle.
    cy = h * rng.uniform(0.4, 0.6)
    cx = w * rng.uniform(0.55, 0.65)
    ry, rx = 0.36 * h, 0.30 * w
    r = np.hypot((grid.ys[:, None] - cy) / ry, (grid.xs[None, :] - cx) / rx)
    net = r + 0.18 * unit_field(rng, grid, 7.0 * grid.scale) < 1.0
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
    gx, gy = random_slopes(rng, grid, sigma_px=1.5, rms_slope=0.4)
    p = np.where(net, fp + gx, p)
    q = np.where(net, fq + gy, q)
    mat[net] = 1
    return SceneGeometry(p, q, mat, materials, [0, 1], net.astype(np.int32))


def fruit_geometry(
    rng: np.random.Generator, grid: Grid, object_size: float | None = None
) -> SceneGeometry:
    """Close-up of a large near-spherical fruit with a bruised patch (inspection crop).

    As in the thesis's 240 × 240 fruit sections, the fruit fills the frame: the task is
    healthy against bruised skin, not fruit against background (which intensity alone
    separates trivially). One instance: the bruise. No ``object_size`` knob (it must be
    None).
    """
    _no_object_size("fruit", object_size)
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
    ux, uy = random_slopes(rng, grid, sigma_px=8.0 * grid.scale, rms_slope=0.08)
    tx, ty = random_slopes(rng, grid, sigma_px=1.5, rms_slope=0.05)
    p += ux + tx
    q += uy + ty

    # Bruise: an irregular, slightly dented patch away from the frame centre.
    direction = rng.uniform(0.0, 2.0 * np.pi)
    offset = rng.uniform(0.18, 0.28) * min(h, w)
    by = cy + offset * np.sin(direction)
    bx = cx + offset * np.cos(direction)
    rb = rng.uniform(0.20, 0.26) * min(h, w)
    rr = np.hypot(yy - by, xx - bx)
    bruise = rr / rb + 0.15 * unit_field(rng, grid, 3.0 * grid.scale) < 1.0
    depth = 0.08 * rb
    sd = 0.6 * rb
    # Height -depth·exp(-r²/2sd²): its slope is depth·exp(...)·(x - bx)/sd² (and rows).
    dent = depth * np.exp(-(rr**2) / (2.0 * sd**2)) / sd**2
    p += dent * (xx - bx)
    q += dent * (yy - by)

    mat = np.zeros(grid.ss_shape, dtype=np.intp)
    mat[bruise] = 1
    # Healthy and bruised skin share one albedo: the bruise does not show yet.
    return SceneGeometry(p, q, mat, materials, [0, 0], bruise.astype(np.int32))


#: The thesis scenes' geometry functions (every layout: ``scenes.GEOMETRIES``).
THESIS_GEOMETRIES: dict[str, GeometryFunction] = {
    "leaves": leaves_geometry,
    "camouflage": camouflage_geometry,
    "fruit": fruit_geometry,
}
