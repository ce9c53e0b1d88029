"""Which part of the scribble loop makes a correction lower the ARI (issue 40, point 13)?

The robot user of :mod:`robot_user` (one disc per material, then one disc on the largest
wrong region each round) on the hand-labelled real frames, with the project's scribble
loop as it ships and without each of the two steps that spread a stroke's effect beyond
its pixels: the region walk over superpixels (``region_walk = 0``) and the region-mean
feature group (``regions``). For each it prints the ARI after every correction, the
setbacks (corrections that lowered the ARI by more than ``robot_user.SETBACK``), the
largest fall, and how many pixels each correction relabelled.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python correction_setbacks.py \\
        [--frames fruits,carps] [--rounds 10]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import Any

import numpy as np
import robot_user as ru

from napari_polarseg.engine import Pipeline, ScribbleSession
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.features.pixel_features import PixelFeatureParams

#: Feature groups without the region means.
NO_REGIONS = tuple(g for g in PixelFeatureParams().groups if g != "regions")
#: Variant name -> (region walk weight or None for the default, feature groups or None).
VARIANTS: dict[str, tuple[float | None, tuple[str, ...] | None]] = {
    "as shipped": (None, None),
    "no region walk": (0.0, None),
    "no region features": (None, NO_REGIONS),
    "neither": (0.0, NO_REGIONS),
}


def session_update(
    pipe: Pipeline, walk: float | None, groups: tuple[str, ...] | None
) -> tuple[ru.Update, list[int]]:
    """The scribble loop's update with the variant's walk and groups, and the list that
    collects how many pixels each update relabelled."""
    session = ScribbleSession.on_pipeline(pipe)
    if groups is not None:
        session.features_params = PixelFeatureParams(groups=groups)
    if walk is not None:
        session.classifier_params = replace(ClassifierParams(), region_walk=walk)
    session.features(session.features_params)
    changed: list[int] = []
    last: dict[str, Any] = {}

    def update(scribbles: np.ndarray) -> np.ndarray:
        labels = session.update(scribbles)
        if "labels" in last:
            changed.append(int(np.count_nonzero(labels != last["labels"])))
        last["labels"] = labels
        return labels

    return update, changed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default="fruits,carps", help="real frames (name prefixes)")
    ap.add_argument("--rounds", type=int, default=10)
    args = ap.parse_args(argv)
    wanted = args.frames.split(",")
    print(
        "| frame | variant | ARI after 0, 1, … corrections | setbacks | largest fall | "
        "pixels relabelled per correction (median) |\n|---|---|---|---:|---:|---:|"
    )
    for scene in ru.real_scenes():
        if scene.name.split("_")[0] not in wanted:
            continue
        pipe = Pipeline(scene.stack, scene.angles_rad)
        for name, (walk, groups) in VARIANTS.items():
            update, changed = session_update(pipe, walk, groups)
            run = ru.run_robot(scene.truth, update, rounds=args.rounds)
            n, fall = run.setbacks()
            aris = " ".join(f"{a:.2f}" for a in run.ari)
            print(
                f"| {scene.name} | {name} | {aris} | {n} | {fall:.3f} | "
                f"{int(np.median(changed)) if changed else 0} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
