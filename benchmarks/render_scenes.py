"""Render new polarised material scenes with Mitsuba 3 (benchmark tool only).

Makes held-out scenes the same way as the 24 shared ones in
``shared/data/rendered/`` (see its README): Mitsuba 3.9.1, variant
``llvm_ad_spectral_polarized``, a ``stokes`` integrator around a ``path`` integrator
with 5 bounces, ``pplastic`` materials, spheres, boxes and upright panels on a
finite floor, an unpolarised constant sky plus a directional sun, and a polarisation
camera's four images (polariser at 0/45/90/135 degrees from the image's column axis
towards its row axis) as 12-bit counts with Poisson shot noise and 2-count read noise.
Each ``scene_<seed>.npz`` has the shared files' keys and dtypes: ``stack`` uint16
(4, 240, 320), ``angles`` float64, ``labels`` uint8 (0 sky, 1 floor material, 2 and up
the objects' materials: label = material + 1) and ``materials`` (JSON text of the
scene's parameters, with ``"layout"``), plus ``instances`` uint16 (240, 320): 0 sky
and floor, i + 1 on object i of the JSON's ``objects``, rendered like the labels (one
jittered sample per pixel, an id instead of a material).

Layouts (``--layout``; each draws its parameters from the seed with its own sampler):

- ``objects`` (default): the shared set's scenes, 4-8 spheres, boxes and panels of
  two object materials (:func:`sample_objects`). A seed draws exactly the parameters
  and stack it drew before layouts existed (only ``"layout"`` is added to the JSON).
- ``small`` ("many small objects", :func:`sample_small`): 20-60 flat elliptic leaves
  (Mitsuba ``disk`` scaled to aspect 1.5-3) of 2-3 object materials, tilted 0-60
  degrees, lying on the floor or up to 0.06 above it, touching and overlapping in a
  patch covering 65-90 % of the frame; each leaf's unoccluded projection is 0.2-2 %
  of the frame (``"share"``). The object materials share one albedo and differ in
  ior, in Beckmann alpha or in both (``"differ"``). Camera elevation 60-80 degrees.
- ``textured`` ("texture-defined materials", :func:`sample_textured`): 4-8 spheres,
  boxes and panels (r 0.5-1.0) of 2-3 object materials with one albedo, ior and alpha
  that differ only in a normal map (Mitsuba ``normalmap`` around the pplastic, an
  in-memory ``mi.Bitmap`` made by :func:`texture_normals`, tiled so that a texel is
  half a pixel on screen): one smooth, one fine (bumps 1-3 px), a third coarse
  (4-8 px) or grooved (1-2 px across, 10-20 px along).

In every new-layout scene each object material it drew covers at least 1 % of the
frame; a draw that misses it is redrawn (attempt 1, 2, ... from the same seed, stored
as ``"attempt"``). ``objects`` scenes are never redrawn (their seeds must keep their
scenes); the progress line says when one of their materials is under 1 %.

This is a benchmark tool, not part of the package: Mitsuba is installed separately,
outside the project's venv, and CI never runs it::

    python3.11 -m venv ../render-venv            # any venv outside the project
    ../render-venv/bin/pip install mitsuba==3.9.1 numpy
    apt-get install libllvm19                    # the LLVM Dr.Jit compiles with (below)
    ../render-venv/bin/python benchmarks/render_scenes.py --seeds 100-123 \\
        --out benchmarks/renders [--layout objects|small|textured] [--spp 256] \\
        [--threads N] [--stats] [--from-json PATH] [--two-materials]

``--two-materials`` renders only the seeds whose objects all draw one material (the
floor's and one more, as the shared set's two-material scenes were drawn; ``objects``
only). ``--threads N`` limits Dr.Jit's thread pool (``drjit.set_thread_count``; Dr.Jit
1.5 of Mitsuba 3.9.1 reads no environment variable for it), default one per core.
``--stats`` prints per label the share, mean 0-degree count, DoLP mean, its spread
(standard deviation and local deviation from the 3 x 3 mean) and AoLP. The render sets
the benchmarks read, their seeds and folders are ``materials.RENDER_SETS``. The
layouts' sets, at the default 256 spp (on one Dr.Jit thread of a 2-core machine
shared with other work, ``nice -n 10 ... --threads 1``: ``small`` 20-43 s a scene,
``textured`` 15-25 s, ``objects`` 11-19 s, all five sets 23 minutes; well under the
90 s a scene that would have called for ``--spp 64``)::

    render_scenes.py --layout small --seeds 5000-5023 --out benchmarks/renders_small_dev
    render_scenes.py --layout textured --seeds 6000-6011 \\
        --out benchmarks/renders_textured_dev
    render_scenes.py --layout small --seeds 5100-5111 --out benchmarks/renders_small_test
    render_scenes.py --layout textured --seeds 6100-6111 \\
        --out benchmarks/renders_textured_test
    render_scenes.py --layout objects --seeds 4000-4011 \\
        --out benchmarks/renders_objects_fresh

Mitsuba's LLVM backend needs an LLVM it can compile with; on this Debian image the
system's LLVM 15 fails on AVX-512 ("Cannot select: fminimum"), so install ``libllvm19``
(apt) and this script points ``DRJIT_LIBLLVM_PATH`` at it when it is there.

Calibration: ``--from-json PATH --compare [--sun-irradiance E]`` re-renders a shared
scene from its JSON and prints label agreement and per-label mean 0-degree counts,
DoLP and AoLP against the shared file. The camera (distance, horizontal field of view,
look-at height), floor size, box and panel geometry were fitted (Nelder-Mead) on the
pixel agreement of label maps of 19 shared scenes: about 0.97 on average, the rest
being edge pixels. The exposure rule (99.5th percentile of the four images = 3000
counts) and the shot-noise gain (variance 0.3 x mean count) were read off the shared
stacks' statistics. The sun/sky ratio is not in the shared JSON; it was fitted per
scene (0.6-3.9). The Stokes sign convention and the microfacet distribution (Beckmann,
not the README's GGX) were chosen by matching per-pixel S1/S0, S2/S0 and per-label
DoLP and AoLP of shared scenes 0, 1 and 3. Scene parameters for new seeds follow the
README's distributions; the ranges it does not give (object positions, sizes,
rot/tilt, sun vector, azimuth) were read off the 24 shared scenes' JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np

LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"
if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(LLVM19):
    os.environ["DRJIT_LIBLLVM_PATH"] = LLVM19

VARIANT = "llvm_ad_spectral_polarized"
LABEL_VARIANT = "llvm_ad_rgb"
WIDTH, HEIGHT = 320, 240
ANGLES = np.array([0.0, 45.0, 90.0, 135.0])
MAX_DEPTH = 5

# Calibrated against shared scenes (see the module docstring).
FOV_DEG = 42.59  # horizontal field of view
CAM_DIST = 8.21  # camera distance from the look-at point
TARGET_Z = 0.391  # height of the look-at point above the origin
FLOOR_HALF = 6.37  # the floor is a square of side 2 * FLOOR_HALF
BOX_HALF = 1.0  # box half-side, in units of its r
PANEL_HALF_W = 1.25  # panel half-width, in units of its r
PANEL_HALF_H = 1.25  # panel half-height, in units of its r
PANEL_Z = 1.25  # panel centre height, in units of its r
SKY_RADIANCE = 1.0
# Sun irradiance relative to the sky radiance. The shared JSON does not record it (it
# is not |sun|): fitted per shared scene it spans 0.6-3.9 (median 1.6), so new scenes
# draw it log-uniformly from SUN_RANGE and store it as "sun_irradiance"; scenes without
# it (the shared ones) use SUN_DEFAULT unless --sun-irradiance gives it.
SUN_RANGE = (0.6, 4.0)
SUN_DEFAULT = 1.6
S2_SIGN = 1.0  # sign that turns Mitsuba's S2 into the shared files' convention
EXPOSURE_PERCENTILE = 99.5
EXPOSURE_TARGET = 3000.0
FULL_SCALE = 4095
# The shared README says GGX, but the shared stacks' polarisation matches pplastic's
# default Beckmann distribution (per-label DoLP within 0.005; GGX is off by up to 0.04).
MICROFACET = "beckmann"
ELECTRONS_PER_COUNT = 10.0 / 3.0  # shared stacks: shot-noise variance = 0.3 * mean count
READ_NOISE = 2.0

# Ranges the README gives, and those read off the shared scenes' JSON.
IOR_RANGES = ((1.30, 1.42), (1.45, 1.60), (1.65, 1.90))
ALPHA_RANGE = (0.05, 0.6)
ALBEDO_RANGE = (0.2, 0.8)
N_OBJECTS = (4, 8)
KINDS = ("sphere", "box", "panel")
XY_RANGE = (-2.6, 2.6)
SIZE_RANGE = (0.35, 0.9)
ROT_RANGE = (0.0, 180.0)
TILT_RANGE = (-35.0, 35.0)
ELEVATION_RANGE = (25.0, 65.0)
AZIMUTH_RANGE = (-40.0, 40.0)

#: The scene layouts (``--layout``); ``objects`` is the shared set's.
LAYOUTS = ("objects", "small", "textured")
#: Second entropy word of a new layout's generator, so that its seeds draw scenes
#: independent of the other layouts' (``objects`` keeps ``default_rng(seed)``).
LAYOUT_STREAMS = {"small": 1, "textured": 2}
#: Object materials per scene in the new layouts (the floor's comes on top).
N_OBJECT_MATERIALS = (2, 3)
FLOOR_IOR_RANGE = (IOR_RANGES[0][0], IOR_RANGES[-1][1])
#: Every object material a scene drew must cover this share of the frame in its labels
#: (new layouts: redrawn with the next attempt otherwise).
MIN_MATERIAL_SHARE = 0.01
MAX_ATTEMPTS = 20

# Layout "small": 20-60 flat leaves (elliptic disks) lying on or just above the floor.
N_LEAVES = (20, 60)
LEAF_SHARE = (0.002, 0.02)  # unoccluded projected area of one leaf, share of the frame
PATCH_RANGE = (0.65, 0.9)  # the patch the leaves lie in, as a share of the frame
LEAF_DENSITY = 0.8  # aimed-at sum of the leaves' shares / the patch's share
# A leaf's target share is LEAF_SHARE[1] * exp(-U(0, w)), log-uniform over a range
# reaching down to LEAF_SHARE[1] * exp(-w); w in LEAF_WIDTH is the widest range whose
# mean share still makes the aimed-at density (0.3-2 % for 60 leaves on 0.65 of the
# frame, 1.5-2 % when too few leaves to reach it).
LEAF_WIDTH = (0.3, float(np.log(0.02 / 0.003)))
LEAF_GROWTH = 2.0  # largest leaf radius over its frontal estimate (edge-on leaves)
LEAF_REDRAWS = 20  # redraws of the orientation of a leaf still under LEAF_SHARE[0]
LEAF_ASPECT = (1.5, 3.0)  # long / short semi-axis
LEAF_TILT = (0.0, 60.0)
LEAF_LIFT = (0.0, 0.06)  # gap under a leaf's lowest point (1 px is about 0.02 here)
LEAF_OUTLINE = 64  # outline points for the projected area
SMALL_ELEVATION_RANGE = (60.0, 80.0)
# Alpha bins, so that materials told apart by roughness are (pairwise) a bin apart.
ALPHA_BINS = ((0.05, 0.12), (0.18, 0.30), (0.40, 0.60))
DIFFER = ("ior", "alpha", "both")

# Layout "textured": objects with one ior, alpha and albedo, normal-mapped textures.
TEXTURED_SIZE_RANGE = (0.5, 1.0)
TEXTURED_IOR_RANGE = (1.40, 1.75)
TEXTURED_ALPHA_RANGE = (0.05, 0.3)
TEX_SIZE = 512  # normal map texels per side (periodic, tiled)
TEXEL_PX = 0.5  # texel size on screen, in pixels, at the object's distance (frontal)
TEXTURE_SLOPE = (12.0, 25.0)  # RMS slope of the height field, degrees
# Bump width on screen (pixels) along u and v; "grooved" is fine along one axis only.
TEXTURE_FEATURES = {
    "fine": ((1.0, 3.0), None),
    "coarse": ((4.0, 8.0), None),
    "grooved": ((1.0, 2.0), (10.0, 20.0)),
}
LABEL_SCALE = 4.0  # label render: a shape's albedo is its label / LABEL_SCALE
INSTANCE_SCALE = 256.0  # instance render: an object's albedo is its id / INSTANCE_SCALE


def sample_scene(seed: int, layout: str = "objects", attempt: int = 0) -> dict:
    """The scene parameters of one seed (and attempt) of a layout, with ``"layout"``.

    ``objects`` draws exactly what it drew before layouts existed (one attempt only);
    the others redraw with ``attempt`` + 1 when a material is too small (see
    :func:`accepted_scene`)."""
    if layout not in LAYOUTS:
        raise ValueError(f"unknown layout {layout!r}; known: {', '.join(LAYOUTS)}")
    if layout == "objects":
        if attempt:
            raise ValueError("the objects layout has one draw per seed (attempt 0)")
        params = sample_objects(seed)
    else:
        rng = np.random.default_rng([seed, LAYOUT_STREAMS[layout], attempt])
        params = SAMPLERS[layout](rng)
        params["attempt"] = attempt
    params["layout"] = layout
    return params


def sample_objects(seed: int) -> dict:
    """Layout ``objects``: the shared files' JSON layout, drawn as the shared set was."""
    rng = np.random.default_rng(seed)
    iors = [rng.uniform(*r) for r in IOR_RANGES]
    iors = [iors[i] for i in rng.permutation(3)]
    alphas = rng.uniform(*ALPHA_RANGE, size=3)
    if rng.random() < 0.5:
        albedos = np.full(3, rng.uniform(*ALBEDO_RANGE))
    else:
        albedos = rng.uniform(*ALBEDO_RANGE, size=3)
    materials = [
        {"ior": float(n), "alpha": float(a), "albedo": float(b)}
        for n, a, b in zip(iors, alphas, albedos, strict=True)
    ]
    objects = []
    for _ in range(int(rng.integers(N_OBJECTS[0], N_OBJECTS[1] + 1))):
        objects.append(
            {
                "kind": str(rng.choice(KINDS)),
                "x": float(rng.uniform(*XY_RANGE)),
                "y": float(rng.uniform(*XY_RANGE)),
                "r": float(rng.uniform(*SIZE_RANGE)),
                "rot": float(rng.uniform(*ROT_RANGE)),
                "tilt": float(rng.uniform(*TILT_RANGE)),
                "mat": int(rng.integers(1, 3)),
            }
        )
    sun = [rng.normal(), rng.normal(), -(0.5 + abs(rng.normal()))]
    sun_irradiance = float(np.exp(rng.uniform(*np.log(SUN_RANGE))))
    return {
        "materials": materials,
        "objects": objects,
        "elevation": float(rng.uniform(*ELEVATION_RANGE)),
        "azimuth": float(rng.uniform(*AZIMUTH_RANGE)),
        "sun": [float(v) for v in sun],
        "sun_irradiance": sun_irradiance,
    }


