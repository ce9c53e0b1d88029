"""The diffuse-regime family of the bench: the engine's own synthetic generator.

Scenes of :func:`napari_polarseg.engine.synthetic.scenes.make_scene` at shape 240 × 320
with the 7 default polariser angles (0..180° in 30° steps), 12-bit, default noise:

- ``leaves``, ``scattered_leaves``, ``texture_patches`` at three object sizes (the
  ``object_size`` knob, :data:`SIZES`), chosen so the measured object size (below) is
  about 12, 25 and 50 px; for ``leaves`` (natural left, plastic right, heavily
  overlapping, so each leaf shows a third of its length) the large size stops at leaves
  half the frame high (measured about 38 px);
- ``camouflage`` and ``fruit`` (no knob: one large object each).

Two seeds per layout and size. Development half: seeds 0..5 of each layout (fixed).
Test half: seeds ``10_000 + 6 · test_base + j``, so any other ``test_base >= 0`` draws a
fresh, disjoint test half.

Each scene is a :class:`BenchScene`: labels = the synthetic labels + 1 (every pixel is
scored), k = the number of materials present, object size = the median equivalent
diameter √(4A/π) (px) of the scene's instances of at least :data:`MIN_INSTANCE_AREA` px.

Usage::

    cd benchmarks && PYTHONPATH=.. ../.venv/bin/python diffuse_family.py --half dev
    cd benchmarks && PYTHONPATH=.. ../.venv/bin/python diffuse_family.py --half test --test-base 3
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from napari_polarseg.engine.synthetic.scenes import make_scene

SHAPE = (240, 320)
#: object_size knob (px) of each layout for the sizes small, medium, large; None: the
#: layout has no knob (its one default size).
SIZES: dict[str, tuple[float | None, ...]] = {
    "leaves": (36.0, 75.0, 120.0),  # leaf length
    "camouflage": (None,),
    "fruit": (None,),
    "scattered_leaves": (24.0, 50.0, 110.0),  # leaf length
    "texture_patches": (15.0, 30.0, 70.0),  # blob diameter
}
SIZE_NAMES = ("small", "medium", "large")
SEEDS_PER_SIZE = 2
#: Seeds a layout uses per half (3 sizes × 2 seeds): the stride of ``test_base``.
SEEDS_PER_HALF = 6
TEST_SEED_BASE = 10_000
#: Instances below this area (px) are left out of the object size.
MIN_INSTANCE_AREA = 9


@dataclass(frozen=True)
class BenchScene:
    """One scored scene: angle stack (N, H, W), angles (radians), labels (int32, 0 =
    unlabelled, 1..k the materials), k, object size (px) and family; plus the layout,
    seed and material names it came from."""

    name: str
    stack: np.ndarray
    angles: np.ndarray
    labels: np.ndarray
    k: int
    object_size: float
    family: str = "diffuse"
    layout: str = ""
    seed: int = 0
    material_names: tuple[str, ...] = ()


def median_instance_diameter(instances: np.ndarray, min_area: int = MIN_INSTANCE_AREA) -> float:
    """Median equivalent diameter √(4A/π) in px of the instances (ids > 0) of at least
    ``min_area`` px; NaN if there is none."""
    areas = np.bincount(np.asarray(instances).ravel().clip(0))[1:]
    areas = areas[areas >= min_area]
    return float(np.median(np.sqrt(4.0 * areas / np.pi))) if areas.size else float("nan")


def scene_seed(half: str, j: int, test_base: int = 0) -> int:
    """Seed of a layout's ``j``-th scene (0..5) in ``half``."""
    if half == "dev":
        return j
    return TEST_SEED_BASE + SEEDS_PER_HALF * test_base + j


def family_scenes(half: str, test_base: int = 0) -> list[BenchScene]:
    """Every scene of one half of the diffuse family (module docstring), in layout order.

    ``half``: ``"dev"`` or ``"test"``; ``test_base`` (>= 0) picks the test half's seeds.
    """
    if half not in ("dev", "test"):
        raise ValueError(f"half must be 'dev' or 'test', got {half!r}")
    if int(test_base) < 0:
        raise ValueError(f"test_base must be >= 0, got {test_base!r}")
    return [_bench_scene(*draw) for draw in scene_draws(half, test_base)]


def scene_draws(half: str, test_base: int = 0) -> list[tuple[str, float | None, str, int]]:
    """(layout, object_size knob, size name, seed) of every scene of one half, in layout
    order (:func:`family_scenes` renders them)."""
    return [
        (layout, size, SIZE_NAMES[s], scene_seed(half, s * SEEDS_PER_SIZE + i, int(test_base)))
        for layout, sizes in SIZES.items()
        for s, size in enumerate(sizes)
        for i in range(SEEDS_PER_SIZE)
    ]


def _bench_scene(layout: str, size: float | None, size_name: str, seed: int) -> BenchScene:
    """One rendered :class:`BenchScene`."""
    sc = make_scene(layout, shape=SHAPE, seed=seed, object_size=size)
    labels = (sc.labels + 1).astype(np.int32)
    name = f"{layout}-{seed}" if size is None else f"{layout}-{size_name}-{seed}"
    return BenchScene(
        name=name,
        stack=sc.stack,
        angles=sc.angles,
        labels=labels,
        k=len(np.unique(labels)),
        object_size=median_instance_diameter(sc.instances),
        layout=layout,
        seed=seed,
        material_names=tuple(sc.material_names),
    )


def main() -> None:
    """Print each scene of a half: name, k, class shares and object size; and the time."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--half", choices=("dev", "test"), default="dev")
    parser.add_argument("--test-base", type=int, default=0)
    args = parser.parse_args()
    start, cpu = time.perf_counter(), time.process_time()
    scenes = family_scenes(args.half, test_base=args.test_base)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    print(f"{'scene':32s} {'k':>2s} {'size px':>8s}  class shares (material)")
    for s in scenes:
        shares = np.bincount(s.labels.ravel(), minlength=s.k + 1)[1:] / s.labels.size
        parts = ", ".join(
            f"{share:.0%} {m}" for share, m in zip(shares, s.material_names, strict=False)
        )
        print(f"{s.name:32s} {s.k:2d} {s.object_size:8.1f}  {parts}")
    size = f"{SHAPE[0]} × {SHAPE[1]}"
    print(f"{len(scenes)} scenes of {size} rendered in {elapsed:.1f} s ({cpu:.1f} s CPU)")


if __name__ == "__main__":
    main()
