"""Variants of the scribble classifier on the development halves of every scene family
(:mod:`families`), for choosing: the robot user's ARI with one disc per material (and,
with ``--rounds N``, after N corrections) for each variant, by family, and its paired
difference to the classifier's defaults, with the frames that moved most.

A variant changes the pixel features' parameters (``PixelFeatureParams``: the scales'
cap in object sizes, the feature groups), the classifier's (``ClassifierParams``: the
region walk's γ) or the region walk's superpixel side in object sizes D (its area
(q · D)², within 16–1024 px, in place of the image's share), turns the walk off
where D is under a number of the walk superpixels' sides, sets the region means'
superpixel side in object sizes, or keeps the classifier's own class means for the
unseeded nodes where the walk's answer is unsure (its two largest class probabilities
closer than a margin). ``--test-base B`` reads
round B's test halves instead, only to check a choice on a test half already read and
reported.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python scribble_variants.py \\
        [--families objects,small,textured,diffuse,real] [--variants NAME,NAME]
        [--rounds N] [--test-base B]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from typing import Any
from unittest import mock

import numpy as np
from families import FAMILIES, Frame, add_check_round, frames, read_half, standard_error
from robot_user import run_robot

from napari_polarseg.engine import Pipeline, ScribbleSession
from napari_polarseg.engine.classifier import pixel_segmentation, region_walk
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.features.pixel_feature_params import PixelFeatureParams
from napari_polarseg.engine.params import PRESETS

WITHOUT_REGIONS = ("intensity", "polarisation", "invariant")


@dataclass(frozen=True)
class Variant:
    """Feature and classifier parameter changes, and the walk's superpixel side in
    object sizes (0: the image's share, the default)."""

    features: dict[str, Any] = field(default_factory=dict)
    classifier: dict[str, Any] = field(default_factory=dict)
    walk_side: float = 0.0
    #: the region means' superpixel side in object sizes (0: the image's share)
    means_side: float = 0.0
    #: no region walk where the object size is under this many walk superpixel sides
    #: (0: the walk everywhere, the default)
    walk_gate: float = 0.0
    #: the unseeded nodes whose walk answer has its two largest class probabilities
    #: closer than this keep the classifier's class means (0: the walk's answer)
    walk_unsure: float = 0.0


VARIANTS = {
    "default": Variant(),
    "every scale": Variant({"largest_scale_objects": 0.0}),
    "scales to D/4": Variant({"largest_scale_objects": 0.25}),
    "scales to D/2": Variant({"largest_scale_objects": 0.5}),
    "walk superpixels 0.15 D": Variant(walk_side=0.15),
    "walk superpixels 0.25 D": Variant(walk_side=0.25),
    "no walk": Variant(classifier={"region_walk": 0.0}),
    "walk 0.3": Variant(classifier={"region_walk": 0.3}),
    "no region means": Variant({"groups": WITHOUT_REGIONS}),
    "no walk under 3 walk superpixels": Variant(walk_gate=3.0),
    "region means of side 0.25 D": Variant(means_side=0.25),
    "region means of side 0.5 D": Variant(means_side=0.5),
    "classifier where the walk is unsure by 0.2": Variant(walk_unsure=0.2),
    "classifier where the walk is unsure by 0.5": Variant(walk_unsure=0.5),
}


def unsure_walk(margin: float) -> Any:
    """:func:`~napari_polarseg.engine.classifier.region_walk.walk` whose unseeded nodes
    with their two largest class probabilities closer than ``margin`` keep their
    prior (the classifier's class means), renormalised."""
    walk = region_walk.walk

    def patched(adjacency: Any, prior: np.ndarray, seeds: np.ndarray, weight: Any) -> np.ndarray:
        x = walk(adjacency, prior, seeds, weight)
        top = np.sort(x, axis=1)
        unsure = (top[:, -1] - top[:, -2] < margin) & (seeds < 0)
        x[unsure] = prior[unsure] / np.maximum(prior[unsure].sum(axis=1, keepdims=True), 1e-12)
        return x

    return patched


def frame_scores(frame: Frame, chosen: dict[str, Variant], rounds: int) -> dict[str, list]:
    """Variant → [ARI with the discs, ARI after ``rounds`` corrections] on one frame."""
    pipe = Pipeline(frame.stack, frame.angles, PRESETS["auto"].replace(n_segments=frame.k))
    out = {}
    for name, v in chosen.items():
        classifier, features = dict(v.classifier), dict(v.features)
        size = ScribbleSession.on_pipeline(pipe).segmenter.object_size(pipe.params).size_px
        if v.means_side > 0:
            features["region_area"] = int(np.clip((v.means_side * size) ** 2, 16, 1024))
        if v.walk_gate > 0:
            side = np.sqrt(pixel_segmentation.walk_region_area(frame.truth.shape))
            if size < v.walk_gate * side:
                classifier["region_walk"] = 0.0
        session = ScribbleSession.on_pipeline(
            pipe,
            features_params=PixelFeatureParams(**features),
            classifier_params=ClassifierParams(**classifier),
        )
        area = 0
        if v.walk_side > 0:
            area = int(np.clip((v.walk_side * size) ** 2, 16, 1024))
        walk_area = pixel_segmentation.walk_region_area
        walk = unsure_walk(v.walk_unsure) if v.walk_unsure > 0 else region_walk.walk
        with (
            mock.patch.object(
                pixel_segmentation, "walk_region_area", (lambda s, a=area: a) if area else walk_area
            ),
            mock.patch.object(region_walk, "walk", walk),
        ):
            session.features()
            run = run_robot(frame.truth, session.update, rounds)
        out[name] = [run.ari[0], run.ari[rounds]]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--rounds", type=int, default=0, help="corrections after the discs")
    add_check_round(ap)
    args = ap.parse_args(argv)
    half = read_half(args.test_base)
    chosen = {n: VARIANTS[n] for n in args.variants.split(",") if n}
    rows: list[tuple[str, str, dict[str, list]]] = []
    t0 = time.perf_counter()
    for family in args.families.split(","):
        for frame in frames(family, half, args.test_base or 0):
            scores = frame_scores(frame, chosen, args.rounds)
            rows.append((family, frame.name, scores))
            cells = ", ".join(f"{n} {s[0]:.3f}/{s[1]:.3f}" for n, s in scores.items())
            print(f"{family} {frame.name}: {cells}", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    families = list(dict.fromkeys(f for f, _, _ in rows))
    columns = [0, 1] if args.rounds else [0]
    for c in columns:
        what = "discs" if c == 0 else f"robot {args.rounds}"
        head = ["variant", *families, "paired vs default (all frames)"]
        print(f"\n{what}\n| " + " | ".join(head) + " |\n|" + "---|" * len(head))
        for n in chosen:
            means = [np.mean([s[n][c] for f, _, s in rows if f == family]) for family in families]
            cells = [n, *(f"{m:.3f}" for m in means)]
            if "default" in chosen:
                d = np.array([s[n][c] - s["default"][c] for _, _, s in rows])
                cells.append(f"{d.mean():+.3f} ± {standard_error(d):.3f}")
            print("| " + " | ".join(cells) + " |")
        if "default" in chosen:
            for n in chosen:
                moved = sorted((s[n][c] - s["default"][c], f"{f}/{name}") for f, name, s in rows)
                ends = moved[:2] + moved[-2:] if len(moved) > 3 else moved
                print(f"{n}: " + ", ".join(f"{m} {d:+.2f}" for d, m in ends))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