def _sun(rng: np.random.Generator) -> dict:
    """Sun direction and irradiance, drawn as in :func:`sample_objects`."""
    sun = [rng.normal(), rng.normal(), -(0.5 + abs(rng.normal()))]
    return {
        "sun": [float(v) for v in sun],
        "sun_irradiance": float(np.exp(rng.uniform(*np.log(SUN_RANGE)))),
    }


def _floor_material(rng: np.random.Generator) -> dict:
    """The floor's material in the new layouts: ior anywhere in the README's ranges."""
    return {
        "ior": float(rng.uniform(*FLOOR_IOR_RANGE)),
        "alpha": float(rng.uniform(*ALPHA_RANGE)),
        "albedo": float(rng.uniform(*ALBEDO_RANGE)),
    }


def _material_choice(rng: np.random.Generator, k: int, n: int) -> np.ndarray:
    """Material numbers 1..k for n objects, every one used at least once."""
    mats = np.concatenate([np.arange(1, k + 1), rng.integers(1, k + 1, size=n - k)])
    return rng.permutation(mats)


def sample_small(rng: np.random.Generator) -> dict:
    """Layout ``small``: 20-60 leaves of 2-3 object materials seen from above.

    The object materials share one albedo and differ (``"differ"``) in ior (one of
    :data:`IOR_RANGES` each), in alpha (one of :data:`ALPHA_BINS` each) or in both.
    Each leaf is an elliptic disk (aspect 1.5-3) tilted 0-60 degrees, its lowest point
    0-0.06 above the floor; its size is solved so that its unoccluded projection
    covers a target share of the frame (``"share"``: the share reached, 0.2-2 %; a
    leaf seen too nearly edge-on to reach 0.2 % gets a new orientation). The leaves
    lie in a patch of 65-90 % of the frame; their target shares are drawn log-uniformly
    from the widest range below 2 % (at most 0.3-2 %) whose mean puts 0.8 x the patch's
    share under leaves (before overlap), so they touch and overlap; with few leaves
    that is out of reach and they are all 1.5-2 %, more sparsely spread."""
    k = int(rng.integers(N_OBJECT_MATERIALS[0], N_OBJECT_MATERIALS[1] + 1))
    differ = str(rng.choice(DIFFER))
    floor = _floor_material(rng)
    albedo = float(rng.uniform(*ALBEDO_RANGE))
    iors = [float(rng.uniform(*IOR_RANGES[i])) for i in rng.permutation(3)[:k]]
    alphas = [float(rng.uniform(*ALPHA_BINS[i])) for i in rng.permutation(3)[:k]]
    if differ == "alpha":
        iors = [iors[0]] * k
    elif differ == "ior":
        alphas = [alphas[0]] * k
    materials = [floor] + [
        {"ior": n, "alpha": a, "albedo": albedo} for n, a in zip(iors, alphas, strict=True)
    ]
    params = {
        "materials": materials,
        "differ": differ,
        "elevation": float(rng.uniform(*SMALL_ELEVATION_RANGE)),
        "azimuth": float(rng.uniform(*AZIMUTH_RANGE)),
        **_sun(rng),
    }
    n = int(rng.integers(N_LEAVES[0], N_LEAVES[1] + 1))
    patch = float(rng.uniform(*PATCH_RANGE))
    widths = np.linspace(*LEAF_WIDTH, 200)
    means = LEAF_SHARE[1] * (1 - np.exp(-widths)) / widths  # decreasing in the width
    width = np.interp(LEAF_DENSITY * patch / n, means[::-1], widths[::-1])
    shares = LEAF_SHARE[1] * np.exp(-rng.uniform(0.0, width, n))
    pw, ph = WIDTH * np.sqrt(patch), HEIGHT * np.sqrt(patch)
    c0 = rng.uniform([pw / 2, ph / 2], [WIDTH - pw / 2, HEIGHT - ph / 2])
    cols = c0[0] + rng.uniform(-pw / 2, pw / 2, n)
    rows = c0[1] + rng.uniform(-ph / 2, ph / 2, n)
    leaves = {
        "rot": rng.uniform(*ROT_RANGE, n),
        "tilt": rng.uniform(*LEAF_TILT, n),
        "spin": rng.uniform(*ROT_RANGE, n),
        "aspect": rng.uniform(*LEAF_ASPECT, n),
        "lift": rng.uniform(*LEAF_LIFT, n),
    }
    mats = _material_choice(rng, k, n)
    xyz = floor_point(cols, rows, params)
    lim = FLOOR_HALF - 0.2
    x, y = np.clip(xyz[:, 0], -lim, lim), np.clip(xyz[:, 1], -lim, lim)
    a, b, z, got = size_leaves(params, x, y, shares, **leaves)
    for _ in range(LEAF_REDRAWS):  # nearly edge-on leaves: a new orientation
        bad = got < LEAF_SHARE[0]
        if not bad.any():
            break
        for key, bounds in (("rot", ROT_RANGE), ("tilt", LEAF_TILT), ("spin", ROT_RANGE)):
            leaves[key][bad] = rng.uniform(*bounds, int(bad.sum()))
        a, b, z, got = size_leaves(params, x, y, shares, **leaves)
    params["objects"] = [
        {
            "kind": "leaf",
            "x": float(x[i]),
            "y": float(y[i]),
            "z": float(z[i]),
            "a": float(a[i]),
            "b": float(b[i]),
            "rot": float(leaves["rot"][i]),
            "tilt": float(leaves["tilt"][i]),
            "spin": float(leaves["spin"][i]),
            "share": float(got[i]),
            "mat": int(mats[i]),
        }
        for i in range(n)
    ]
    return params


