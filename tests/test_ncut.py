"""Normalized cuts: generalized eigenproblem, best split, recursion on planted partitions."""

import numpy as np
import pytest
import scipy.linalg
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import CutTree, best_split, fiedler_vector, recursive_ncut


def planted(sizes, p_in=0.9, p_out=0.05, noise=0.04, seed=0):
    rng = np.random.default_rng(seed)
    truth = np.repeat(np.arange(len(sizes)), sizes)
    rng.shuffle(truth)
    W = np.where(truth[:, None] == truth[None, :], p_in, p_out)
    W = W + noise * rng.random(W.shape)
    W = (W + W.T) / 2
    return W, truth


@pytest.mark.parametrize("n", [40, 600])  # dense eigh and Lanczos paths
def test_fiedler_vector_solves_generalized_problem(n):
    W, _ = planted([n // 2, n - n // 2], seed=1)
    y = fiedler_vector(W)
    D = np.diag(W.sum(1))
    vals = scipy.linalg.eigh(D - W, D, eigvals_only=True)
    lam = y @ (D - W) @ y / (y @ D @ y)
    assert lam == pytest.approx(vals[1], rel=1e-6)
    np.testing.assert_allclose((D - W) @ y, lam * D @ y, atol=1e-6 * np.abs(D @ y).max())


@pytest.mark.parametrize(
    ("sizes", "seed"), [((30, 50), 0), ((100, 80, 60), 1), ((200, 150, 120, 90, 60), 2)]
)
def test_recovers_planted_partition_exactly(sizes, seed):
    W, truth = planted(sizes, seed=seed)
    labels = recursive_ncut(W, len(sizes))
    assert adjusted_rand_score(truth, labels) == 1.0
    assert labels[0] == 0  # numbered in order of first appearance


def test_best_split_minimises_ncut_by_brute_force():
    rng = np.random.default_rng(3)
    W = rng.random((9, 9))
    W = (W + W.T) / 2
    y = rng.normal(size=9)
    mask, value = best_split(W, y)
    order = np.argsort(y)
    d = W.sum(1)
    best = np.inf
    for k in range(1, 9):
        a = np.zeros(9, bool)
        a[order[:k]] = True
        cut = W[a][:, ~a].sum()
        best = min(best, cut / d[a].sum() + cut / d[~a].sum())
    assert value == pytest.approx(best, rel=1e-12)
    cut = W[mask][:, ~mask].sum()
    assert cut / d[mask].sum() + cut / d[~mask].sum() == pytest.approx(value)


def test_min_size_and_threshold_stop_splitting():
    W, truth = planted((50, 50, 4), seed=4)
    labels = recursive_ncut(W, 3, min_size=10)
    assert np.bincount(labels).min() >= 10
    tree = CutTree(W, threshold=1e-9)
    assert tree.labels(3).max() == 0  # no cut is that good: one segment
    tree = CutTree(W)
    assert tree.labels(1).max() == 0


def test_cut_tree_is_cached_and_consistent():
    W, truth = planted((60, 40, 30), seed=5)
    tree = CutTree(W)
    three = tree.labels(3)
    two = tree.labels(2)
    # the 3-segment labelling refines the 2-segment one
    for lab in np.unique(three):
        assert np.unique(two[three == lab]).size == 1
    assert len(tree.ncut_values) == 2
    assert adjusted_rand_score(truth, three) == 1.0
