"""The feature-separation bench (benchmarks/feature_separation.py): η² against known
answers, and the diffuse physics table's columns on one synthetic scene."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
import feature_separation  # noqa: E402

from napari_polarseg.engine.synthetic.scenes import make_scene  # noqa: E402


def test_eta_squared_known_answers():
    rng = np.random.default_rng(0)
    material = np.repeat([0, 1], 500)
    weight = np.ones(material.size)
    x = np.stack(
        [
            material.astype(float),  # the material itself: all of the spread
            rng.standard_normal(material.size),  # unrelated: none of it
            material + np.tile([-1.0, 1.0], 500),  # means 1 apart, spread 1 within: 1/5
        ],
        axis=1,
    )
    eta = feature_separation.eta_squared(x, material, weight)
    assert eta[0] == pytest.approx(1.0)
    assert eta[1] < 0.01
    # between-material variance 1/4 over a total of 1/4 + 1
    assert eta[2] == pytest.approx(0.2)


def test_zenith_physics_separates_leaves():
    """On a leaves scene, ρ over the diffuse ρ of the true zenith tells the two leaf
    materials (and the board) apart far better than either cue read without it."""
    scene = make_scene("leaves", shape=(240, 320), seed=0)  # the bench's shape
    true_zenith, shading, given = feature_separation.zenith_figures(scene)
    assert true_zenith > 0.6
    assert true_zenith > shading + 0.2 and true_zenith > given + 0.2
