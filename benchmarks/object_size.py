"""The object-size estimate against the truth, scene by scene and set by set.

:func:`~napari_polarseg.engine.features.object_size.estimate_object_size` (from Î, ρ, φ
alone) against the truth's median object size: the median equivalent diameter √(4A/π)
(px) of the scene's ``instances`` where it has them
(:func:`~napari_polarseg.engine.features.object_size.instance_size`), else of the
connected components of its object classes
(:func:`~napari_polarseg.engine.features.object_size.component_size`: labels ≥ 2 on a
render, where 0 is the sky and 1 the floor; labels > 0 on a synthetic scene). Components
merge touching objects, so without instances the truth can be far larger than what one
sees as an object (a ``c`` after the truth marks it).

Sets (a missing folder is reported and skipped):

- ``shared``: the 24 shared Mitsuba renders ``../shared/data/rendered/scene_<n>.npz``;
- ``objects-fresh``, ``small-dev``, ``small-test``, ``textured-dev``, ``textured-test``:
  the render folders of ``render_scenes.py --layout ...`` beside this script
  (git-ignored; ``families.py`` names the commands);
- ``thesis``: the engine's synthetic ``leaves`` (seeds 0–3) and ``camouflage`` (seeds
  0–1) at 240 × 320;
- ``layouts``: the synthetic ``scattered_leaves`` and ``texture_patches`` at the three
  object sizes of ``diffuse_family.py`` (seed 0).

The hand-labelled real frames are not scored: their truth polygons lie inside the
objects (``families.py``), so they give no object size.

Î, ρ, φ come from the engine's own sinusoid fit
(:func:`~napari_polarseg.engine.physics.polarimage.polarisation_image`); its invalid
pixels are left out (``mask``). Per scene: estimate, truth, their ratio and the
estimate's time; per set: the median ratio and the count outside [1/1.5, 1.5].

Usage::

    cd benchmarks && PYTHONPATH=.. OMP_NUM_THREADS=1 ../.venv/bin/python object_size.py
    ... object_size.py --sets shared thesis --quiet
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from napari_polarseg.engine.features.object_size import (
    component_size,
    estimate_object_size,
    instance_size,
)
from napari_polarseg.engine.physics.polarimage import polarisation_image
from napari_polarseg.engine.synthetic.scenes import make_scene

HERE = Path(__file__).resolve().parent
SHARED_DIR = HERE.parents[1] / "shared" / "data" / "rendered"
#: Render folders beside this script (set name → folder).
RENDER_FOLDERS = {
    "objects-fresh": HERE / "renders_objects_fresh",
    "small-dev": HERE / "renders_small_dev",
    "small-test": HERE / "renders_small_test",
    "textured-dev": HERE / "renders_textured_dev",
    "textured-test": HERE / "renders_textured_test",
}
#: Synthetic thesis scenes (name → seeds) and layouts (name → object sizes, px).
THESIS = {"leaves": (0, 1, 2, 3), "camouflage": (0, 1)}
LAYOUT_SIZES = {"scattered_leaves": (24.0, 50.0, 110.0), "texture_patches": (15.0, 30.0, 70.0)}
SYNTHETIC_SHAPE = (240, 320)
SETS = ("shared", *RENDER_FOLDERS, "thesis", "layouts")
#: The accepted factor between estimate and truth.
FACTOR = 1.5


@dataclass(frozen=True)
class Case:
    """One scene: its angle stack (N, H, W), angles (radians) and truth size (px)."""

    name: str
    stack: np.ndarray
    angles: np.ndarray
    truth: float
    from_components: bool


def render_case(path: Path) -> Case:
    """A ``scene_<n>.npz`` render: instances if it has them, else components of the
    object labels (≥ 2)."""
    with np.load(path, allow_pickle=False) as f:
        stack, angles, labels = f["stack"], np.deg2rad(f["angles"]), f["labels"]
        instances = f["instances"] if "instances" in f.files else None
    if instances is not None:
        return Case(path.stem, stack, angles, instance_size(instances), False)
    classes = [int(c) for c in np.unique(labels) if c >= 2]
    return Case(path.stem, stack, angles, component_size(labels, classes), True)


def seed_of(path: Path) -> int:
    return int(path.stem.rsplit("_", 1)[-1])


def render_cases(folder: Path) -> Iterator[Case]:
    for path in sorted(folder.glob("scene_*.npz"), key=seed_of):
        yield render_case(path)


def synthetic_case(name: str, seed: int, size: float | None = None) -> Case:
    """A synthetic scene: its ``instances`` where the generator gives them, else the
    components of labels > 0."""
    kwargs = {} if size is None else {"object_size": size}
    scene = make_scene(name, shape=SYNTHETIC_SHAPE, seed=seed, **kwargs)
    tag = f"{name}-{seed}" if size is None else f"{name}-{size:g}px-{seed}"
    instances = getattr(scene, "instances", None)
    if instances is not None:
        return Case(tag, scene.stack, scene.angles, instance_size(instances), False)
    return Case(tag, scene.stack, scene.angles, component_size(scene.labels, [1, 2, 3]), True)


def cases(set_name: str) -> Iterator[Case]:
    """The scenes of one set (module docstring)."""
    if set_name == "shared":
        paths = sorted(SHARED_DIR.glob("scene_*.npz"), key=seed_of)
        if not paths:
            print(f"  no renders in {SHARED_DIR}: skipped")
        for path in paths:
            yield render_case(path)
    elif set_name in RENDER_FOLDERS:
        folder = RENDER_FOLDERS[set_name]
        if not any(folder.glob("scene_*.npz")):
            print(f"  no renders in {folder} (families.py names the command): skipped")
            return
        yield from render_cases(folder)
    elif set_name == "thesis":
        for name, seeds in THESIS.items():
            for seed in seeds:
                yield synthetic_case(name, seed)
    elif set_name == "layouts":
        for name, sizes in LAYOUT_SIZES.items():
            for size in sizes:
                yield synthetic_case(name, 0, size)
    else:
        raise ValueError(f"unknown set {set_name!r}; one of {', '.join(SETS)}")


def run_set(set_name: str, quiet: bool) -> tuple[list[float], float]:
    """Print one line per scene and the set's summary; return the ratios and the
    slowest estimate (s)."""
    print(f"\n== {set_name}")
    if not quiet:
        print(f"  {'scene':28s} {'estimate':>9s} {'truth':>9s} {'ratio':>6s} {'ms':>5s}")
    ratios, slowest = [], 0.0
    for case in cases(set_name):
        pol = polarisation_image(case.stack, case.angles)
        valid = ~np.asarray(pol.invalid, dtype=bool)
        t0 = time.perf_counter()
        est = estimate_object_size(pol.intensity, pol.dop, pol.phase, valid)
        seconds = time.perf_counter() - t0
        slowest = max(slowest, seconds)
        ratio = est.size_px / case.truth if case.truth > 0 else float("nan")
        ratios.append(ratio)
        outside = np.isfinite(ratio) and not (1.0 / FACTOR <= ratio <= FACTOR)
        if not quiet:
            mark = " c" if case.from_components else "  "
            flag = "  outside" if outside else ""
            print(
                f"  {case.name:28s} {est.size_px:9.1f} {case.truth:7.1f}{mark} {ratio:6.2f} "
                f"{1000 * seconds:5.0f}{flag}"
            )
    finite = np.asarray([r for r in ratios if np.isfinite(r)])
    if finite.size:
        out = int(np.sum((finite > FACTOR) | (finite < 1.0 / FACTOR)))
        print(
            f"  {set_name}: {finite.size} scenes, median ratio {np.median(finite):.2f}, "
            f"{out} outside [1/{FACTOR:g}, {FACTOR:g}]"
        )
    return ratios, slowest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS))
    parser.add_argument("--quiet", action="store_true", help="only the per-set lines")
    args = parser.parse_args()
    start = time.perf_counter()
    summary = []
    for set_name in args.sets:
        ratios, slowest = run_set(set_name, args.quiet)
        summary.append((set_name, ratios, slowest))
    print(f"\n{'set':16s} {'scenes':>6s} {'median ratio':>13s} {'outside':>8s} {'slowest s':>10s}")
    for set_name, ratios, slowest in summary:
        finite = np.asarray([r for r in ratios if np.isfinite(r)])
        if not finite.size:
            print(f"{set_name:16s} {0:6d} {'—':>13s} {'—':>8s} {'—':>10s}")
            continue
        out = int(np.sum((finite > FACTOR) | (finite < 1.0 / FACTOR)))
        print(f"{set_name:16s} {finite.size:6d} {np.median(finite):13.2f} {out:8d} {slowest:10.3f}")
    # the speed on a full-resolution polarisation-camera frame
    rng = np.random.default_rng(0)
    frame = rng.uniform(0.2, 0.8, (1024, 1224))
    t0 = time.perf_counter()
    estimate_object_size(frame, 0.5 * frame, 3.0 * frame)
    print(f"one 1224 × 1024 frame: {time.perf_counter() - t0:.3f} s")
    print(f"total {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
