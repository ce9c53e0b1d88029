"""Unsupervised segmentation on superpixels (engine/unsupervised/segmenter.py)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features.superpixels import polarisation_superpixels
from napari_polarseg.engine.unsupervised.params import (
    CLUSTERINGS,
    NODE_FEATURES,
    UnsupervisedParams,
)
from napari_polarseg.engine.unsupervised.region_features import (
    dop_given_intensity,
    node_features,
)
from napari_polarseg.engine.unsupervised.segmenter import region_adjacency, segment_unsupervised


def planted(k: int = 3, shape: tuple[int, int] = (96, 120), seed: int = 0):
    """k vertical bands of materials differing in ρ and AoLP coherence under one shading.

    Shared smooth shading, a per-material intensity level (intensity edges at the
    borders), ρ of 0.04 / 0.12 / 0.25 with 5 % noise; φ follows one smooth field except
    in band 1, where it is random (incoherent AoLP).
    """
    rng = np.random.default_rng(seed)
    h, w = shape
    rows, cols = np.mgrid[0:h, 0:w]
    truth = np.minimum(cols * k // w, k - 1)
    shading = 0.5 + 0.3 * np.sin(rows / h * np.pi) * np.cos((cols / w - 0.5) * 2)
    level = np.array([1.0, 0.7, 1.3])[:k]
    rho = np.array([0.04, 0.12, 0.25])[:k]
    intensity = shading * level[truth] * (1 + 0.01 * rng.standard_normal(shape))
    dop = rho[truth] * (1 + 0.05 * rng.standard_normal(shape))
    coherent = np.arctan2(rows - h / 2, cols - w / 2) % np.pi
    phase = np.where(truth == 1, rng.uniform(0, np.pi, shape), coherent)
    return intensity, dop, phase, truth


@pytest.mark.parametrize("k", [2, 3])
def test_planted_materials_recovered_exactly(k):
    i, d, p, truth = planted(k)
    r = segment_unsupervised(i, d, p, k)
    assert adjusted_rand_score(truth.ravel(), r.labels.ravel()) == pytest.approx(1.0)
    assert r.labels.shape == truth.shape and r.labels.dtype == np.int32
    assert not r.degenerate
    # every pixel takes its superpixel's label away from the refined borders
    assert np.mean(r.labels == r.node_labels[r.regions]) > 0.9
    assert r.labels[0, 0] == 0  # numbered in order of first appearance


def test_deterministic():
    i, d, p, _ = planted(3, seed=1)
    a = segment_unsupervised(i, d, p, 3)
    b = segment_unsupervised(i, d, p, 3)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.regions, b.regions)


@pytest.mark.parametrize("clustering", CLUSTERINGS)
def test_every_clustering_runs(clustering):
    i, d, p, truth = planted(2)
    params = UnsupervisedParams(clustering=clustering)
    r = segment_unsupervised(i, d, p, 2, params)
    assert r.labels.shape == truth.shape
    assert set(np.unique(r.labels)) <= {0, 1}


def test_pixel_features_and_material_cue_and_maf():
    i, d, p, truth = planted(2)
    params = UnsupervisedParams(
        features=NODE_FEATURES, pixel_scales=(2.0,), projection="maf", components=2
    )
    r = segment_unsupervised(i, d, p, 2, params)
    assert any(n.startswith("pixel:") for n in r.feature_names)
    assert r.node_features.shape[1] == 2
    assert adjusted_rand_score(truth.ravel(), r.labels.ravel()) > 0.9


def test_one_segment():
    i, d, p, _ = planted(2)
    r = segment_unsupervised(i, d, p, 1)
    assert np.all(r.labels == 0) and not r.degenerate


def test_superpixels_and_adjacency():
    i, d, p, _ = planted(2)
    regions = polarisation_superpixels(i, d, p, 64)
    n = int(regions.max()) + 1
    assert np.array_equal(np.unique(regions), np.arange(n))
    adj = region_adjacency(regions)
    assert adj.shape == (n, n) and (adj != adj.T).nnz == 0
    assert adj.diagonal().sum() == 0
    x = node_features(i, d, p, regions)
    assert x.shape == (n, len(NODE_FEATURES)) and np.all(np.isfinite(x))


def test_region_dolp_of_constant_region():
    i = np.ones((8, 8))
    d = np.full((8, 8), 0.2)
    p = np.zeros((8, 8))
    x = node_features(i, d, p, np.zeros((8, 8), dtype=np.int32), ("dop", "dolp"))
    np.testing.assert_allclose(x[0], [0.2, 0.2], rtol=1e-6)


def test_dop_given_intensity_is_zero_on_the_relation_and_flags_another_material():
    """Regions on one cubic relation log ρ = f(log Î) have no residual; regions of a
    material with ρ halved at the same shading lie at log ½ off it, if the relation is
    fitted where the first material covers most of the image (by area)."""
    rng = np.random.default_rng(0)
    log_i = rng.uniform(-1.0, 1.0, 200)
    f = -3.0 + 0.8 * log_i - 0.3 * log_i**2 + 0.1 * log_i**3
    np.testing.assert_allclose(dop_given_intensity(log_i, np.exp(f), np.ones(200)), 0.0, atol=1e-3)
    other = np.arange(200) < 10
    dop = np.exp(f) * np.where(other, 0.5, 1.0)
    area = np.where(other, 1.0, 50.0)
    r = dop_given_intensity(log_i, dop, area)
    np.testing.assert_allclose(r[other], np.log(0.5), atol=0.02)
    np.testing.assert_allclose(r[~other], 0.0, atol=0.02)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((np.ones((8, 8)), np.ones((8, 9)), np.ones((8, 8)), 2), "one shape"),
        ((np.ones(8), np.ones(8), np.ones(8), 2), "2-D"),
        ((np.ones((8, 8)), np.ones((8, 8)), np.ones((8, 8)), 0), "n_segments"),
        ((np.ones((8, 8)), np.ones((8, 8)), np.ones((8, 8)), 2.5), "n_segments"),
        ((np.ones((8, 8)), np.ones((8, 8)), np.ones((8, 8)), 50), "superpixels"),
    ],
)
def test_bad_inputs_raise_one_line(args, message):
    with pytest.raises(PolarsegError, match=message) as info:
        segment_unsupervised(*args)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "change",
    [
        {"region_area": 2},
        {"boundary": "edges"},
        {"features": ("colour",)},
        {"features": (), "pixel_scales": ()},
        {"pixel_scales": (-1.0,)},
        {"pixel_scales": (1.0,), "pixel_groups": ("regions",)},
        {"variance": 0.0},
        {"projection": "ica"},
        {"components": 0},
        {"clustering": "dbscan"},
        {"covariance": "banded"},
        {"smoothing": 1.0},
        {"smoothing_iterations": -1},
        {"scale": 0.0},
        {"polarisation_edge_weight": -1.0},
    ],
)
def test_bad_params_raise_one_line(change):
    with pytest.raises(PolarsegError) as info:
        UnsupervisedParams(**change)
    assert "\n" not in str(info.value)


def test_params_round_trip():
    p = UnsupervisedParams()
    assert UnsupervisedParams(**p.to_dict()) == p
    assert p.replace(clustering="kmeans").clustering == "kmeans"


def test_relabel_matches_unique_inverse():
    from napari_polarseg.engine.features.superpixels import relabel

    rng = np.random.default_rng(0)
    for labels in (
        rng.integers(0, 50, (30, 40)) * 3 + 7,  # gaps, non-negative: counted
        rng.integers(-5, 5, (20, 20)),  # negative labels: sorted
    ):
        _, inverse = np.unique(labels, return_inverse=True)
        out = relabel(labels)
        assert out.dtype == np.int32
        assert np.array_equal(out, inverse.reshape(labels.shape))