def sample_textured(rng: np.random.Generator) -> dict:
    """Layout ``textured``: 4-8 objects whose 2-3 materials differ only in texture.

    The object materials share ior, alpha (Beckmann) and albedo; one is smooth, one
    has a fine normal-map texture (bumps 1-3 px on screen) and a third, if drawn, a
    coarse (4-8 px) or grooved (1-2 px across, 10-20 px along) one, each with an RMS
    slope of 12-25 degrees (:func:`texture_normals`). Shapes, positions and camera are
    drawn as in :func:`sample_objects`, sizes from :data:`TEXTURED_SIZE_RANGE`."""
    k = int(rng.integers(N_OBJECT_MATERIALS[0], N_OBJECT_MATERIALS[1] + 1))
    floor = _floor_material(rng)
    shared = {
        "ior": float(rng.uniform(*TEXTURED_IOR_RANGE)),
        "alpha": float(rng.uniform(*TEXTURED_ALPHA_RANGE)),
        "albedo": float(rng.uniform(*ALBEDO_RANGE)),
    }
    kinds = ["smooth", "fine", str(rng.choice(("coarse", "grooved")))][:k]
    materials = [floor]
    for kind in (kinds[i] for i in rng.permutation(k)):
        mat = dict(shared)
        if kind != "smooth":
            (lo, hi), along = TEXTURE_FEATURES[kind]
            across = float(rng.uniform(lo, hi))
            feature = [across, float(rng.uniform(*along)) if along else across]
            mat["texture"] = {
                "kind": kind,
                "feature_px": [feature[i] for i in rng.permutation(2)],
                "slope_deg": float(rng.uniform(*TEXTURE_SLOPE)),
                "seed": int(rng.integers(2**31)),
            }
        materials.append(mat)
    n = int(rng.integers(N_OBJECTS[0], N_OBJECTS[1] + 1))
    mats = _material_choice(rng, k, n)
    objects = [
        {
            "kind": str(rng.choice(KINDS)),
            "x": float(rng.uniform(*XY_RANGE)),
            "y": float(rng.uniform(*XY_RANGE)),
            "r": float(rng.uniform(*TEXTURED_SIZE_RANGE)),
            "rot": float(rng.uniform(*ROT_RANGE)),
            "tilt": float(rng.uniform(*TILT_RANGE)),
            "mat": int(mats[i]),
        }
        for i in range(n)
    ]
    return {
        "materials": materials,
        "objects": objects,
        "elevation": float(rng.uniform(*ELEVATION_RANGE)),
        "azimuth": float(rng.uniform(*AZIMUTH_RANGE)),
        **_sun(rng),
    }


