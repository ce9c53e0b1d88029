"""benchmarks/merge_headroom.py: the ARI of a contingency table is sklearn's, and the
best grouping of over-segmented clusters recovers a truth they refine."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from sklearn.metrics import adjusted_rand_score

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import merge_headroom  # noqa: E402


def test_contingency_ari_is_sklearns():
    rng = np.random.default_rng(0)
    truth, labels = rng.integers(0, 3, 500), rng.integers(0, 4, 500)
    labels[:200] = truth[:200]  # partly agreeing
    table = np.zeros((4, 3))
    np.add.at(table, (labels, truth), 1)
    assert np.isclose(merge_headroom.contingency_ari(table), adjusted_rand_score(truth, labels))


def test_best_grouping_finds_the_truth_that_the_clusters_refine():
    truth = np.repeat([1, 2, 3], 100)
    # five clusters, each inside one class: 1 = {0, 1}, 2 = {2, 3}, 3 = {4}
    labels = np.repeat([0, 1, 2, 3, 4, 4], 50)
    assert merge_headroom.best_grouping(labels, truth, 3) == 1.0
    assert adjusted_rand_score(truth, labels) < 1.0
    # a cluster straddling two classes caps the best grouping below 1
    labels[90:110] = 5
    assert merge_headroom.best_grouping(labels, truth, 3) < 1.0
