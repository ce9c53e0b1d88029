"""The family bench (issue 37): every method beside its plain baselines, by scene family
and half, with the truth-trained bound and the object size estimated against the truth.

Families and halves: :mod:`families`. Every frame is scored by the adjusted Rand index
(ARI) over its labelled pixels with k = the truth's classes:

- unsupervised: ``intensity k-means`` and ``smoothed k-means`` (the plain baselines of
  :mod:`baselines`), ``superpixels`` (the default before issue 24), ``default`` (what
  ``polarseg segment --segments K`` does: its superpixels keep their share of the
  frame), ``at estimated size`` (the default following the object size it estimates,
  the candidate) and ``at true size`` (given the truth's object size, where known);
- scribbles: the robot user of :mod:`robot_user` paints one disc per material at its
  deepest point (``… discs``), then one disc on the largest wrong region per round
  (``… robot 5``: after 5 corrections), for the project's scribble classifier
  (``scribbles``), a random forest on the 20 plain features (``plain forest``) and one
  on ilastik's default filter bank (``ilastik forest``, discs only);
- ``bound``: a random forest on the 20 plain features trained on the truth of the left
  half, scored on the right half (:func:`baselines.truth_bound_halves`): what those
  features allow, given labels;
- ``scribble bound``: the project's scribble classifier given the truth of the left
  half as its strokes, scored on the right half, the better of it with and without
  its region walk (:func:`scribble_bound`): what the best classifier here reaches
  with labels on half the frame, the bound a claim about the data needs;
- ``default right``: the default scored on the same right-half pixels, to stand
  beside both bounds;
- object size: :func:`~napari_polarseg.engine.features.object_size.estimate_object_size`
  against the truth's median object size (their ratio; within a factor 1.5 is the
  target).

A degenerate result (one segment holds ≥ 90 % of the scored pixels, :func:`materials.degenerate`)
is marked ``‡``, counted, and the default's are named. ``--markdown PAGE`` writes the
tables into PAGE between :data:`BEGIN` and :data:`END`.

Usage (from the repository root; the Mitsuba families need their renders, see
:data:`families.RENDER_SETS`)::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python evaluate_families.py \\
        --test-base 0 --markdown ../docs/quality.md
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np
from baselines import (
    intensity_kmeans,
    plain_features,
    right_half_ari,
    smoothed_kmeans,
    truth_bound_halves,
)
from families import FAMILIES, HALVES, RENDER_SETS, Frame, frames, standard_error
from ilastik_features import ilastik_features
from materials import degenerate, replace_block
from robot_user import forest_update, product_update, run_robot
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline, Scene, ScribbleSession
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.features.object_size import estimate_object_size
from napari_polarseg.engine.methods import register_method
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.params import PRESETS

BEGIN = "<!-- family tables: begin -->"
END = "<!-- family tables: end -->"
#: Corrections after which the robot user's ARI is read.
ROUNDS = 5
UNSUPERVISED = (
    "intensity k-means",
    "smoothed k-means",
    "superpixels",
    "default",
    "at estimated size",
    "at true size",
)
SUPERVISED = (
    "scribbles discs",
    "plain forest discs",
    "ilastik forest discs",
    "scribbles robot 5",
    "plain forest robot 5",
)
BOUNDS = ("bound", "scribble bound", "default right")
COLUMNS = (*UNSUPERVISED, *SUPERVISED, *BOUNDS)
#: Issue 37's targets on every rendered family's test half.
TARGET_DEFAULT = 0.5
TARGET_SCRIBBLES = 0.7
#: The object size estimate should lie within this factor of the truth's.
SIZE_FACTOR = 1.5


class EstimatedSize(SurfaceSuperpixels):
    """The default method following the object size it estimates (``object_size = 0``)
    as it follows a given one: the candidate of issue 37's object size."""

    name = "surface_superpixels_estimated_size"
    title = "the default at the estimated object size (benchmark column)"
    follows_estimate = True


register_method(EstimatedSize())


def scribble_bound(pipe: Pipeline, truth: np.ndarray) -> float:
    """ARI over the labelled pixels right of the middle (:func:`baselines.right_half_ari`)
    of the project's scribble classifier (``ScribbleSession``) whose strokes are the
    truth of the columns left of the middle, the better of its default parameters and
    those without the region walk (the walk spreads sparse strokes over the superpixel
    graph; given half the frame's truth it can cost more than it brings): the
    truth-trained bound of the best classifier here. Where the left half holds one
    material, a classifier can name only that one: the right half all of it (as the
    forest bound, marked † by :func:`score`); none, NaN."""
    half = truth.shape[1] // 2
    strokes = np.where(truth > 0, truth, 0).astype(np.int32)
    strokes[:, half:] = 0
    named = np.unique(strokes[strokes > 0])
    if named.size < 2:
        if named.size == 0:
            return float("nan")
        return right_half_ari(np.full(truth.shape, named[0], np.int32), truth)
    session = ScribbleSession.on_pipeline(pipe, classifier_params=ClassifierParams())
    session.features()  # once: both settings read the same features
    scores = []
    for params in (ClassifierParams(), ClassifierParams(region_walk=0.0)):
        session.classifier_params = params
        scores.append(right_half_ari(session.update(strokes), truth))
    return max(scores)


