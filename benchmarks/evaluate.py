"""Segmentation quality on the synthetic scenes: pixel adjusted Rand index (ARI).

For every scene (the bundled sample, seed 0, and freshly rendered held-out seeds), prints
the ARI against ground truth of

- ``intensity only``: the intensity baseline (block mean and std of Î, the same
  Mahalanobis affinity and recursive normalized cuts, no polarisation);
- ``thesis defaults``: the pipeline with ``SegmentParams()`` (w 10, L 12, n 1.45, 95 %
  variance, s = 1);
- ``recommended``: the pipeline with ``RECOMMENDED`` (napari_polarseg.engine.params);
- with ``--sweep``: the best cell of a parameter grid per scene (chosen on the same
  scene, so an optimistic upper bound, not a fair score), and the cells with the best
  worst case over all scenes and seeds (how ``RECOMMENDED`` was chosen).

Usage::

    .venv/bin/python benchmarks/evaluate.py            # table, ~1 minute
    .venv/bin/python benchmarks/evaluate.py --sweep    # plus the grid search, ~5 minutes
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline, SegmentParams, intensity_baseline
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.engine.synthetic import SCENES, make_scene

SAMPLES = Path(__file__).resolve().parents[1] / "napari_polarseg" / "sample_data"

GRID = {
    "features": ["thesis", "zonal", "energy"],
    "window": [8, 10, 12, 16],
    "degree": [4, 6, 8, 12],
    "scale": [1.0, 2.0, 4.0],
    "scale_mode": ["median"],
    "spatial_radius": [0.0, 1.5],
    "min_segment_blocks": [4],
}


def load(name: str, seed: int):
    """(stack, angles in radians, ground truth) of a scene: the bundled file for seed 0."""
    if seed == 0 and (SAMPLES / f"{name}.npz").exists():
        with np.load(SAMPLES / f"{name}.npz", allow_pickle=False) as f:
            return f["stack"], np.deg2rad(f["angles"]), f["labels"]
    sc = make_scene(name, seed=seed)
    return sc.stack, sc.angles, sc.labels


def ari(truth: np.ndarray, labels: np.ndarray) -> float:
    return float(adjusted_rand_score(truth.ravel(), labels.ravel()))


def evaluate(name: str, seed: int, sweep: bool) -> dict:
    stack, angles, truth = load(name, seed)
    k = int(truth.max()) + 1
    row = {"scene": name, "seed": seed, "k": k}
    intensity = stack.astype(float).mean(axis=0)
    row["intensity only"] = ari(truth, intensity_baseline(intensity, 10, k))
    pipe = Pipeline(stack, angles, SegmentParams(n_segments=k))
    row["thesis defaults"] = ari(truth, pipe.run(reconstruction=False).labels)
    pipe.params = RECOMMENDED.replace(n_segments=k)
    row["recommended"] = ari(truth, pipe.run(reconstruction=False).labels)
    if sweep:
        row["grid"] = {}
        for values in itertools.product(*GRID.values()):
            change = dict(zip(GRID, values, strict=True))
            pipe.params = SegmentParams(n_segments=k, **change)
            row["grid"][values] = ari(truth, pipe.run(reconstruction=False).labels)
        best = max(row["grid"], key=row["grid"].get)
        row["best of grid"] = row["grid"][best]
        row["best params"] = dict(zip(GRID, best, strict=True))
    return row


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep", action="store_true", help="also search the grid")
    parser.add_argument("--seeds", default="0,1,2", help="scene seeds (0 = bundled sample)")
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    cols = ["intensity only", "thesis defaults", "recommended"]
    if args.sweep:
        cols.append("best of grid")
    t0 = time.perf_counter()
    rows = [evaluate(name, seed, args.sweep) for name in SCENES for seed in seeds]
    print(f"recommended = {RECOMMENDED.to_dict()}\n")
    header = f"| {'scene':<11}| seed | k | " + " | ".join(f"{c:>15}" for c in cols) + " |"
    print(header)
    print("|" + "|".join("-" * (len(p)) for p in header.split("|")[1:-1]) + "|")
    for r in rows:
        cells = " | ".join(f"{r[c]:>15.3f}" for c in cols)
        print(f"| {r['scene']:<11}| {r['seed']:>4} | {r['k']} | {cells} |")
    print()
    for name in SCENES:
        mine = [r for r in rows if r["scene"] == name]
        means = "  ".join(f"{c}: {np.mean([r[c] for r in mine]):.3f}" for c in cols)
        print(f"mean over seeds, {name}: {means}")
    if args.sweep:
        print()
        for r in rows:
            print(f"best cell {r['scene']} seed {r['seed']}: {r['best params']}")
        cells = rows[0]["grid"].keys()
        worst = {c: min(r["grid"][c] for r in rows) for c in cells}
        print("\ncells with the best worst case over every scene and seed:")
        for c in sorted(cells, key=lambda c: -worst[c])[:8]:
            per_scene = {
                n: round(float(np.mean([r["grid"][c] for r in rows if r["scene"] == n])), 3)
                for n in SCENES
            }
            cell = dict(zip(GRID, c, strict=True))
            print(f"  worst {worst[c]:.3f}  mean per scene {per_scene}  {cell}")
    print(f"\n{time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
