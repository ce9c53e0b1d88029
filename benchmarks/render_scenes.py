"""Render new polarised material scenes with Mitsuba 3 (benchmark tool only).

Makes held-out scenes the same way as the 24 shared ones in
``shared/data/rendered/`` (see its README): Mitsuba 3.9.1, variant
``llvm_ad_spectral_polarized``, a ``stokes`` integrator around a ``path`` integrator
with 5 bounces, ``pplastic`` materials, spheres, boxes and upright panels on a
finite floor, an unpolarised constant sky plus a directional sun, and a polarisation
camera's four images (polariser at 0/45/90/135 degrees from the image's column axis
towards its row axis) as 12-bit counts with Poisson shot noise and 2-count read noise.
Each ``scene_<seed>.npz`` has the shared files' keys and dtypes: ``stack`` uint16
(4, 240, 320), ``angles`` float64, ``labels`` uint8 (0 sky, 1 floor material, 2 and 3
the objects' materials) and ``materials`` (JSON text of the scene's parameters).

This is a benchmark tool, not part of the package: Mitsuba is installed separately,
outside the project's venv, and CI never runs it::

    python3.11 -m venv ../render-venv            # any venv outside the project
    ../render-venv/bin/pip install mitsuba==3.9.1 numpy
    ../render-venv/bin/python benchmarks/render_scenes.py --seeds 100-123 \\
        --out benchmarks/renders [--spp 256] [--from-json PATH] [--two-materials]

``--two-materials`` renders only the seeds whose objects all draw one material (the
floor's and one more, as the shared set's two-material scenes were drawn). The render
sets the benchmarks read, their seeds and folders are ``materials.RENDER_SETS``.

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
from pathlib import Path

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


def sample_scene(seed: int) -> dict:
    """The scene parameters for one seed, in the shared files' JSON layout."""
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


def object_materials(params: dict) -> int:
    """How many distinct materials the objects were drawn with (1 or 2)."""
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


def sensor_dict(mi, params: dict, spp: int, rfilter: str = "gaussian") -> dict:
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


def object_transform(mi, obj: dict):
    """World transform of one object's unit shape (sphere, cube or rectangle)."""
    T = mi.ScalarTransform4f()
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


def shape_dicts(mi, params: dict, bsdfs: list[dict]) -> dict:
    """The floor (material 0) and the objects, each with bsdfs[material]."""
    kind_type = {"sphere": "sphere", "box": "cube", "panel": "rectangle"}
    shapes = {
        "floor": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f().scale([FLOOR_HALF, FLOOR_HALF, 1.0]),
            "bsdf": bsdfs[0],
        }
    }
    for i, obj in enumerate(params["objects"]):
        shapes[f"obj{i}"] = {
            "type": kind_type[obj["kind"]],
            "to_world": object_transform(mi, obj),
            "bsdf": bsdfs[obj["mat"]],
        }
    return shapes


def pplastic(mat: dict) -> dict:
    return {
        "type": "twosided",
        "bsdf": {
            "type": "pplastic",
            "diffuse_reflectance": {"type": "spectrum", "value": mat["albedo"]},
            "eta": mat["ior"],
            "alpha": mat["alpha"],
            "distribution": MICROFACET,
        },
    }


def scene_dict(mi, params: dict, spp: int) -> dict:
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
    scene.update(shape_dicts(mi, params, [pplastic(m) for m in params["materials"]]))
    return scene


def label_scene_dict(mi, params: dict, spp: int = 1) -> dict:
    """Same geometry; each shape's albedo encodes its label (material + 1) / 4."""
    bsdfs = [
        {"type": "diffuse", "reflectance": {"type": "spectrum", "value": (k + 1) / 4.0}}
        for k in range(3)
    ]
    scene = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": "alb:albedo"},
        "sensor": sensor_dict(mi, params, spp, rfilter="box"),
    }
    scene.update(shape_dicts(mi, params, bsdfs))
    return scene


def luminance(img: np.ndarray) -> np.ndarray:
    return img @ np.array([0.2126, 0.7152, 0.0722])


def render_stokes(mi, params: dict, spp: int, seed: int) -> np.ndarray:
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


def render_labels(mi, params: dict, seed: int, spp: int = 1) -> np.ndarray:
    """Per-pixel label from one jittered sample per pixel (RGB variant: exact albedo)."""
    mi.set_variant(LABEL_VARIANT)
    try:
        scene = mi.load_dict(label_scene_dict(mi, params, spp))
        img = np.array(mi.render(scene, seed=seed))
    finally:
        mi.set_variant(VARIANT)
    alb = img[..., -3:].mean(axis=-1)
    return np.clip(np.rint(alb * 4.0), 0, 3).astype(np.uint8)


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


def render_scene(params: dict, spp: int, seed: int) -> dict:
    import mitsuba as mi

    mi.set_variant(VARIANT)
    stokes = render_stokes(mi, params, spp, seed)
    labels = render_labels(mi, params, seed)
    return {
        "stack": to_counts(polariser_images(stokes), seed),
        "angles": ANGLES.copy(),
        "labels": labels,
        "materials": np.array(json.dumps(params)),
    }


def polarisation_stats(stack: np.ndarray, labels: np.ndarray) -> dict:
    """Per label: pixel fraction, mean 0-degree count, mean DoLP, mean AoLP (deg)."""
    st = stack.astype(float)
    s0 = st.sum(axis=0) / 2.0
    s1, s2 = st[0] - st[2], st[1] - st[3]
    dolp = np.hypot(s1, s2) / np.maximum(s0, 1.0)
    aolp = np.degrees(0.5 * np.arctan2(s2, s1))
    out = {}
    for k in range(4):
        m = labels == k
        if m.any():
            out[k] = (m.mean(), st[0][m].mean(), dolp[m].mean(), aolp[m].mean())
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


def parse_seeds(text: str) -> list[int]:
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
    ap.add_argument(
        "--two-materials",
        action="store_true",
        help="render only the seeds whose objects all draw one material (floor + one)",
    )
    ap.add_argument("--from-json", help="re-render a shared scene_<n>.npz's parameters")
    ap.add_argument("--compare", action="store_true", help="with --from-json: print a table")
    ap.add_argument("--sun-irradiance", type=float, help="with --from-json: sun/sky ratio")
    args = ap.parse_args(argv)
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
    for name, params, seed in jobs:
        params = params if params is not None else sample_scene(seed)
        t0 = time.perf_counter()
        data = render_scene(params, args.spp, seed)
        np.savez_compressed(out / f"{name}.npz", **data)
        classes = np.unique(data["labels"]).tolist()
        print(
            f"{name}: {time.perf_counter() - t0:.1f} s, classes {classes}, "
            f"max count {int(data['stack'].max())}",
            flush=True,
        )
        if args.from_json and args.compare:
            print(compare(src, data))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