#: The samplers of the new layouts (``objects`` is :func:`sample_objects`).
SAMPLERS: dict[str, Callable[[np.random.Generator], dict]] = {
    "small": sample_small,
    "textured": sample_textured,
}


def object_materials(params: dict) -> int:
    """How many distinct materials the objects were drawn with."""
    return len({obj["mat"] for obj in params["objects"]})


def camera_origin(params: dict) -> list[float]:
    """Camera position: elevation above the floor, azimuth 0 looking along +y."""
    el = np.radians(params["elevation"])
    az = np.radians(params["azimuth"])
    return [
        float(CAM_DIST * np.cos(el) * np.sin(az)),
        float(-CAM_DIST * np.cos(el) * np.cos(az)),
        float(TARGET_Z + CAM_DIST * np.sin(el)),
    ]


def focal_px() -> float:
    """The camera's focal length in pixels (horizontal field of view FOV_DEG)."""
    return float(WIDTH / 2 / np.tan(np.radians(FOV_DEG) / 2))


def camera_axes(params: dict) -> tuple[np.ndarray, np.ndarray]:
    """Camera origin and the rows left, up, forward of Mitsuba's ``look_at`` frame."""
    origin = np.array(camera_origin(params))
    forward = np.array([0.0, 0.0, TARGET_Z]) - origin
    forward /= np.linalg.norm(forward)
    left = np.cross([0.0, 0.0, 1.0], forward)
    left /= np.linalg.norm(left)
    return origin, np.stack([left, np.cross(forward, left), forward])


def project(points: np.ndarray, params: dict) -> np.ndarray:
    """Image (column, row) in pixels of world points (..., 3), as the sensor sees them."""
    origin, axes = camera_axes(params)
    cam = (np.asarray(points) - origin) @ axes.T
    f = focal_px()
    col = WIDTH / 2 - f * cam[..., 0] / cam[..., 2]
    row = HEIGHT / 2 - f * cam[..., 1] / cam[..., 2]
    return np.stack([col, row], axis=-1)


def floor_point(cols: np.ndarray, rows: np.ndarray, params: dict) -> np.ndarray:
    """The floor (z = 0) points seen at image columns and rows, shape (..., 3)."""
    origin, axes = camera_axes(params)
    f = focal_px()
    cam = np.stack(
        [-(np.asarray(cols) - WIDTH / 2) / f, -(np.asarray(rows) - HEIGHT / 2) / f],
        axis=-1,
    )
    ray = cam[..., :1] * axes[0] + cam[..., 1:] * axes[1] + axes[2]
    t = -origin[2] / ray[..., 2]
    return origin + t[..., None] * ray