def score(frame: Frame, rounds: int = ROUNDS, bound: bool = True) -> dict:
    """One row: every column's ARI, the marks, the object sizes and the seconds."""
    truth, k = frame.truth, frame.k
    scored = truth > 0
    t0 = time.perf_counter()
    pipe = Pipeline(frame.stack, frame.angles, PRESETS["auto"].replace(n_segments=k))
    pol = pipe.get("polarisation")
    valid = ~np.asarray(pol.invalid, bool)
    scene, params = Scene(pipeline=pipe), pipe.params
    row: dict = {"frame": frame.name, "family": frame.family, "half": frame.half, "k": k}
    row.update(marks={}, seconds={}, note=frame.note)
    runs = {
        "intensity k-means": lambda: intensity_kmeans(pol.intensity, k),
        "smoothed k-means": lambda: smoothed_kmeans(pol.intensity, pol.dop, pol.phase, k, valid),
        "superpixels": lambda: scene.segment(params.replace(method="superpixels")).labels,
        "default": lambda: scene.segment(params).labels,
        "at estimated size": lambda: (
            scene.segment(params.replace(method=EstimatedSize.name)).labels
        ),
    }
    if np.isfinite(frame.object_size):
        runs["at true size"] = lambda: (
            scene.segment(params.replace(object_size=float(frame.object_size))).labels
        )
    kept = {}
    for column, run in runs.items():
        t1 = time.perf_counter()
        labels = kept[column] = run()
        row["seconds"][column] = time.perf_counter() - t1
        row[column] = float(adjusted_rand_score(truth[scored], labels[scored]))
        if degenerate(labels, truth):
            row["marks"][column] = "‡"
    record = scene.segment(params).method_record
    row["object size used"] = record.get("object_size")
    updates = {
        "scribbles": (lambda: product_update(pipe), rounds),
        "plain forest": (
            lambda: forest_update(plain_features(pol.intensity, pol.dop, pol.phase)),
            rounds,
        ),
        "ilastik forest": (lambda: forest_update(ilastik_features(frame.stack)), 0),
    }
    for name, (factory, n) in updates.items():
        t1 = time.perf_counter()
        run = run_robot(truth, factory(), n)
        row["seconds"][name] = time.perf_counter() - t1
        row[f"{name} discs"] = run.ari[0]
        if n:
            row[f"{name} robot {n}"] = run.ari[n]
    if bound:
        value, seen = truth_bound_halves(pol.intensity, pol.dop, pol.phase, truth, "plain", ~valid)
        row["bound"] = value
        t1 = time.perf_counter()
        row["scribble bound"] = scribble_bound(pipe, truth)
        row["seconds"]["scribble bound"] = time.perf_counter() - t1
        row["default right"] = right_half_ari(kept["default"], truth)
        if not seen:
            row["marks"]["bound"] = row["marks"]["scribble bound"] = "†"
    t1 = time.perf_counter()
    estimate = estimate_object_size(pol.intensity, pol.dop, pol.phase, valid)
    row["seconds"]["object size"] = time.perf_counter() - t1
    row["object size"] = float(estimate.size_px)
    row["object size truth"] = frame.object_size
    row["seconds"]["all"] = time.perf_counter() - t0
    return row


def mean(rows: list[dict], column: str) -> float:
    values = [r[column] for r in rows if column in r and np.isfinite(r[column])]
    return float(np.mean(values)) if values else float("nan")


def paired(rows: list[dict], a: str, b: str) -> tuple[float, float]:
    """Mean of ``a − b`` over the frames and its standard error."""
    d = np.array([r[a] - r[b] for r in rows if a in r and b in r])
    return (float(d.mean()) if d.size else float("nan")), standard_error(d)


def size_ratio(row: dict) -> float:
    truth = row.get("object size truth", float("nan"))
    return row["object size"] / truth if np.isfinite(truth) and truth > 0 else float("nan")


def fmt(value: float) -> str:
    return "–" if not np.isfinite(value) else f"{value:.3f}"


