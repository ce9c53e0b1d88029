"""Segmentation quality on the synthetic scenes: pixel adjusted Rand index (ARI).

For every scene (the bundled sample, seed 0, and freshly rendered held-out seeds), prints
the ARI against ground truth of every option the "Segmentation quality" table
(docs/quality.md) lists (:data:`OPTIONS`):

- ``intensity only``: the intensity baseline (block mean and std of Î, the same
  Mahalanobis affinity and recursive normalized cuts, no polarisation);
- ``thesis defaults``: the pipeline with ``SegmentParams(method="thesis")`` (w 10, L 12,
  n 1.45, 95 % variance, s = 1);
- the other columns start from ``RECOMMENDED`` (w 12, L 8, zonal features, s = 2 ×
  median distance, min 4 blocks) and change one thing: the feature kind (thesis,
  energy, ridge coefficients, polarisation statistics, zonal + statistics), the spatial
  term, k-way spectral clustering;
- ``block scribbles``: the older scribble mode (a logistic regression on the block
  features, w 8) trained on a fixed small set of strokes (``synthetic.scribble_strokes``:
  6 strokes of 16 px per material, 1-2 % of the pixels);
- ``plain baseline``: a random forest on 20 Gaussian-smoothed polarisation features
  (``baselines.plain_baseline``) trained on the same strokes — the floor every method
  is read against;
- ``pixel classifier``: the product's scribble classifier (``engine.classifier.pixel_classifier``
  with its default features and parameters) on the same strokes;
- then, per scene, the pixel classifier against its target (0.8) and the plain
  baseline, beside a bound: the best classifier we train on the richest pixel features
  with the *truth* of the other seeds (``truth_bound``; ``--no-bound`` skips it);
- the real frames with hand-drawn truth (``napari_polarseg/sample_data/truth``, frames
  in ``../shared/data/polanalyser``): intensity k-means, the thesis defaults and
  ``RECOMMENDED`` cut into as many segments as there are classes, the plain baseline and
  the pixel classifier on the truth file's strokes, and the in-sample bound (trained on
  the frame's own truth); ARI over the labelled pixels, degenerate results marked;
- the material tables (``materials.py``): the rendered scenes (development half, seeds
  0–11, and test half, seeds 12–23, each with its means) and the real frames, one row
  per frame: intensity k-means, smoothed k-means, the default (preset ``auto``) and the
  truth-trained left→right bounds; degenerate results marked ‡ and counted (the render
  sets of ``materials.RENDER_SETS`` with their flags);
- with ``--sweep``: the best cell of a parameter grid per scene (chosen on the same
  scene, so an optimistic upper bound, not a fair score), and the cells with the best
  worst case over all scenes and seeds (how ``RECOMMENDED`` was chosen);
- with ``--limits``: what limits every option, measured (docs/quality.md, "Why not 0.8").

Usage::

    .venv/bin/python benchmarks/evaluate.py            # tables, ~6 minutes
    .venv/bin/python benchmarks/evaluate.py --docs     # and rewrite docs/quality.md's tables
    .venv/bin/python benchmarks/evaluate.py --limits   # the limits analysis, ~1 minute
    .venv/bin/python benchmarks/evaluate.py --sweep    # plus the grid search, ~5 minutes
    .venv/bin/python benchmarks/evaluate.py --rendered dev      # only the rendered dev half
    .venv/bin/python benchmarks/evaluate.py --rendered all --real --bounds plain
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import materials
import numpy as np
from baselines import intensity_kmeans, plain_baseline, real_frames
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline, Scene, SegmentParams, intensity_baseline
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams, make_model
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.classifier.scribbles import scribble_result
from napari_polarseg.engine.features.pixel_feature_params import GROUPS
from napari_polarseg.engine.features.pixel_features import PixelFeatureParams, pixel_features
from napari_polarseg.engine.params import AUTO, RECOMMENDED
from napari_polarseg.engine.synthetic.scenes import SCENES, make_scene, scribble_strokes

#: The page whose table block ``--docs`` (alias ``--readme``) rewrites.
QUALITY_PAGE = Path(__file__).resolve().parents[1] / "docs" / "quality.md"
BEGIN, END = "<!-- evaluate.py table: begin -->", "<!-- evaluate.py table: end -->"

#: Column name -> parameters (None: a special column computed in ``evaluate``).
OPTIONS: dict[str, SegmentParams | None] = {
    "intensity only": None,
    "thesis defaults": SegmentParams(method="thesis"),
    "thesis features": RECOMMENDED.replace(features="thesis"),
    "zonal (recommended)": RECOMMENDED,
    "energy": RECOMMENDED.replace(features="energy"),
    "ridge coefficients": RECOMMENDED.replace(coefficients="ridge"),
    "polarisation stats": RECOMMENDED.replace(features="polstats"),
    "zonal + stats": RECOMMENDED.replace(features="zonal+polstats"),
    "spatial term": RECOMMENDED.replace(spatial_radius=1.5),
    "k-way": RECOMMENDED.replace(clustering="kway"),
    "k-way, stats": RECOMMENDED.replace(features="polstats", clustering="kway"),
    "auto (default)": AUTO,
    "block scribbles": None,
    "plain baseline": None,
    "pixel classifier": None,
}
#: Columns trained on the fixed strokes (the others are unsupervised).
SUPERVISED = ("block scribbles", "plain baseline", "pixel classifier")
#: Richest features for the bound (every group, ilastik-like scales).
BOUND_FEATURES = PixelFeatureParams(scales=(1.0, 2.0, 4.0, 8.0, 16.0), groups=GROUPS)
#: Pixels sampled from the truth that trains the bound's classifier.
BOUND_PIXELS = 20_000
#: The real frames: ../shared/data/polanalyser beside the repository.
REAL_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "polanalyser"
#: A result is degenerate when one segment holds this share of the pixels.
DEGENERATE_SHARE = 0.95
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
    pipe = Pipeline(stack, angles, SegmentParams(method="thesis", n_segments=k))
    for column, params in OPTIONS.items():
        if params is not None:
            row[column] = ari(
                truth,
                Scene(pipeline=pipe)
                .segment(params.replace(n_segments=k), reconstruction=False)
                .labels,
            )
    strokes = scribble_strokes(truth, seed=0)
    labels, _ = scribble_result(pipe, strokes, RECOMMENDED.replace(window=SCRIBBLE_WINDOW))
    row["block scribbles"] = ari(truth, labels)
    pol = pipe.get("polarisation")
    row["plain baseline"] = ari(truth, plain_baseline(pol.intensity, pol.dop, pol.phase, strokes))
    row["pixel classifier"] = ari(truth, PixelSegmenter(pipe).segment(strokes).result.labels)
    if sweep:
        row["grid"] = {}
        for values in itertools.product(*GRID.values()):
            change = dict(zip(GRID, values, strict=True))
            params = SegmentParams(method="thesis", n_segments=k, **change)
            row["grid"][values] = ari(
                truth, Scene(pipeline=pipe).segment(params, reconstruction=False).labels
            )
        best = max(row["grid"], key=row["grid"].get)
        row["best of grid"] = row["grid"][best]
        row["best params"] = dict(zip(GRID, best, strict=True))
    return row


def truth_bound(train: list[tuple], test: tuple) -> float:
    """ARI on ``test`` of the best classifier we train on the richest pixel features
    (:data:`BOUND_FEATURES`, a random forest of 200 trees) with the *truth* of the
    ``train`` scenes: what the features can tell apart with all the labels there are.
    Each item is (intensity, dop, phase, truth, weight mask or None)."""
    rng = np.random.default_rng(0)
    xs, ys = [], []
    for i, d, p, t, where in train:
        f = pixel_features(i, d, p, BOUND_FEATURES)
        pick = np.flatnonzero(where.ravel() if where is not None else np.ones(t.size, bool))
        pick = rng.choice(pick, min(BOUND_PIXELS, pick.size), replace=False)
        xs.append(f.take(pick))
        ys.append(t.ravel()[pick])
    model = make_model(ClassifierParams(n_estimators=200, balance_classes=True))
    model.fit(np.concatenate(xs), np.concatenate(ys))
    i, d, p, t, where = test
    f = pixel_features(i, d, p, BOUND_FEATURES)
    pred = np.concatenate(
        [model.predict(f.rows(r, min(r + 128, t.shape[0]))) for r in range(0, t.shape[0], 128)]
    ).reshape(t.shape)
    return ari_where(t, pred, where)


def ari_where(truth: np.ndarray, labels: np.ndarray, where: np.ndarray | None) -> float:
    """ARI over the pixels ``where`` (all when None)."""
    if where is None:
        return ari(truth, labels)
    return float(adjusted_rand_score(truth[where], labels[where]))


def largest_share(labels: np.ndarray) -> float:
    """Share of the pixels in the largest segment."""
    return float(np.bincount(np.asarray(labels).ravel()).max() / labels.size)


#: Columns of the real-frame table.
REAL_COLUMNS = (
    "intensity k-means",
    "thesis defaults",
    "recommended",
    "auto (default)",
    "plain baseline",
    "pixel classifier",
    "bound: all truth",
)


def evaluate_real(folder: Path) -> list[dict]:
    """Every real frame with hand-drawn truth: ARI over the labelled pixels.

    The supervised columns train on the truth file's fixed strokes; the unsupervised
    ones cut into as many segments as the truth has classes. ``bound: all truth`` trains
    on the frame's whole truth (sampled) and is scored on the same frame: an in-sample
    upper bound of the features, not a fair score. A degenerate result (one segment with
    ≥ 95 % of the pixels) is recorded in ``degenerate``.
    """
    rows = []
    for truth_file, data in real_frames(folder):
        truth, strokes = truth_file.truth, truth_file.strokes
        where = truth > 0
        k = len(truth_file.classes)
        row: dict = {"scene": truth_file.frame, "k": k, "degenerate": []}
        pipe = Pipeline(data.stack, data.angles_rad, SegmentParams(method="thesis", n_segments=k))
        pol = pipe.get("polarisation")
        row["intensity k-means"] = ari_where(truth, intensity_kmeans(pol.intensity, k), where)
        presets = (
            ("thesis defaults", SegmentParams(method="thesis")),
            ("recommended", RECOMMENDED),
            ("auto (default)", AUTO),
        )
        for column, params in presets:
            t0 = time.perf_counter()
            labels = (
                Scene(pipeline=pipe)
                .segment(params.replace(n_segments=k), reconstruction=False)
                .labels
            )
            row[column] = ari_where(truth, labels, where)
            row[f"{column} seconds"] = time.perf_counter() - t0
            if largest_share(labels) >= DEGENERATE_SHARE:
                row["degenerate"].append(column)
        row["plain baseline"] = ari_where(
            truth, plain_baseline(pol.intensity, pol.dop, pol.phase, strokes), where
        )
        t0 = time.perf_counter()
        out = PixelSegmenter(pipe).segment(strokes, reconstruction=False)
        row["pixel classifier seconds"] = time.perf_counter() - t0
        row["pixel classifier"] = ari_where(truth, out.result.labels, where)
        item = (pol.intensity, pol.dop, pol.phase, truth, where)
        row["bound: all truth"] = truth_bound([item], item)
        rows.append(row)
    return rows


def real_table(rows: list[dict]) -> str:
    """Markdown table of :func:`evaluate_real` (a degenerate cell is marked ‡)."""
    lines = [
        "| frame | classes | " + " | ".join(REAL_COLUMNS) + " |",
        "|---|---:|" + "---:|" * len(REAL_COLUMNS),
    ]
    for r in rows:
        cells = [f"{r[c]:.3f}" + (" ‡" if c in r["degenerate"] else "") for c in REAL_COLUMNS]
        lines.append(f"| {r['scene']} | {r['k']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def synthetic_bounds(seeds: list[int]) -> dict[str, float]:
    """Mean over seeds of :func:`truth_bound` trained on the *other* seeds' truth."""
    out = {}
    for name in SCENES:
        scenes = {}
        for seed in seeds:
            stack, angles, truth = load(name, seed)
            pol = Pipeline(stack, angles, SegmentParams(method="thesis")).get("polarisation")
            scenes[seed] = (pol.intensity, pol.dop, pol.phase, truth, None)
        values = [truth_bound([scenes[o] for o in seeds if o != s], scenes[s]) for s in seeds]
        out[name] = float(np.mean(values))
    return out


