"""Segmentation quality on the synthetic scenes: pixel adjusted Rand index (ARI).

For every scene (the bundled sample, seed 0, and freshly rendered held-out seeds), prints
the ARI against ground truth of every option the README's "Segmentation quality" table
lists (:data:`OPTIONS`):

- ``intensity only``: the intensity baseline (block mean and std of Î, the same
  Mahalanobis affinity and recursive normalized cuts, no polarisation);
- ``thesis defaults``: the pipeline with ``SegmentParams()`` (w 10, L 12, n 1.45, 95 %
  variance, s = 1);
- the other columns start from ``RECOMMENDED`` (w 12, L 8, zonal features, s = 2 ×
  median distance, min 4 blocks) and change one thing: the feature kind (thesis,
  energy, ridge coefficients, polarisation statistics, zonal + statistics), the spatial
  term, k-way spectral clustering;
- ``scribbles``: the scribble mode (a classifier on the block features, w 8) trained on
  a fixed small set of strokes (``synthetic.scribble_strokes``: 6 strokes of 16 px per
  material, 1-2 % of the pixels);
- with ``--sweep``: the best cell of a parameter grid per scene (chosen on the same
  scene, so an optimistic upper bound, not a fair score), and the cells with the best
  worst case over all scenes and seeds (how ``RECOMMENDED`` was chosen);
- with ``--limits``: what limits every option, measured (README "Why not 0.8").

Usage::

    .venv/bin/python benchmarks/evaluate.py            # table, ~1 minute
    .venv/bin/python benchmarks/evaluate.py --readme   # and rewrite README's table
    .venv/bin/python benchmarks/evaluate.py --limits   # the limits analysis, ~1 minute
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
from napari_polarseg.engine.synthetic import SCENES, make_scene, scribble_strokes

README = Path(__file__).resolve().parents[1] / "README.md"
BEGIN, END = "<!-- evaluate.py table: begin -->", "<!-- evaluate.py table: end -->"

#: Column name -> parameters (None: a special column computed in ``evaluate``).
OPTIONS: dict[str, SegmentParams | None] = {
    "intensity only": None,
    "thesis defaults": SegmentParams(),
    "thesis features": RECOMMENDED.replace(features="thesis"),
    "zonal (recommended)": RECOMMENDED,
    "energy": RECOMMENDED.replace(features="energy"),
    "ridge coefficients": RECOMMENDED.replace(coefficients="ridge"),
    "polarisation stats": RECOMMENDED.replace(features="polstats"),
    "zonal + stats": RECOMMENDED.replace(features="zonal+polstats"),
    "spatial term": RECOMMENDED.replace(spatial_radius=1.5),
    "k-way": RECOMMENDED.replace(clustering="kway"),
    "k-way, stats": RECOMMENDED.replace(features="polstats", clustering="kway"),
    "scribbles": None,
}
#: Block side of the scribble mode (more, smaller blocks: more training examples).
SCRIBBLE_WINDOW = 8

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
    for column, params in OPTIONS.items():
        if params is not None:
            pipe.params = params.replace(n_segments=k)
            row[column] = ari(truth, pipe.run(reconstruction=False).labels)
    pipe.params = RECOMMENDED.replace(window=SCRIBBLE_WINDOW)
    labels, _ = pipe.scribble_result(scribble_strokes(truth, seed=0))
    row["scribbles"] = ari(truth, labels)
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


def markdown_table(rows: list[dict], cols: list[str]) -> str:
    """The README table: one row per scene and seed, then the mean per scene."""
    lines = [
        "| scene | seed | " + " | ".join(cols) + " |",
        "|---|---|" + "---:|" * len(cols),
    ]
    for r in rows:
        lines.append(
            f"| {r['scene']} | {r['seed']} | " + " | ".join(f"{r[c]:.3f}" for c in cols) + " |"
        )
    for name in SCENES:
        mine = [r for r in rows if r["scene"] == name]
        means = " | ".join(f"**{np.mean([r[c] for r in mine]):.3f}**" for c in cols)
        lines.append(f"| {name} | mean | {means} |")
    return "\n".join(lines)


def write_readme(table: str, command: str) -> None:
    text = README.read_text(encoding="utf-8")
    if BEGIN not in text or END not in text:
        raise SystemExit(f"README.md has no {BEGIN} ... {END} block to replace")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    block = f"{BEGIN}\n<!-- generated by `{command}`; do not edit by hand -->\n\n{table}\n\n{END}"
    README.write_text(head + block + tail, encoding="utf-8")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep", action="store_true", help="also search the grid")
    parser.add_argument("--seeds", default="0,1,2", help="scene seeds (0 = bundled sample)")
    parser.add_argument(
        "--readme", action="store_true", help="rewrite the table in README.md with the result"
    )
    parser.add_argument(
        "--limits", action="store_true", help="only the limits analysis (limits.py), no table"
    )
    args = parser.parse_args(argv)
    if args.limits:
        from limits import main as limits_main

        limits_main()
        return
    seeds = [int(s) for s in args.seeds.split(",")]
    cols = list(OPTIONS)
    if args.sweep:
        cols.append("best of grid")
    t0 = time.perf_counter()
    rows = [evaluate(name, seed, args.sweep) for name in SCENES for seed in seeds]
    print(f"recommended = {RECOMMENDED.to_dict()}\n")
    table = markdown_table(rows, cols)
    print(table)
    print()
    if args.sweep:
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
    if args.readme:
        cmd = "python benchmarks/evaluate.py --readme"
        if args.seeds != "0,1,2":
            cmd += f" --seeds {args.seeds}"
        write_readme(markdown_table(rows, list(OPTIONS)), cmd)
        print(f"README.md table rewritten ({README})")


if __name__ == "__main__":
    main()