def _rz(deg: np.ndarray) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    o, i = np.zeros_like(c), np.ones_like(c)
    return np.stack(
        [np.stack([c, -s, o], -1), np.stack([s, c, o], -1), np.stack([o, o, i], -1)], -2
    )


def _rx(deg: np.ndarray) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    o, i = np.zeros_like(c), np.ones_like(c)
    return np.stack(
        [np.stack([i, o, o], -1), np.stack([o, c, -s], -1), np.stack([o, s, c], -1)], -2
    )


def leaf_rotation(rot: np.ndarray, tilt: np.ndarray, spin: np.ndarray) -> np.ndarray:
    """Rotation of a leaf's disk, (..., 3, 3): spin in its plane, tilt about x, rot about z
    (the order of :func:`object_transform`)."""
    return _rz(rot) @ _rx(tilt) @ _rz(spin)


def leaf_height(
    a: np.ndarray, b: np.ndarray, tilt: np.ndarray, spin: np.ndarray, lift: np.ndarray | float
) -> np.ndarray:
    """Centre height that puts a tilted leaf's lowest point ``lift`` above the floor."""
    sp = np.radians(spin)
    reach = np.sqrt((a * np.sin(sp)) ** 2 + (b * np.cos(sp)) ** 2)
    return np.sin(np.radians(tilt)) * reach + lift


def leaf_shares(
    params: dict,
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    rot: np.ndarray,
    tilt: np.ndarray,
    spin: np.ndarray,
) -> np.ndarray:
    """Unoccluded projected area of each leaf as a share of the frame (outline polygon,
    not clipped to the frame)."""
    t = np.linspace(0.0, 2 * np.pi, LEAF_OUTLINE, endpoint=False)
    ca = np.asarray(a)[:, None] * np.cos(t)
    local = np.stack([ca, np.asarray(b)[:, None] * np.sin(t), np.zeros_like(ca)], axis=-1)
    world = local @ np.swapaxes(leaf_rotation(rot, tilt, spin), -1, -2)
    world = world + np.stack([x, y, z], axis=-1)[:, None, :]
    uv = project(world, params)
    u, v = uv[..., 0], uv[..., 1]
    area = 0.5 * np.abs(np.sum(u * np.roll(v, -1, axis=1) - np.roll(u, -1, axis=1) * v, axis=1))
    return area / (WIDTH * HEIGHT)


def size_leaves(
    params: dict,
    x: np.ndarray,
    y: np.ndarray,
    shares: np.ndarray,
    rot: np.ndarray,
    tilt: np.ndarray,
    spin: np.ndarray,
    aspect: np.ndarray,
    lift: np.ndarray,
    iterations: int = 5,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Semi-axes a, b and centre height z of leaves whose projection covers ``shares``
    of the frame; returns them with the shares reached. A leaf's radius sqrt(a b)
    grows at most LEAF_GROWTH times its estimate from a frontal view, so a leaf seen
    nearly edge-on stays small (and short of its share)."""
    d = np.linalg.norm(np.stack([x, y, 0 * x], -1) - np.array(camera_origin(params)), axis=-1)
    el = np.radians(params["elevation"])
    c0 = np.sqrt(shares * WIDTH * HEIGHT * d**2 / (np.pi * focal_px() ** 2 * np.sin(el)))
    c = c0
    for _ in range(iterations):
        a, b = c * np.sqrt(aspect), c / np.sqrt(aspect)
        z = leaf_height(a, b, tilt, spin, lift)
        got = leaf_shares(params, x, y, z, a, b, rot, tilt, spin)
        c = np.minimum(c * np.sqrt(shares / np.maximum(got, 1e-9)), LEAF_GROWTH * c0)
    a, b = c * np.sqrt(aspect), c / np.sqrt(aspect)
    z = leaf_height(a, b, tilt, spin, lift)
    return a, b, z, leaf_shares(params, x, y, z, a, b, rot, tilt, spin)


def texture_normals(texture: dict, size: int = TEX_SIZE) -> np.ndarray:
    """A periodic tangent-space normal map (size, size, 3), encoded (n + 1) / 2.

    The normals are those of a Gaussian random height field: white noise from
    ``texture["seed"]`` low-passed by a Gaussian of standard deviation
    ``feature_px / 2`` screen pixels (``feature_px / (2 TEXEL_PX)`` texels) along u
    (columns) and v (rows), its gradient scaled to an RMS slope of ``slope_deg``."""
    rng = np.random.default_rng(texture["seed"])
    noise = np.fft.fft2(rng.standard_normal((size, size)))
    ku = np.fft.fftfreq(size)[None, :]
    kv = np.fft.fftfreq(size)[:, None]
    su, sv = (f / (2 * TEXEL_PX) for f in texture["feature_px"])
    spectrum = noise * np.exp(-2 * np.pi**2 * ((su * ku) ** 2 + (sv * kv) ** 2))
    hu = np.fft.ifft2(spectrum * 2j * np.pi * ku).real
    hv = np.fft.ifft2(spectrum * 2j * np.pi * kv).real
    scale = np.tan(np.radians(texture["slope_deg"])) / np.sqrt(np.mean(hu**2 + hv**2))
    n = np.stack([-scale * hu, -scale * hv, np.ones_like(hu)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return ((n + 1.0) / 2.0).astype(np.float32)


def uv_extent(obj: dict) -> tuple[float, float]:
    """World length along u and v of one unit of a shape's texture coordinates."""
    r = obj["r"]
    if obj["kind"] == "sphere":
        return 2 * np.pi * r, np.pi * r
    if obj["kind"] == "box":
        return 2 * BOX_HALF * r, 2 * BOX_HALF * r
    return 2 * PANEL_HALF_W * r, 2 * PANEL_HALF_H * r


def texture_repeats(params: dict, obj: dict) -> tuple[float, float]:
    """How often the normal map repeats along u and v on an object, so that a texel is
    TEXEL_PX pixels on screen at the object's distance."""
    centre = np.array([obj["x"], obj["y"], obj["r"]])
    texel = TEXEL_PX * np.linalg.norm(centre - camera_origin(params)) / focal_px()
    eu, ev = uv_extent(obj)
    ru, rv = eu / (TEX_SIZE * texel), ev / (TEX_SIZE * texel)
    if obj["kind"] == "sphere":  # u goes once round: a whole number of repeats, no seam
        ru = max(1.0, round(ru))
    return float(ru), float(rv)


def sensor_dict(mi: ModuleType, params: dict, spp: int, rfilter: str = "gaussian") -> dict:
    """The perspective camera looking at (0, 0, TARGET_Z) from :func:`camera_origin`."""
    to_world = mi.ScalarTransform4f().look_at(
        origin=camera_origin(params), target=[0.0, 0.0, TARGET_Z], up=[0.0, 0.0, 1.0]
    )
    return {
        "type": "perspective",
        "fov": FOV_DEG,
        "fov_axis": "x",
        "to_world": to_world,
        "film": {
            "type": "hdrfilm",
            "width": WIDTH,
            "height": HEIGHT,
            "rfilter": {"type": rfilter},
            "pixel_format": "rgb",
        },
        "sampler": {"type": "independent", "sample_count": spp},
    }


def object_transform(mi: ModuleType, obj: dict):  # -> mi.ScalarTransform4f
    """World transform of one object's unit shape (sphere, cube, rectangle or disk)."""
    T = mi.ScalarTransform4f()
    if obj["kind"] == "leaf":
        # A flat elliptic leaf: the unit disk scaled to semi-axes a, b, spun in its
        # plane, tilted about x and turned about the vertical (see leaf_rotation).
        return (
            T.translate([obj["x"], obj["y"], obj["z"]])
            .rotate([0, 0, 1], obj["rot"])
            .rotate([1, 0, 0], obj["tilt"])
            .rotate([0, 0, 1], obj["spin"])
            .scale([obj["a"], obj["b"], 1.0])
        )
    r = obj["r"]
    if obj["kind"] == "sphere":
        return T.translate([obj["x"], obj["y"], r]).scale(r)
    if obj["kind"] == "box":
        h = BOX_HALF * r
        return T.translate([obj["x"], obj["y"], h]).rotate([0, 0, 1], obj["rot"]).scale(h)
    # Upright panel: a vertical rectangle, its centre PANEL_Z * r above the floor,
    # turned by rot about the vertical and leaned by tilt about its horizontal axis.
    hw, hh = PANEL_HALF_W * r, PANEL_HALF_H * r
    return (
        T.translate([obj["x"], obj["y"], PANEL_Z * r])
        .rotate([0, 0, 1], obj["rot"])
        .rotate([1, 0, 0], obj["tilt"])
        .rotate([1, 0, 0], 90.0)
        .scale([hw, hh, 1.0])
    )


def shape_dicts(mi: ModuleType, params: dict, floor_bsdf: dict, bsdfs: list[dict]) -> dict:
    """The floor (with floor_bsdf) and the objects, object i with bsdfs[i]."""
    kind_type = {"sphere": "sphere", "box": "cube", "panel": "rectangle", "leaf": "disk"}
    shapes = {
        "floor": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f().scale([FLOOR_HALF, FLOOR_HALF, 1.0]),
            "bsdf": floor_bsdf,
        }
    }
    for i, (obj, bsdf) in enumerate(zip(params["objects"], bsdfs, strict=True)):
        shapes[f"obj{i}"] = {
            "type": kind_type[obj["kind"]],
            "to_world": object_transform(mi, obj),
            "bsdf": bsdf,
        }
    return shapes


