"""Two refinements of the default's clusters tried for issue 24, measured beside it.

The default as it was then (preset ``auto``: ``surface_superpixels``, k + 1 clusters,
the two closest merged; since 2026-12-03 the default merges across the weakest border
instead) on the development half of the rendered scenes and the four labelled real
frames, and:

- **self-training**: the pixel classifier of the scribble loop (``ScribbleSession``)
  trained on every cluster's interior (eroded by ``--erode`` px), then every pixel
  predicted, by the classifier alone and with the region walk;
- **separability merge**: k + ``--extra`` clusters, then the two clusters that a random
  forest on shading-free pixel features (``polarisation`` and ``invariant`` groups at
  σ = 2, 4, 8; 400 pixels of each, 3-fold balanced accuracy) tells apart worst are
  merged, until k remain.

ARI over the labelled pixels, k = the truth's classes. ``--test`` adds the test half
(only to report: choose on the development half). Not part of the test run::

    cd benchmarks && PYTHONPATH=.. python default_refinements.py  # ~2 min
"""

from __future__ import annotations

import argparse

import numpy as np
from baselines import real_frames
from default_variants import W, frames
from evaluate import REAL_DIR
from materials import HALVES, RENDERED_DIR, load_rendered
from scipy import ndimage
from sklearn.ensemble import RandomForestClassifier
from sklearn.metrics import adjusted_rand_score
from sklearn.model_selection import cross_val_score

from napari_polarseg.engine import ScribbleSession
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.features.pixel_features import PixelFeatureParams, pixel_features
from napari_polarseg.engine.methods.valid_superpixels import clustered_pixels
from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.unsupervised.merge import merged_clustering
from napari_polarseg.engine.unsupervised.segmenter import cluster_regions, prepare_regions

#: Pixels of each cluster the separability forest reads.
SAMPLE = 400
SHADING_FREE = PixelFeatureParams(scales=(2.0, 4.0, 8.0), groups=("polarisation", "invariant"))


def self_trained(stack, angles, labels, invalid, k: int, erode: int, gamma: float):  # noqa: ANN001
    """Labels (H, W) of the classifier trained on the clusters' eroded interiors."""
    strokes = np.zeros(labels.shape, np.int32)
    for c in range(k):
        strokes[ndimage.binary_erosion(labels == c, iterations=erode) & ~invalid] = c + 1
    params = PRESETS["auto"].replace(n_segments=k)
    walk = ClassifierParams(region_walk=gamma)
    session = ScribbleSession(
        stack, np.rad2deg(angles), segment_params=params, classifier_params=walk
    )
    return session.update(strokes)


def separability_merged(maps, invalid, model, k: int, extra: int) -> np.ndarray:  # noqa: ANN001
    """Labels (H, W): k + ``extra`` clusters, the least separable pair merged in turn."""
    rng = np.random.default_rng(0)
    labels = cluster_regions(model, k + extra).labels.copy()
    features = pixel_features(*maps, SHADING_FREE)
    usable = ~invalid.ravel()
    while np.unique(labels).size > k:
        sample = {}
        for c in np.unique(labels):
            idx = np.flatnonzero((labels.ravel() == c) & usable)
            sample[c] = rng.choice(idx, min(SAMPLE, idx.size), replace=False)
        worst, pair = 2.0, None
        for a in sample:
            for b in sample:
                if a >= b:
                    continue
                acc = 0.5
                if min(sample[a].size, sample[b].size) >= 20:
                    x = features.take(np.concatenate([sample[a], sample[b]]))
                    y = np.r_[np.zeros(sample[a].size), np.ones(sample[b].size)]
                    forest = RandomForestClassifier(30, max_depth=8, random_state=0)
                    acc = cross_val_score(forest, x, y, cv=3, scoring="balanced_accuracy").mean()
                if acc < worst:
                    worst, pair = acc, (a, b)
        labels[labels == pair[1]] = pair[0]
    return labels


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--test", action="store_true", help="also the test half")
    parser.add_argument("--erode", type=int, default=3, help="self-training erosion [3]")
    parser.add_argument("--extra", type=int, default=2, help="extra clusters to merge [2]")
    args = parser.parse_args(argv)
    stacks = {}
    for group in ("dev", "test") if args.test else ("dev",):
        for seed in HALVES[group]:
            stack, angles, _ = load_rendered(seed, RENDERED_DIR)
            stacks[f"scene_{seed}"] = (stack, angles)
    for tf, data in real_frames(REAL_DIR):
        stacks[tf.frame] = (data.stack, data.angles_rad)
    columns = ("default", "self-trained alone", "self-trained, walk", "separability merge")
    print("| set | frame | " + " | ".join(columns) + " |\n|---|---|" + "---:|" * len(columns))
    rows = []
    for group, name, (i, d, ph, invalid), truth, k in frames(args.test):
        model = prepare_regions(i, d, ph, W, clustered_pixels(None, invalid))
        default = merged_clustering(model, k).labels
        stack, angles = stacks[name]
        found = [
            default,
            self_trained(stack, angles, default, invalid, k, args.erode, 0.0),
            self_trained(stack, angles, default, invalid, k, args.erode, 0.03),
            separability_merged((i, d, ph), invalid, model, k, args.extra),
        ]
        scored = truth > 0
        aris = [adjusted_rand_score(truth[scored], f[scored]) for f in found]
        rows.append((group, aris))
        print(f"| {group} | {name} | " + " | ".join(f"{a:.3f}" for a in aris) + " |", flush=True)
    for group in ("dev", "test", "real"):
        if not any(r[0] == group for r in rows):
            continue
        means = [np.mean([r[1][j] for r in rows if r[0] == group]) for j in range(len(columns))]
        if means:
            print(f"| {group} | mean | " + " | ".join(f"**{m:.3f}**" for m in means) + " |")


if __name__ == "__main__":
    main()
