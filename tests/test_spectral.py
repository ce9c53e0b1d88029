"""k-way spectral clustering (engine/graph/spectral.py) against planted partitions and by hand."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sps
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline, SegmentParams
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.graph import spectral
from napari_polarseg.engine.synthetic.scenes import make_scene


def planted(sizes, p_in=0.9, p_out=0.05, noise=0.04, seed=0):
    rng = np.random.default_rng(seed)
    truth = np.repeat(np.arange(len(sizes)), sizes)
    rng.shuffle(truth)
    W = np.where(truth[:, None] == truth[None, :], p_in, p_out)
    W = W + noise * rng.random(W.shape)
    return (W + W.T) / 2, truth


@pytest.mark.parametrize("sizes", [[30, 50], [40, 25, 35], [20, 30, 25, 15, 40]])
def test_recovers_planted_partitions(sizes):
    W, truth = planted(sizes, seed=len(sizes))
    labels = spectral.SpectralClustering(W).labels(len(sizes))
    assert adjusted_rand_score(truth, labels) == 1.0
    assert labels[0] == 0 and labels.max() == len(sizes) - 1  # first-appearance numbering


def test_eigenvectors_solve_the_normalized_problem_and_paths_agree():
    W, _ = planted([900, 700], seed=3)  # above DENSE_MAX: Lanczos path
    assert W.shape[0] > spectral.DENSE_MAX
    z = spectral.normalized_eigenvectors(W, 3)
    d = W.sum(1)
    M = W / np.sqrt(d)[:, None] / np.sqrt(d)[None, :]
    vals = scipy.linalg.eigh(M, eigvals_only=True)[::-1][:3]
    np.testing.assert_allclose(np.einsum("ik,ij,jk->k", z, M, z), vals, rtol=1e-7)
    np.testing.assert_allclose(M @ z, z * vals, atol=1e-6)
    # the top eigenvector is the known D^1/2 1 (eigenvalue 1)
    assert vals[0] == pytest.approx(1.0)
    u = np.sqrt(d) / np.linalg.norm(np.sqrt(d))
    assert abs(z[:, 0] @ u) == pytest.approx(1.0, abs=1e-8)
    # sparse input gives the same partition as dense
    lab_dense = spectral.SpectralClustering(W).labels(2)
    lab_sparse = spectral.SpectralClustering(sps.csr_matrix(W)).labels(2)
    assert adjusted_rand_score(lab_dense, lab_sparse) == 1.0


def test_changing_k_reuses_the_eigenvectors():
    W, truth = planted([30, 30, 30, 30], seed=5)
    sc = spectral.SpectralClustering(W)
    sc.labels(2)
    vectors = sc._vectors
    assert vectors.shape[1] == 2 + spectral.EXTRA_VECTORS
    assert adjusted_rand_score(truth, sc.labels(4)) == 1.0
    assert sc._vectors is vectors  # no new eigensolve for k within the cached vectors


def test_kway_ncut_by_hand():
    # two pairs joined by weak edges: A = {0, 1}, B = {2, 3}
    W = np.array(
        [[0, 1.0, 0.1, 0], [1.0, 0, 0, 0.2], [0.1, 0, 0, 1.0], [0, 0.2, 1.0, 0]], dtype=float
    )
    labels = np.array([0, 0, 1, 1])
    cut = 0.3
    assoc_a = 1.0 + 1.0 + 0.1 + 0.2
    assoc_b = 1.0 + 1.0 + 0.1 + 0.2
    expected = cut / assoc_a + cut / assoc_b
    np.testing.assert_allclose(spectral.kway_ncut(W, labels), [expected, expected])


def test_small_segments_merge_into_the_nearest_one():
    W, truth = planted([60, 60, 4], seed=7)
    assert adjusted_rand_score(truth, spectral.SpectralClustering(W).labels(3)) == 1.0
    merged = spectral.SpectralClustering(W, min_size=10).labels(3)
    assert np.bincount(merged).min() >= 10
    assert len(np.unique(merged)) == 2
    big = truth < 2
    assert adjusted_rand_score(truth[big], merged[big]) == 1.0


def test_bad_inputs():
    with pytest.raises(PolarsegError, match="square"):
        spectral.SpectralClustering(np.ones((3, 4)))
    with pytest.raises(PolarsegError, match=">= 1"):
        spectral.SpectralClustering(np.ones((3, 3))).labels(0)
    with pytest.raises(PolarsegError, match="degree"):
        spectral.normalized_eigenvectors(np.zeros((3, 3)), 2)


def test_pipeline_kway_only_reruns_labels_when_k_changes():
    sc = make_scene("leaves", shape=(64, 72), seed=1)
    pipe = Pipeline(
        sc.stack,
        sc.angles,
        SegmentParams(window=8, degree=6, clustering="kway", scale_mode="median", scale=2.0),
    )
    res = pipe.run(reconstruction=False)
    assert res.labels.shape == sc.labels.shape and res.labels.max() == 2
    assert len(res.ncut_values) == 3 and all(0 <= v <= 2 for v in res.ncut_values)
    before = dict(pipe.calls)
    res4 = pipe.run(pipe.params.replace(n_segments=4), reconstruction=False)
    assert res4.labels.max() == 3
    changed = {s for s in pipe.calls if pipe.calls[s] != before.get(s, 0)}
    assert changed == {"labels"}
    # switching back to recursive cuts recomputes the cut stage only
    pipe.run(pipe.params.replace(clustering="recursive"), reconstruction=False)
    assert pipe.calls["cut"] == before["cut"] + 1 and pipe.calls["affinity"] == before["affinity"]