def pplastic(mat: dict, normalmap: dict | None = None) -> dict:
    """Two-sided pplastic of a material, inside a normal map when one is given."""
    bsdf = {
        "type": "pplastic",
        "diffuse_reflectance": {"type": "spectrum", "value": mat["albedo"]},
        "eta": mat["ior"],
        "alpha": mat["alpha"],
        "distribution": MICROFACET,
    }
    if normalmap is not None:
        bsdf = {"type": "normalmap", "normalmap": normalmap, "bsdf": bsdf}
    return {"type": "twosided", "bsdf": bsdf}


def object_bsdfs(mi: ModuleType, params: dict) -> list[dict]:
    """Each object's BSDF: its material's pplastic; a textured material's with the
    material's normal map, tiled so that a texel is TEXEL_PX pixels on that object."""
    mats = params["materials"]
    bitmaps = {
        k: mi.Bitmap(texture_normals(m["texture"])) for k, m in enumerate(mats) if "texture" in m
    }
    out = []
    for obj in params["objects"]:
        k = obj["mat"]
        if k not in bitmaps:
            out.append(pplastic(mats[k]))
            continue
        ru, rv = texture_repeats(params, obj)
        normalmap = {
            "type": "bitmap",
            "bitmap": bitmaps[k],
            "raw": True,
            "wrap_mode": "repeat",
            "to_uv": mi.ScalarTransform4f().scale([ru, rv, 1.0]),
        }
        out.append(pplastic(mats[k], normalmap))
    return out


def scene_dict(mi: ModuleType, params: dict, spp: int) -> dict:
    """The polarised scene: Stokes integrator, camera, sky, sun, floor and objects."""
    sun = np.asarray(params["sun"], dtype=float)
    irradiance = float(params.get("sun_irradiance", SUN_DEFAULT))
    scene = {
        "type": "scene",
        "integrator": {
            "type": "stokes",
            "integrator": {"type": "path", "max_depth": MAX_DEPTH},
        },
        "sensor": sensor_dict(mi, params, spp),
        "sky": {"type": "constant", "radiance": {"type": "spectrum", "value": SKY_RADIANCE}},
        "sun": {
            "type": "directional",
            "direction": (sun / np.linalg.norm(sun)).tolist(),
            "irradiance": {"type": "spectrum", "value": irradiance},
        },
    }
    floor = pplastic(params["materials"][0])
    scene.update(shape_dicts(mi, params, floor, object_bsdfs(mi, params)))
    return scene


def id_scene_dict(
    mi: ModuleType, params: dict, floor_value: float, values: list[float], spp: int = 1
) -> dict:
    """Same geometry; the floor's albedo is floor_value, object i's is values[i]."""

    def diffuse(v: float) -> dict:
        return {"type": "diffuse", "reflectance": {"type": "spectrum", "value": v}}

    scene = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": "alb:albedo"},
        "sensor": sensor_dict(mi, params, spp, rfilter="box"),
    }
    scene.update(shape_dicts(mi, params, diffuse(floor_value), [diffuse(v) for v in values]))
    return scene