def markdown_table(rows: list[dict], cols: list[str]) -> str:
    """The quality table: one row per scene and seed, then the mean per scene."""
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


def write_docs(table: str, command: str, page: Path = QUALITY_PAGE) -> None:
    """Replace the block between :data:`BEGIN` and :data:`END` in ``page`` with ``table``."""
    text = page.read_text(encoding="utf-8")
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{page} has no {BEGIN} ... {END} block to replace")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    block = f"{BEGIN}\n<!-- generated by `{command}`; do not edit by hand -->\n\n{table}\n\n{END}"
    page.write_text(head + block + tail, encoding="utf-8")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line of :func:`main`."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep", action="store_true", help="also search the grid")
    parser.add_argument("--seeds", default="0,1,2", help="scene seeds (0 = bundled sample)")
    parser.add_argument(
        "--docs",
        "--readme",
        dest="docs",
        action="store_true",
        help="rewrite the table in docs/quality.md with the result (--readme: the old name, "
        "same effect)",
    )
    parser.add_argument(
        "--limits", action="store_true", help="only the limits analysis (limits.py), no table"
    )
    parser.add_argument(
        "--no-bound",
        action="store_true",
        help="skip the truth-trained bounds (~1 minute; also --bounds none)",
    )
    parser.add_argument(
        "--real-dir", type=Path, default=REAL_DIR, help=f"the real frames [{REAL_DIR}]"
    )
    materials.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.no_bound:
        args.bounds = "none"
    return args


