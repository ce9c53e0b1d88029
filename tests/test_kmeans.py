"""The hand-written weighted k-means (engine/unsupervised/kmeans.py) against known answers and
against scikit-learn's KMeans."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.cluster import KMeans
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.unsupervised.kmeans import weighted_kmeans


def blobs(seed: int, k: int = 3, n: int = 600, d: int = 3, spread: float = 0.3):
    rng = np.random.default_rng(seed)
    centres = 4.0 * np.eye(k, d) + rng.normal(scale=0.5, size=(k, d))
    truth = rng.integers(0, k, n)
    return centres[truth] + rng.normal(scale=spread, size=(n, d)), truth


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_separated_blobs_are_recovered_exactly(seed):
    x, truth = blobs(seed)
    fit = weighted_kmeans(x, 3, seed=seed)
    assert adjusted_rand_score(truth, fit.labels) == 1.0
    for j in range(3):  # each centre is its cluster's mean
        np.testing.assert_allclose(fit.centres[j], x[fit.labels == j].mean(axis=0), atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_inertia_matches_scikit_learn_on_overlapping_weighted_data(seed):
    """Overlapping clusters and unequal weights: the same optimum as scikit-learn's
    KMeans with as many restarts (within 0.5 % of its inertia, or lower)."""
    x, _ = blobs(seed, k=4, spread=2.0)
    w = np.random.default_rng(seed + 10).uniform(0.1, 5.0, x.shape[0])
    ours = weighted_kmeans(x, 4, w, n_init=10, seed=seed)
    ref = KMeans(4, n_init=10, random_state=seed).fit(x, sample_weight=w)
    assert ours.inertia <= ref.inertia_ * 1.005
    d = ((x[:, None] - ours.centres[None]) ** 2).sum(-1)
    assert ours.inertia == pytest.approx(float(w @ d.min(axis=1)))


def test_weights_move_the_centres():
    """Two points of a cluster, one weighing 3: the centre sits at 3/4 of the way."""
    x = np.array([[0.0], [4.0], [100.0]])
    fit = weighted_kmeans(x, 2, np.array([1.0, 3.0, 1.0]))
    centres = np.sort(fit.centres[:, 0])
    np.testing.assert_allclose(centres, [3.0, 100.0])


def test_deterministic_for_a_seed():
    x, _ = blobs(5, spread=2.0)
    a = weighted_kmeans(x, 3, seed=7)
    b = weighted_kmeans(x, 3, seed=7)
    np.testing.assert_array_equal(a.labels, b.labels)


@pytest.mark.parametrize(
    "x, k, w",
    [
        (np.zeros((5, 2)), 0, None),
        (np.zeros((5, 2)), 6, None),
        (np.zeros(5), 2, None),
        (np.array([[0.0], [np.nan]]), 1, None),
        (np.zeros((3, 1)), 2, np.array([1.0, -1.0, 1.0])),
        (np.zeros((3, 1)), 2, np.zeros(3)),
    ],
)
def test_bad_input_is_refused(x, k, w):
    with pytest.raises(PolarsegError):
        weighted_kmeans(x, k, w)


def test_identical_samples_give_one_populated_cluster_without_error():
    fit = weighted_kmeans(np.ones((10, 2)), 3)
    assert fit.inertia == 0.0
    assert fit.labels.shape == (10,)