def label_scene_dict(mi: ModuleType, params: dict, spp: int = 1) -> dict:
    """Same geometry; each shape's albedo encodes its label (material + 1) / 4."""
    values = [(obj["mat"] + 1) / LABEL_SCALE for obj in params["objects"]]
    return id_scene_dict(mi, params, 1 / LABEL_SCALE, values, spp)


def instance_scene_dict(mi: ModuleType, params: dict, spp: int = 1) -> dict:
    """Same geometry; object i's albedo encodes its instance id (i + 1) / 256, the
    floor's is 0 (as the sky's)."""
    values = [(i + 1) / INSTANCE_SCALE for i in range(len(params["objects"]))]
    return id_scene_dict(mi, params, 0.0, values, spp)


def luminance(img: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of RGB images (..., 3)."""
    return img @ np.array([0.2126, 0.7152, 0.0722])


def render_stokes(mi: ModuleType, params: dict, spp: int, seed: int) -> np.ndarray:
    """Noise-free (up to path-tracing noise) S0, S1, S2 images, shape (3, H, W)."""
    scene = mi.load_dict(scene_dict(mi, params, spp))
    img = np.array(mi.render(scene, seed=seed))
    names = scene.integrator().aov_names()
    out = []
    for s in ("S0", "S1", "S2"):
        idx = [names.index(f"{s}.{c}") for c in "RGB"]
        # aov channels follow the nested integrator's 3 RGB channels
        out.append(luminance(img[..., [3 + i for i in idx]]))
    out[2] = S2_SIGN * out[2]
    return np.stack(out)


def render_ids(
    mi: ModuleType, build: Callable[[], dict], seed: int, scale: float, top: int
) -> np.ndarray:
    """Per-pixel id from one jittered sample per pixel of the scene ``build()`` makes
    (RGB variant: exact albedo, id = albedo x scale, at most ``top``)."""
    mi.set_variant(LABEL_VARIANT)
    try:
        img = np.array(mi.render(mi.load_dict(build()), seed=seed))
    finally:
        mi.set_variant(VARIANT)
    alb = img[..., -3:].mean(axis=-1)
    return np.clip(np.rint(alb * scale), 0, top)


def render_labels(mi: ModuleType, params: dict, seed: int, spp: int = 1) -> np.ndarray:
    """Per-pixel label (0 sky, 1 floor, material + 1 on objects), uint8."""
    top = len(params["materials"])
    ids = render_ids(mi, lambda: label_scene_dict(mi, params, spp), seed, LABEL_SCALE, top)
    return ids.astype(np.uint8)


def render_instances(mi: ModuleType, params: dict, seed: int, spp: int = 1) -> np.ndarray:
    """Per-pixel object instance (0 sky and floor, i + 1 on object i), uint16."""
    top = len(params["objects"])
    ids = render_ids(mi, lambda: instance_scene_dict(mi, params, spp), seed, INSTANCE_SCALE, top)
    return ids.astype(np.uint16)


def polariser_images(stokes: np.ndarray) -> np.ndarray:
    """Intensities through a linear polariser at ANGLES, shape (4, H, W)."""
    s0, s1, s2 = stokes
    th = np.radians(ANGLES)[:, None, None]
    return 0.5 * (s0 + s1 * np.cos(2 * th) + s2 * np.sin(2 * th))


def to_counts(images: np.ndarray, seed: int) -> np.ndarray:
    """Auto-exposed 12-bit counts with Poisson shot noise and read noise."""
    rng = np.random.default_rng([seed, 12])
    images = np.clip(images, 0.0, None)
    scale = EXPOSURE_TARGET / max(float(np.percentile(images, EXPOSURE_PERCENTILE)), 1e-12)
    counts = rng.poisson(images * scale * ELECTRONS_PER_COUNT) / ELECTRONS_PER_COUNT
    counts += rng.normal(0.0, READ_NOISE, size=counts.shape)
    return np.clip(np.rint(counts), 0, FULL_SCALE).astype(np.uint16)


def load_mitsuba(threads: int = 0) -> ModuleType:
    """Mitsuba with VARIANT set; ``threads`` > 0 limits Dr.Jit's thread pool to that
    many threads (the calling one included; Dr.Jit 1.5 reads no environment variable
    for it), 0 keeps its default of one per core."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(VARIANT)
    if threads > 0:
        dr.set_thread_count(threads)
    return mi


def material_shares(params: dict, labels: np.ndarray) -> dict[int, float]:
    """Share of the frame each object material the scene drew covers (by material)."""
    return {
        k: float((labels == k + 1).mean()) for k in sorted({o["mat"] for o in params["objects"]})
    }


def accepted_scene(mi: ModuleType, seed: int, layout: str) -> tuple[dict, np.ndarray]:
    """The first draw of a seed whose object materials each cover MIN_MATERIAL_SHARE of
    the frame in its label render, with those labels. ``objects`` keeps its single
    draw whatever it covers (its scenes must not change)."""
    for attempt in range(MAX_ATTEMPTS if layout != "objects" else 1):
        params = sample_scene(seed, layout, attempt)
        labels = render_labels(mi, params, seed)
        if layout == "objects" or min(material_shares(params, labels).values()) >= (
            MIN_MATERIAL_SHARE
        ):
            return params, labels
    raise RuntimeError(f"seed {seed}: no accepted {layout} scene in {MAX_ATTEMPTS} draws")


def render_scene(
    params: dict,
    spp: int,
    seed: int,
    mi: ModuleType | None = None,
    labels: np.ndarray | None = None,
) -> dict:
    """The stack, angles, labels, instances and materials JSON of one scene."""
    if mi is None:
        mi = load_mitsuba()
    mi.set_variant(VARIANT)
    stokes = render_stokes(mi, params, spp, seed)
    if labels is None:
        labels = render_labels(mi, params, seed)
    return {
        "stack": to_counts(polariser_images(stokes), seed),
        "angles": ANGLES.copy(),
        "labels": labels,
        "instances": render_instances(mi, params, seed),
        "materials": np.array(json.dumps(params)),
    }


def _dolp_aolp(stack: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    st = stack.astype(float)
    s0 = st.sum(axis=0) / 2.0
    s1, s2 = st[0] - st[2], st[1] - st[3]
    return st, np.hypot(s1, s2) / np.maximum(s0, 1.0), np.degrees(0.5 * np.arctan2(s2, s1))


def polarisation_stats(stack: np.ndarray, labels: np.ndarray) -> dict:
    """Per label: pixel fraction, mean 0-degree count, mean DoLP, mean AoLP (deg)."""
    st, dolp, aolp = _dolp_aolp(stack)
    out = {}
    for k in range(max(int(labels.max()) + 1, 4)):
        m = labels == k
        if m.any():
            out[k] = (m.mean(), st[0][m].mean(), dolp[m].mean(), aolp[m].mean())
    return out


def polarisation_spread(stack: np.ndarray, labels: np.ndarray) -> dict:
    """Per label: DoLP standard deviation, local DoLP deviation (RMS difference from
    the 3 x 3 mean, over pixels whose 3 x 3 window is all that label) and local AoLP
    deviation in degrees (the same on the doubled angle)."""
    _, dolp, aolp = _dolp_aolp(stack)
    z = np.exp(2j * np.radians(aolp))

    def box3(a: np.ndarray) -> np.ndarray:
        p = np.pad(a, 1, mode="edge")
        return (
            sum(p[i : i + a.shape[0], j : j + a.shape[1]] for i in range(3) for j in range(3)) / 9
        )

    out = {}
    for k in range(int(labels.max()) + 1):
        m = labels == k
        inner = box3(m.astype(float)) > 1 - 1e-9
        if inner.sum() < 20:
            continue
        local = np.sqrt(np.mean((dolp - box3(dolp))[inner] ** 2))
        zbar = box3(z)[inner]
        ang = np.degrees(np.sqrt(np.mean(np.angle(z[inner] * np.conj(zbar)) ** 2))) / 2
        out[k] = (float(dolp[m].std()), float(local), float(ang))
    return out


def compare(shared: dict, mine: dict) -> str:
    """A text table comparing a re-rendered scene with the shared file."""
    agree = float((shared["labels"] == mine["labels"]).mean())
    a = polarisation_stats(shared["stack"], shared["labels"])
    b = polarisation_stats(mine["stack"], mine["labels"])
    lines = [
        f"label agreement {agree:.4f}",
        "label  frac(sh/me)    I0(sh/me)    DoLP(sh/me)   AoLP(sh/me)",
    ]
    for k in sorted(set(a) | set(b)):
        x = a.get(k, (0, 0, 0, 0))
        y = b.get(k, (0, 0, 0, 0))
        lines.append(
            f"{k:5d}  {x[0]:.3f}/{y[0]:.3f}  {x[1]:6.0f}/{y[1]:6.0f}  "
            f"{x[2]:.3f}/{y[2]:.3f}  {x[3]:6.1f}/{y[3]:6.1f}"
        )
    return "\n".join(lines)


def stats_table(data: dict) -> str:
    """Per label of a rendered scene: share, mean I0, DoLP mean and spread, AoLP."""
    params = json.loads(str(data["materials"]))
    a = polarisation_stats(data["stack"], data["labels"])
    b = polarisation_spread(data["stack"], data["labels"])
    lines = ["label  texture   frac   I0     DoLP  DoLP-sd  local-sd  AoLP  AoLP-local"]
    for k, (frac, i0, dolp, aolp) in a.items():
        mat = params["materials"][k - 1] if k > 0 else {}
        tex = mat.get("texture", {}).get("kind", "-" if k < 2 else "smooth")
        sd, local, ang = b.get(k, (np.nan, np.nan, np.nan))
        lines.append(
            f"{k:5d}  {tex:8s} {frac:.3f} {i0:6.0f}  {dolp:.3f}  {sd:.3f}    {local:.3f}"
            f"   {aolp:6.1f}  {ang:5.1f}"
        )
    return "\n".join(lines)


def parse_seeds(text: str) -> list[int]:
    """Seeds from text such as ``100-123`` or ``5,7,9``."""
    seeds: list[int] = []
    for part in text.split(","):
        if "-" in part.strip()[1:]:
            lo, hi = part.split("-", 1)
            seeds.extend(range(int(lo), int(hi) + 1))
        elif part.strip():
            seeds.append(int(part))
    return seeds


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="100-123", help="e.g. 100-123 or 5,7,9")
    ap.add_argument("--out", default=str(Path(__file__).parent / "renders"))
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--layout", choices=LAYOUTS, default="objects", help="scene layout")
    ap.add_argument(
        "--threads", type=int, default=0, help="Dr.Jit threads (default 0: one per core)"
    )
    ap.add_argument(
        "--two-materials",
        action="store_true",
        help="render only the seeds whose objects all draw one material (floor + one)",
    )
    ap.add_argument("--from-json", help="re-render a shared scene_<n>.npz's parameters")
    ap.add_argument("--compare", action="store_true", help="with --from-json: print a table")
    ap.add_argument("--sun-irradiance", type=float, help="with --from-json: sun/sky ratio")
    ap.add_argument("--stats", action="store_true", help="print per-label polarisation")
    args = ap.parse_args(argv)
    if args.two_materials and args.layout != "objects":
        ap.error("--two-materials selects seeds of the objects layout only")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.from_json:
        src = np.load(args.from_json)
        params = json.loads(str(src["materials"]))
        if args.sun_irradiance is not None:
            params["sun_irradiance"] = args.sun_irradiance
        jobs = [(Path(args.from_json).stem + "_rerender", params, 0)]
    else:
        seeds = parse_seeds(args.seeds)
        if args.two_materials:
            seeds = [s for s in seeds if object_materials(sample_scene(s)) == 1]
        jobs = [(f"scene_{s}", None, s) for s in seeds]
    mi = load_mitsuba(args.threads)
    for name, params, seed in jobs:
        t0 = time.perf_counter()
        labels = None
        if params is None:
            params, labels = accepted_scene(mi, seed, args.layout)
        data = render_scene(params, args.spp, seed, mi, labels)
        np.savez_compressed(out / f"{name}.npz", **data)
        classes = np.unique(data["labels"]).tolist()
        shares = material_shares(params, data["labels"])
        small = [k for k, v in shares.items() if v < MIN_MATERIAL_SHARE]
        print(
            f"{name}: {time.perf_counter() - t0:.1f} s, {params.get('layout', 'objects')}"
            f" (attempt {params.get('attempt', 0)}), classes {classes}, "
            f"{len(np.unique(data['instances'])) - 1}/{len(params['objects'])} instances "
            f"seen, smallest object material {min(shares.values()):.3f}"
            + (f" (materials {small} under 1 %)" if small else "")
            + f", max count {int(data['stack'].max())}",
            flush=True,
        )
        if args.stats:
            print(stats_table(data), flush=True)
        if args.from_json and args.compare:
            print(compare(src, data))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