def main(argv: list[str] | None = None) -> None:  # noqa: PLR0915 - a report script
    args = parse_args(argv)
    if args.limits:
        from limits import main as limits_main

        limits_main()
        return
    if materials.subset_only(args):
        materials.run(args, args.real_dir)
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
    means = {
        n: {c: float(np.mean([r[c] for r in rows if r["scene"] == n])) for c in cols}
        for n in SCENES
    }
    bounds = None if args.no_bound else synthetic_bounds(seeds)
    report = floor_report(means, bounds)
    print("\n".join(report))
    real = evaluate_real(args.real_dir) if args.real_dir.is_dir() else []
    if real:
        print("\nreal frames (ARI over the hand-labelled pixels; ‡ = degenerate):\n")
        print(real_table(real))
        for r in real:
            print(real_report(r))
    else:
        print(f"\nno real frames in {args.real_dir}: the real-frame table is skipped")
    materials.run(args, args.real_dir)
    print(f"\n{time.perf_counter() - t0:.1f} s wall in all")
    if args.docs:
        cmd = "python benchmarks/evaluate.py --docs"
        if args.seeds != "0,1,2":
            cmd += f" --seeds {args.seeds}"
        block = markdown_table(rows, list(OPTIONS)) + "\n\n" + "\n".join(report)
        if real:
            block += "\n\nReal frames, ARI over the hand-labelled pixels (‡ = degenerate):\n\n"
            block += real_table(real) + "\n\n" + "\n".join(real_report(r) for r in real)
        write_docs(block, cmd)
        print(f"docs/quality.md table rewritten ({QUALITY_PAGE})")


