"""The scribble classifier's feature scales follow the scene's object size D: a scene
keeps the candidate scales σ ≤ max(c · D, 4 px) (``PixelFeatureParams.at_object_size``,
c = ``largest_scale_objects``); D is ``--object-size`` when given, else the scene's own
estimate. A trained classifier keeps the scales it was trained on, on any image."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score
from test_object_size_param import discs_stack
from test_valid_superpixels import ANGLES

from napari_polarseg.engine import Pipeline, Scene
from napari_polarseg.engine.classifier import pixel_segmentation
from napari_polarseg.engine.classifier.pixel_classifier import PixelClassifier
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features.object_size import estimate_object_size, smallest_estimate
from napari_polarseg.engine.features.pixel_feature_params import (
    MIN_LARGEST_SCALE,
    PixelFeatureParams,
)
from napari_polarseg.engine.methods.pixel_classification import scribble_session
from napari_polarseg.engine.params import AUTO
from napari_polarseg.messages import feature_scales_text


def test_at_object_size_keeps_the_scales_up_to_the_diameter():
    p = PixelFeatureParams()  # candidates 1, 2, 4, 8, 16; c = 1
    assert p.at_object_size(10.0).scales == (1.0, 2.0, 4.0, 8.0)
    assert p.at_object_size(16.0).scales == p.scales
    assert p.at_object_size(500.0).scales == p.scales
    assert MIN_LARGEST_SCALE == 4.0 and p.at_object_size(2.0).scales == (1.0, 2.0, 4.0)
    half = PixelFeatureParams(largest_scale_objects=0.5)
    assert half.at_object_size(20.0).scales == (1.0, 2.0, 4.0, 8.0)
    # the kept parameters are fixed: they no longer follow a size
    sized = p.at_object_size(10.0)
    assert not sized.follows_object_size and sized.at_object_size(1000.0) == sized
    fixed = PixelFeatureParams(largest_scale_objects=0.0)
    assert fixed.at_object_size(2.0) is fixed
    # candidates all wider than the cap: the smallest stays
    assert PixelFeatureParams(scales=(8.0, 16.0)).at_object_size(2.0).scales == (8.0,)
    with pytest.raises(PolarsegError, match="largest_scale_objects"):
        PixelFeatureParams(largest_scale_objects=-1.0)
    assert PixelFeatureParams.from_dict(half.to_dict()) == half


def strokes_of(truth: np.ndarray, seed: int = 0, per_class: int = 40) -> np.ndarray:
    """Scribbles: ``per_class`` random pixels of every class (values class + 1)."""
    rng = np.random.default_rng(seed)
    strokes = np.zeros_like(truth)
    for c in np.unique(truth):
        where = np.flatnonzero(truth.ravel() == c)
        strokes.ravel()[rng.choice(where, per_class, replace=False)] = c + 1
    return strokes


def classify(stack: np.ndarray, strokes: np.ndarray, **changes) -> tuple:
    result = Scene(stack, ANGLES).segment(
        AUTO.replace(method="classifier", **changes), inputs={"scribbles": strokes}
    )
    return result, result.method_record


@pytest.mark.parametrize("diameter", [10, 40])
def test_planted_discs_keep_the_scales_up_to_their_diameter(diameter):
    """Discs of a known diameter: the estimate lies within 1.5 × of it, the classifier
    keeps the scales up to it, the record says so, and the materials are found."""
    stack, truth = discs_stack(diameter)
    result, record = classify(stack, strokes_of(truth))
    assert record["object_size_found"] is True and record["object_size_applied"] is True
    assert diameter / 1.5 < record["object_size"] < diameter * 1.5
    expected = [s for s in (1.0, 2.0, 4.0, 8.0, 16.0) if s <= max(record["object_size"], 4.0)]
    assert record["feature_scales"] == expected
    assert (16.0 in expected) is (diameter == 40)
    assert adjusted_rand_score(truth.ravel(), result.labels.ravel()) > 0.9


def test_given_object_size_sets_the_scales():
    stack, truth = discs_stack(10)
    _, record = classify(stack, strokes_of(truth), object_size=40.0)
    assert record["object_size"] == 40.0 and record["object_size_found"] is False
    assert record["feature_scales"] == [1.0, 2.0, 4.0, 8.0, 16.0]
    _, record = classify(stack, strokes_of(truth), object_size=5.0)
    assert record["feature_scales"] == [1.0, 2.0, 4.0]


def test_a_trained_classifier_keeps_its_scales_on_another_image():
    """Trained on 10 px discs (σ ≤ 8), applied to 40 px discs (whose own estimate
    would keep σ = 16): the classifier's features are computed, not the new scene's."""
    small, small_truth = discs_stack(10)
    scene = Scene(small, ANGLES)
    scene.segment(AUTO.replace(method="classifier"), inputs={"scribbles": strokes_of(small_truth)})
    trained = scribble_session(scene).classifier
    assert trained.feature_params.scales == (1.0, 2.0, 4.0, 8.0)
    # what a classifier file stores and gives back: fixed scales
    meta = trained.metadata()
    meta["feature_params"]["largest_scale_objects"] = 1.0  # as an older file might say
    loaded = PixelClassifier.from_metadata(trained.model, meta)
    assert not loaded.feature_params.follows_object_size
    large, large_truth = discs_stack(40, seed=1)
    applied = Scene(large, ANGLES).segment(
        AUTO.replace(method="classifier"), inputs={"classifier": loaded}
    )
    assert "object_size" not in applied.method_record
    assert adjusted_rand_score(large_truth.ravel(), applied.labels.ravel()) > 0.5


@pytest.mark.parametrize("shape", [(64, 80), (700, 900), (1500, 1100)])
def test_no_estimate_falls_below_the_smallest_it_can_give(shape):
    """The shortcut of ``PixelSegmenter.sized`` (every scale kept without waiting for
    the estimate) holds: on noise and on fine discs the estimate never falls below
    :func:`smallest_estimate` of the image."""
    rng = np.random.default_rng(1)
    rows, cols = np.indices(shape)
    fine = ((rows % 6) < 3) ^ ((cols % 6) < 3)  # a 3 px checkerboard: finer than a grid cell
    for intensity in (1 + rng.random(shape), 1 + 0.5 * fine + 0.01 * rng.random(shape)):
        dop, phase = 0.1 + 0.05 * rng.random(shape), rng.random(shape)
        valid = np.ones(shape, dtype=bool)
        floor = smallest_estimate(valid)
        assert estimate_object_size(intensity, dop, phase, valid).size_px >= floor - 1e-9
    assert smallest_estimate(np.zeros(shape, dtype=bool)) == 0.0


def test_a_large_image_keeps_every_scale_without_the_estimate(monkeypatch):
    """Where no estimate could drop a scale, the features do not wait for one."""
    shape = (1900, 1900)  # 3.6 MP: the estimate's grid is block-averaged by 6
    rng = np.random.default_rng(2)
    stack = rng.integers(900, 1100, size=(len(ANGLES), *shape)).astype(np.uint16)
    seg = PixelSegmenter(Pipeline(stack, ANGLES))
    assert smallest_estimate(np.ones(shape, dtype=bool)) > 16.0

    def refuse(*args, **kwargs):
        raise AssertionError("estimated")

    monkeypatch.setattr(pixel_segmentation, "scene_object_size", refuse)
    assert seg.sized(PixelFeatureParams()).scales == (1.0, 2.0, 4.0, 8.0, 16.0)
    assert seg.known_object_size() is None  # nothing estimated


def test_the_line_says_what_the_scales_followed():
    small = {"feature_scales": [1.0, 2.0, 4.0, 8.0], "object_size_applied": True}
    found = {**small, "object_size": 9.4, "object_size_found": True}
    assert feature_scales_text(found) == (
        "object size about 9 px (estimated from the scene): feature scales σ = 1, 2, 4, 8 px"
    )
    given = {**small, "object_size": 12.0, "object_size_found": False}
    assert feature_scales_text(given).startswith("object size 12 px (given)")
    large = {**small, "feature_scales": [1.0, 2.0, 4.0, 8.0, 16.0], "object_size_at_least": 39.6}
    assert feature_scales_text(large) == (
        "feature scales σ = 1, 2, 4, 8, 16 px, every one: an object size estimated on this "
        "image is at least 40 px"
    )
    assert feature_scales_text({"feature_scales": [1.0], "object_size_applied": False}) == ""
    assert feature_scales_text({"k": 3}) == ""
