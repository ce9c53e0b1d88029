"""How much a better merge could give: the default's k + e clusters merged to k by the
truth (the best of every way to group them), against the default's own merge.

The default (preset ``auto``, ``surface_superpixels``) clusters the superpixels into
k + 1 segments and merges two (``engine/unsupervised/merge.py``, the weakest border).
For e = 0 … 3 this prints the mean ARI (over the labelled pixels) of the best grouping
of the k + e clusters into k, found by trying every assignment of clusters to groups
and scoring it from the clusters' contingency table with the truth: an upper bound on
any merge rule over those clusters (e = 0 is the clustering into k itself). It is a
bound read off the truth, not a method, so it may be printed for held-out sets too.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python merge_headroom.py \\
        [--sets dev,test,dev-renders,unseen,two-materials,real]     # ~3 min for all
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np
from baselines import default_region_model
from evaluate import REAL_DIR
from materials import set_frames
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline
from napari_polarseg.engine.methods.registry import get_method
from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.unsupervised.merge import merged_clustering
from napari_polarseg.engine.unsupervised.segmenter import cluster_regions

EXTRAS = (0, 1, 2, 3)
#: The default method (preset auto's): its parameters and merge rule.
DEFAULT = get_method(PRESETS["auto"].method)


def pairs(x: np.ndarray) -> float:
    """Σ x(x − 1)/2: the pairs within each count of ``x``."""
    return float((x * (x - 1) / 2).sum())


def contingency_ari(table: np.ndarray) -> float:
    """The adjusted Rand index (Hubert and Arabie 1985) of a contingency table
    (rows: segments, columns: true classes), as sklearn's ``adjusted_rand_score``;
    written out because the grouping search scores thousands of merged tables."""
    n = table.sum()
    rows, cols, cells = pairs(table.sum(axis=1)), pairs(table.sum(axis=0)), pairs(table)
    expected = rows * cols / (n * (n - 1) / 2)
    return (cells - expected) / max(0.5 * (rows + cols) - expected, 1e-12)


def best_grouping(labels: np.ndarray, truth: np.ndarray, k: int) -> float:
    """The largest ARI of any grouping of the m clusters of ``labels`` into k groups."""
    classes = np.unique(truth, return_inverse=True)[1]
    m = int(labels.max()) + 1
    table = np.zeros((m, int(classes.max()) + 1))
    np.add.at(table, (labels, classes), 1)
    best = -1.0
    for assign in itertools.product(range(k), repeat=m):
        if len(set(assign)) == k:
            grouped = np.zeros((k, table.shape[1]))
            np.add.at(grouped, np.asarray(assign), table)
            best = max(best, contingency_ari(grouped))
    return best


def frame_row(stack, angles, truth: np.ndarray, k: int) -> list[float]:
    """[the default's merge, the best grouping of k + e clusters for each e]."""
    pol = Pipeline(stack, angles, PRESETS["auto"].replace(n_segments=k)).get("polarisation")
    model = default_region_model(pol.intensity, pol.dop, pol.phase, pol.invalid)
    scored = truth > 0
    merged = merged_clustering(model, k, merge=DEFAULT.merge_rule).labels
    row = [float(adjusted_rand_score(truth[scored], merged[scored]))]
    for extra in EXTRAS:
        labels = cluster_regions(model, k + extra).labels
        row.append(best_grouping(labels[scored], truth[scored], k))
    return row


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", default="dev,test,dev-renders,unseen,two-materials,real")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    heads = " | ".join(f"best grouping of k + {e}" for e in EXTRAS)
    print(f"| set | n | default (k + 1, weakest border) | {heads} |")
    print("|---|---:|" + "---:|" * (1 + len(EXTRAS)))
    for name in args.sets.split(","):
        rows = [frame_row(*frame[1:]) for frame in set_frames(name, REAL_DIR)]
        if not rows:
            print(f"| {name} | 0 | (no frames) |")
            continue
        means = " | ".join(f"{v:.3f}" for v in np.mean(rows, axis=0))
        print(f"| {name} | {len(rows)} | {means} |", flush=True)
    print(f"\n{time.perf_counter() - t0:.1f} s wall")


if __name__ == "__main__":
    main()
