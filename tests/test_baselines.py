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
from baselines import smoothed_kmeans, truth_bound_halves  # noqa: E402


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


@pytest.mark.parametrize("features", ["plain", "rich"])
def test_truth_bound_halves_is_one_on_a_separable_scene(features):
    intensity, dop, phase, truth = _planted()
    truth = truth.copy()
    truth[:, 88:104] = 0  # an unlabelled band, as the hand-drawn truth has
    value, seen = truth_bound_halves(intensity, dop, phase, truth, features)
    assert seen
    assert value > 0.95


def test_truth_bound_halves_flags_a_class_missing_on_the_left():
    intensity, dop, phase, truth = _planted()
    truth = truth.copy()
    truth[:, 120:150] = 3  # a class only in the right half
    _, seen = truth_bound_halves(intensity, dop, phase, truth)
    assert not seen
