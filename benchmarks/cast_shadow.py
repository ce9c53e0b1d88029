"""A cast shadow is not a material: how far each method's segments follow a shadow
laid across scenes whose truth is known.

A shadow of the direct light multiplies the mean intensity Î of the pixels it covers by
a factor f and leaves ρ and φ as they are (ambient light of the same polarisation as
the direct light; the sensor's noise then weighs more in the shadow). Each scene is
rendered again from its noise-free maps (``SyntheticScene.intensity``, ``dop``,
``phase``, or the planted maps below) with Î × (f inside the shadow, 1 outside; the
shadow's edge a Gaussian penumbra of :data:`PENUMBRA` px), the scene's own noise and
12-bit quantisation, and segmented into the truth's number of classes by:

- intensity k-means and k-means on the 20 smoothed polarisation features (the plain
  baselines of ``baselines.py``), ``superpixels``, the default (``auto``), the default
  without its border gate (``border_gate = 0``: a border's log Î edges weigh in full)
  and ``polarisation_borders`` (the default's method with its borders weighed on the
  polarisation edges alone);

and scored against the materials (ARI over every pixel) and, for the default, against
the shadow (ARI of its labels with the lit / shadowed split: 1 = the segments are the
shadow). The shadow is a set of parallel bands at an angle drawn from the scene's seed
(:func:`shadow_mask`), so it crosses every material.

Scenes: ``planted``: two plastics side by side along a wavy border (ρ 0.08 and 0.25,
φ of two smooth surfaces, Î the same shading ramp on both), which every method
separates without a shadow; the engine's ``leaves``, ``camouflage`` and
``scattered_leaves`` (diffuse polarisation, 240 × 320, object size 25 px for the last),
seeds 0–2 each.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python cast_shadow.py [--factors 1,0.7,0.5,0.3]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator

import numpy as np
from baselines import intensity_kmeans, smoothed_kmeans
from families import standard_error
from family_variants import VARIANTS, register
from scipy import ndimage
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Scene
from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.synthetic.optics import render_stack
from napari_polarseg.engine.synthetic.scenes import make_scene

#: The default with its log Î borders ungated (``border_gate = 0``), as registered here.
UNGATED = register("no border gate", VARIANTS["no border gate"])
#: σ (px) of the Gaussian penumbra of the shadow's edge.
PENUMBRA = 2.0
#: Width of one shadow band, a share of the short side.
BAND = 0.3
#: Noise of the planted scene, a share of full scale (the engine's scenes keep theirs).
PLANTED_NOISE = 0.003
SHAPE = (240, 320)
ANGLES = np.deg2rad([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])
SCENES = ("planted", "leaves", "camouflage", "scattered_leaves")
SEEDS = (0, 1, 2)
METHODS = (
    "intensity k-means",
    "smoothed k-means",
    "superpixels",
    "default",
    "default without the border gate",
    "polarisation_borders",
)


def shadow_mask(shape: tuple[int, int], seed: int) -> np.ndarray:
    """(H, W) bool: parallel bands of shadow (a branch's or a blind's), each
    :data:`BAND` of the short side wide with as much light between, at an angle and
    offset drawn from ``seed``: every material lies partly in the shadow and partly
    out of it, whatever the layout."""
    rng = np.random.default_rng(1000 + seed)
    h, w = shape
    angle, offset = rng.uniform(0.0, np.pi), rng.uniform(0.0, 2.0 * np.pi)
    yy, xx = np.mgrid[0:h, 0:w]
    across = yy * np.cos(angle) - xx * np.sin(angle)
    return np.sin(np.pi * across / (BAND * min(h, w)) + offset) > 0


def planted_maps(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Î, ρ, φ and the truth (0, 1) of the planted two-plastic scene (module docstring)."""
    h, w = SHAPE
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    wave = 0.1 * w * np.sin(yy / (0.15 * h) + seed)
    truth = (xx > 0.45 * w + wave).astype(int)
    rho = np.where(truth == 1, 0.25, 0.08) + 0.02 * yy / h
    phi = np.where(truth == 1, 0.3 + 0.4 * xx / w, 1.2 - 0.3 * yy / h)
    intensity = 0.4 * (0.8 + 0.2 * xx / w)
    return intensity, rho, phi, truth


def scenes(factors: list[float]) -> Iterator[tuple[str, float, np.ndarray, np.ndarray, np.ndarray]]:
    """(name, f, stack, truth, shadow) of every scene and seed at every shadow factor."""
    for name in SCENES:
        for seed in SEEDS:
            if name == "planted":
                intensity, rho, phi, truth = planted_maps(seed)
                noise = PLANTED_NOISE
            else:
                size = 25.0 if name == "scattered_leaves" else None
                sc = make_scene(name, shape=SHAPE, seed=seed, object_size=size)
                intensity, rho, phi, truth = sc.intensity, sc.dop, sc.phase, sc.labels
                noise = float(sc.params["noise_sigma"])
            shadow = shadow_mask(truth.shape, seed)
            soft = ndimage.gaussian_filter(shadow.astype(float), PENUMBRA)
            for f in factors:
                shade = 1.0 - (1.0 - f) * soft
                stack = render_stack(
                    intensity * shade, rho, phi, ANGLES, noise_sigma=noise, bit_depth=12, rng=seed
                )
                yield f"{name}-{seed}", f, stack, truth, shadow


def segment_all(stack: np.ndarray, k: int) -> dict[str, np.ndarray]:
    """Labels of every method of :data:`METHODS` into k segments."""
    scene = Scene(stack, ANGLES)
    params = PRESETS["auto"].replace(n_segments=k)
    pol = scene.polarisation(params)
    return {
        "intensity k-means": intensity_kmeans(pol.intensity, k),
        "smoothed k-means": smoothed_kmeans(pol.intensity, pol.dop, pol.phase, k),
        "superpixels": scene.segment(params.replace(method="superpixels")).labels,
        "default": scene.segment(params).labels,
        "default without the border gate": scene.segment(params.replace(method=UNGATED)).labels,
        "polarisation_borders": scene.segment(params.replace(method="polarisation_borders")).labels,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factors", default="1,0.7,0.5,0.3", help="shadow factors f")
    args = ap.parse_args(argv)
    factors = [float(f) for f in args.factors.split(",")]
    scores: dict[tuple[str, float], dict[str, float]] = {}
    t0 = time.perf_counter()
    for name, f, stack, truth, shadow in scenes(factors):
        labels = segment_all(stack, len(np.unique(truth)))
        row = {m: adjusted_rand_score(truth.ravel(), x.ravel()) for m, x in labels.items()}
        row["default follows the shadow"] = adjusted_rand_score(
            shadow.ravel(), labels["default"].ravel()
        )
        scores[(name, f)] = row
        print(f"{name} f={f:g}: " + ", ".join(f"{m} {v:.3f}" for m, v in row.items()), flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s\n")
    columns = [*METHODS, "default follows the shadow"]
    print("| scenes | f | " + " | ".join(columns) + " | default − default at f = 1 |")
    print("|---|---:|" + "---:|" * (len(columns) + 1))
    for scene in SCENES:
        names = sorted({n for n, _ in scores if n.startswith(f"{scene}-")})
        for f in factors:
            cells = [f"{np.mean([scores[(n, f)][c] for n in names]):.3f}" for c in columns]
            d = np.array(
                [scores[(n, f)]["default"] - scores[(n, factors[0])]["default"] for n in names]
            )
            cells.append(f"{d.mean():+.3f} ± {standard_error(d):.3f}")
            print(f"| {scene} | {f:g} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