#: Targets of issue 12 (scribbles) and 13 (unsupervised default).
TARGET = {"pixel classifier": 0.8}


def floor_report(means: dict, bounds: dict | None) -> list[str]:
    """One line per scene: the pixel classifier against its target, the plain baseline
    (the floor) and, when measured, the truth-trained bound."""
    lines = []
    for name, m in means.items():
        pc, plain = m["pixel classifier"], m["plain baseline"]
        target = TARGET["pixel classifier"]
        verdict = "met" if pc >= target else f"MISSED by {target - pc:.3f}"
        floor = "above" if pc > plain else "NOT above"
        bound = (
            ""
            if bounds is None
            else (f"; bound (richest features, truth of the other seeds) {bounds[name]:.3f}")
        )
        lines.append(
            f"- {name}: pixel classifier {pc:.3f}, target {target} {verdict}; "
            f"{floor} the plain baseline {plain:.3f}{bound}"
        )
    return lines


def real_report(r: dict) -> str:
    """The real frame's pixel classifier against its target and floor."""
    pc, km = r["pixel classifier"], r["intensity k-means"]
    target = TARGET["pixel classifier"]
    verdict = "met" if pc >= target else f"MISSED by {target - pc:.3f}"
    floor = "above" if pc > km else "NOT above"
    deg = ", ".join(r["degenerate"]) or "none"
    return (
        f"- {r['scene']}: pixel classifier {pc:.3f} ({r['pixel classifier seconds']:.1f} s), "
        f"target {target} {verdict}; {floor} intensity k-means {km:.3f}; plain baseline "
        f"{r['plain baseline']:.3f}; degenerate: {deg}"
    )


if __name__ == "__main__":
    main()
