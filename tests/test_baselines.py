"""The benchmarks' plain yardsticks (benchmarks/baselines.py) on planted images.

``smoothed_kmeans`` must split two materials that differ only in ρ (same intensity),
and the truth-trained left→right bound must reach ≈ 1 where the classes are trivially
separable. Small images, so the whole module runs in a few seconds.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from baselines import (  # noqa: E402
    region_features,
    right_half_ari,
    smoothed_kmeans,
    truth_bound_halves,
)


def _planted(shape=(160, 192), seed=0):
    """Two materials, same mean intensity, ρ 0.05 (top) vs 0.4 (bottom), noisy."""
    rng = np.random.default_rng(seed)
    truth = np.ones(shape, np.int32)
    truth[shape[0] // 2 :] = 2
    intensity = 100 + 5 * rng.standard_normal(shape)
    dop = np.where(truth == 1, 0.05, 0.4) + 0.02 * rng.standard_normal(shape)
    phase = 0.3 + 0.05 * rng.standard_normal(shape)
    return intensity, np.clip(dop, 0, 1), phase, truth


def test_smoothed_kmeans_separates_two_materials_by_dop():
    intensity, dop, phase, truth = _planted()
    labels = smoothed_kmeans(intensity, dop, phase, 2)
    assert labels.shape == truth.shape
    assert adjusted_rand_score(truth.ravel(), labels.ravel()) > 0.9


def test_smoothed_kmeans_fits_on_valid_pixels_only():
    intensity, dop, phase, truth = _planted()
    valid = np.ones(truth.shape, bool)
    valid[:, :8] = False
    labels = smoothed_kmeans(intensity, dop, phase, 2, valid=valid)
    assert adjusted_rand_score(truth[valid], labels[valid]) > 0.9


@pytest.mark.parametrize(
    ("features", "classifier"),
    [("plain", "forest"), ("rich", "forest"), ("regions", "forest"), ("regions", "boosting")],
)
def test_truth_bound_halves_is_one_on_a_separable_scene(features, classifier):
    intensity, dop, phase, truth = _planted()
    truth = truth.copy()
    truth[:, 88:104] = 0  # an unlabelled band, as the hand-drawn truth has
    value, seen = truth_bound_halves(intensity, dop, phase, truth, features, None, classifier)
    assert seen
    assert value > 0.95


def test_truth_bound_halves_flags_a_class_missing_on_the_left():
    intensity, dop, phase, truth = _planted()
    truth = truth.copy()
    truth[:, 120:150] = 3  # a class only in the right half
    _, seen = truth_bound_halves(intensity, dop, phase, truth)
    assert not seen


def test_region_features_split_the_materials():
    intensity, dop, phase, truth = _planted()
    f = region_features(intensity, dop, phase)
    assert f.shape[:2] == truth.shape and f.shape[2] >= 1
    # the two materials' pixels carry different node features (the first component)
    top, bottom = f[truth == 1, 0], f[truth == 2, 0]
    assert abs(np.median(top) - np.median(bottom)) > 3 * (top.std() + bottom.std()) / 2


def test_region_features_fill_invalid_pixels_from_the_nearest_valid_one():
    intensity, dop, phase, truth = _planted()
    invalid = np.zeros(truth.shape, bool)
    invalid[:10, :10] = True
    f = region_features(intensity, dop, phase, invalid)
    assert np.all(np.isfinite(f))
    # each corner pixel carries a superpixel of the valid pixels just around the corner
    border = np.concatenate(
        [f[:11, 10:12].reshape(-1, f.shape[2]), f[10:12, :11].reshape(-1, f.shape[2])]
    )
    corner = f[:10, :10].reshape(-1, f.shape[2])
    assert all(np.any(np.all(np.isclose(border, v), axis=1)) for v in corner)


def test_right_half_ari_scores_only_the_labelled_right_half():
    truth = np.zeros((4, 8), np.int32)
    truth[:, 4:6], truth[:, 6:] = 1, 2
    labels = np.zeros_like(truth)  # the left half is all wrong: not scored
    labels[:, 4:6], labels[:, 6:] = 5, 7
    assert right_half_ari(labels, truth) == pytest.approx(1.0)
    labels[:, 6:] = 5
    assert right_half_ari(labels, truth) == pytest.approx(0.0)