def summary_table(sets: dict[tuple[str, str], list[dict]]) -> str:
    """One line per family and half: n, every column's mean, the degenerate defaults,
    the paired difference of the default at the estimated size against the default and
    the object-size ratio."""
    head = ["family", "half", "n", *COLUMNS, "‡ default", "estimated size − default", "size ratio"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for (family, half), rows in sets.items():
        if not rows:
            continue
        d, se = paired(rows, "at estimated size", "default")
        ratios = np.array([size_ratio(r) for r in rows])
        ratios = ratios[np.isfinite(ratios)]
        out = int(np.sum((ratios > SIZE_FACTOR) | (ratios < 1 / SIZE_FACTOR)))
        ratio = f"{np.median(ratios):.2f} ({out} out)" if ratios.size else "–"
        bad = [r["frame"] for r in rows if "default" in r["marks"]]
        note = " (read before)" if any(r["note"] for r in rows) else ""
        cells = [family, half + note, str(len(rows)), *(fmt(mean(rows, c)) for c in COLUMNS)]
        cells += [", ".join(bad) or "0", f"{d:+.3f} ± {se:.3f}", ratio]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def frame_table(rows: list[dict]) -> str:
    """One line per frame (a test half or the real frames)."""
    cols = [c for c in COLUMNS if any(c in r for r in rows)]
    head = ["frame", "k", *cols, "object size (truth)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["frame"], str(r["k"])]
        cells += [fmt(r.get(c, float("nan"))) + r["marks"].get(c, "") for c in cols]
        cells.append(f"{r['object size']:.0f} ({fmt(r['object size truth'])[:-2]})")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def verdicts(sets: dict[tuple[str, str], list[dict]]) -> list[str]:
    """Issue 37's floors and targets, read on each family's test half (the real frames:
    all of them)."""
    out = []
    for family in FAMILIES:
        half = "dev" if family == "real" else "test"
        rows = sets.get((family, half)) or []
        if not rows:
            out.append(f"- {family}: no {half} frames")
            continue
        m = {c: mean(rows, c) for c in COLUMNS}
        floor_u = m["default"] >= max(m["smoothed k-means"], m["superpixels"])
        floor_s = (
            m["scribbles discs"] >= m["plain forest discs"]
            and m["scribbles robot 5"] >= m["plain forest robot 5"]
        )
        parts = [
            f"default {m['default']:.3f} against smoothed k-means {m['smoothed k-means']:.3f} "
            f"and superpixels {m['superpixels']:.3f}: floor {'met' if floor_u else 'NOT met'}",
            f"scribbles {m['scribbles discs']:.3f} / robot 5 {m['scribbles robot 5']:.3f} "
            f"against the plain forest {m['plain forest discs']:.3f} / "
            f"{m['plain forest robot 5']:.3f}: floor {'met' if floor_s else 'NOT met'}",
        ]
        if family != "real":
            parts.append(
                f"targets: default ≥ {TARGET_DEFAULT} "
                f"{'met' if m['default'] >= TARGET_DEFAULT else 'missed'}, scribbles ≥ "
                f"{TARGET_SCRIBBLES} "
                f"{'met' if m['scribbles discs'] >= TARGET_SCRIBBLES else 'missed'}"
            )
        out.append(f"- {family} ({half}): " + "; ".join(parts))
    return out


def report(sets: dict[tuple[str, str], list[dict]], command: str) -> str:
    parts = [
        f"Made by `{command}`.",
        "",
        "Means of ARI over the labelled pixels, by family and half (k = the truth's "
        "classes). ‡ default: the frames where the default is degenerate. "
        "*estimated size − default*: the paired difference of the default at the "
        "estimated object size against the default, ± one standard error. *size ratio*: "
        "the median of estimated / true object size, and how many frames lie outside a "
        f"factor {SIZE_FACTOR}. *bound*, *scribble bound*: a forest on the 20 plain "
        "features and the scribble classifier, each trained on the truth of the left half "
        "and scored on the right half; *default right*: the default on those pixels.",
        "",
        summary_table(sets),
        "",
        "Issue 37's floors and targets:",
        "",
        *verdicts(sets),
    ]
    for (family, half), rows in sets.items():
        if rows and (half == "test" or family == "real"):
            parts += ["", f"**{FAMILIES[family]}, {half}**", "", frame_table(rows)]
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES), help="comma-separated")
    ap.add_argument("--halves", default=",".join(HALVES), help="dev, test or both")
    ap.add_argument(
        "--test-base",
        type=int,
        default=0,
        help="round of the test halves: the diffuse seeds' base and the Mitsuba renders' "
        "round (families.render_set); a new base reads scenes nobody has read",
    )
    ap.add_argument("--rounds", type=int, default=ROUNDS)
    ap.add_argument("--no-bound", action="store_true")
    ap.add_argument("--json", help="also write every row to this file")
    ap.add_argument("--markdown", help="rewrite the family tables in this page")
    args = ap.parse_args(argv)
    command = "cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python evaluate_families.py " + (
        shlex.join(argv if argv is not None else sys.argv[1:])
    )
    sets: dict[tuple[str, str], list[dict]] = {}
    for family in args.families.split(","):
        for half in args.halves.split(","):
            rows = sets.setdefault((family, half), [])
            for frame in frames(family, half, args.test_base):
                rows.append(score(frame, args.rounds, not args.no_bound))
                r = rows[-1]
                print(
                    f"{family} {half} {r['frame']}: "
                    + ", ".join(
                        f"{c} {fmt(r.get(c, float('nan')))}{r['marks'].get(c, '')}" for c in COLUMNS
                    )
                    + f", size {r['object size']:.0f} / {fmt(r['object size truth'])}"
                    + f" ({r['seconds']['all']:.0f} s)",
                    flush=True,
                )
    text = report(sets, command)
    print(text)
    if args.json:
        flat = {f"{f}/{h}": rows for (f, h), rows in sets.items()}
        Path(args.json).write_text(json.dumps(flat, indent=1, default=float))
    if args.markdown:
        replace_block(Path(args.markdown), text, command, BEGIN, END)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["RENDER_SETS", "score", "main"]
