"""The scribble-trained pixel classifier: planted materials, probabilities, smoothing."""

import numpy as np
import pytest
from scipy import ndimage
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline, SegmentParams
from napari_polarseg.engine.classifier.pixel_classifier import (
    ClassifierParams,
    PixelClassifier,
    guided_filter,
    margin_uncertainty,
    predict_pixels,
    train_pixel_classifier,
    training_pixels,
)
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.errors import Cancelled, PolarsegError
from napari_polarseg.engine.features.pixel_features import PixelFeatureParams, pixel_features

ANGLES = np.deg2rad([0.0, 45.0, 90.0, 135.0])


#: Pixel features without the superpixel regions and a classifier without smoothing:
#: the planted scene has no intensity edge at its material boundaries, which both follow.
PIXEL_ONLY = PixelFeatureParams(scales=(0.5, 1.0), groups=("intensity", "polarisation"))
NO_SMOOTHING = ClassifierParams(smoothing=0.0)


def planted_scene(shape=(90, 120), seed=0, albedo=(1.0, 1.0, 1.0)):
    """Two materials in two discs on a background; shading varies across each material.

    Material ρ differs (0.06 / 0.02 / 0.12 at the same shading), while Î is a ramp that
    all three share: intensity alone cannot separate them.
    """
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    truth = np.zeros(shape, dtype=np.int64)
    truth[(rows - 45) ** 2 + (cols - 30) ** 2 < 22**2] = 1
    truth[(rows - 45) ** 2 + (cols - 88) ** 2 < 22**2] = 2
    intensity = (0.3 + 0.4 * cols / shape[1]) * np.asarray(albedo)[truth]
    rho = np.array([0.06, 0.02, 0.12])[truth]  # no class between two neighbours
    phase = np.mod(0.02 * rows + 0.01 * cols, np.pi)
    stack = intensity * (1 + rho * np.cos(2 * ANGLES[:, None, None] - 2 * phase))
    stack = stack + 0.002 * rng.standard_normal(stack.shape)
    strokes = np.zeros(shape, dtype=np.int64)
    # one stroke across each material (over its shades); background: value 3 here,
    # 1 below (labels are class indices of the ascending stroke values)
    strokes[44:46, 14:46] = 1
    strokes[44:46, 72:104] = 2
    strokes[4:6, 5:115] = 3
    strokes[84:86, 5:115] = 3
    strokes, truth = np.where(strokes == 3, 1, np.where(strokes > 0, strokes + 1, 0)), truth
    return stack, truth, strokes


@pytest.fixture(scope="module")
def planted():
    stack, truth, strokes = planted_scene()
    seg = PixelSegmenter(Pipeline(stack, ANGLES, SegmentParams(window=10)))
    return stack, truth, strokes, seg


def test_planted_materials_are_recovered_exactly(planted):
    _, truth, strokes, seg = planted
    out = seg.segment(strokes, feature_params=PIXEL_ONLY, params=NO_SMOOTHING)
    # stroke values 1 (background), 2, 3 → labels 0, 1, 2 = truth
    np.testing.assert_array_equal(out.prediction.classes, [1, 2, 3])
    assert adjusted_rand_score(truth.ravel(), out.result.labels.ravel()) == 1.0
    np.testing.assert_array_equal(out.result.labels, truth)
    p = out.prediction.probabilities
    assert p.shape == (3,) + truth.shape and p.dtype == np.float32
    np.testing.assert_allclose(p.sum(axis=0), 1, atol=1e-5)
    u = out.prediction.uncertainty
    assert u.min() >= 0 and u.max() <= 1
    # the contract maps come from the pipeline
    assert out.result.reconstruction_error is not None
    assert out.result.summary()["n_segments"] == 3


def test_planted_materials_with_edges_are_recovered_exactly_with_the_defaults():
    """Default features (with superpixel regions, scales to σ = 16) and smoothing:
    materials whose albedo differs a little come out exactly away from the boundaries
    (the coarse scales blur the last few pixels of each side)."""
    stack, truth, strokes = planted_scene(albedo=(1.0, 0.9, 1.1))
    seg = PixelSegmenter(Pipeline(stack, ANGLES, SegmentParams(window=10)))
    out = seg.segment(strokes)
    # the default scales at the scene's estimated object size, fixed in the classifier
    sized = PixelFeatureParams().at_object_size(seg.object_size().size_px)
    assert out.classifier.feature_params == sized and not sized.follows_object_size
    assert any(n.startswith("region:") for n in out.classifier.feature_names)
    edge = ndimage.morphological_gradient(truth, size=3) > 0
    near = ndimage.binary_dilation(edge, iterations=3)
    np.testing.assert_array_equal(out.result.labels[~near], truth[~near])
    # measured 0.947 (the region walk puts a few border pixels with their superpixel's
    # side; the classifier alone, region_walk=0: 0.970)
    assert adjusted_rand_score(truth.ravel(), out.result.labels.ravel()) > 0.94


def test_features_are_kept_between_retrainings(planted):
    _, _, strokes, seg = planted
    params = PixelFeatureParams(scales=(0.5, 1.0))
    a = seg.features(params)
    seg.segment(strokes, feature_params=params)
    assert seg.features(params) is a
    assert seg.features(PixelFeatureParams(scales=(1.0,))) is not a


def test_a_trained_classifier_applies_to_another_image(planted):
    _, truth, strokes, seg = planted
    trained = seg.segment(strokes, feature_params=PIXEL_ONLY, params=NO_SMOOTHING)
    stack2, truth2, _ = planted_scene(seed=5)
    other = PixelSegmenter(Pipeline(stack2, ANGLES, SegmentParams(window=10)))
    applied = other.segment(classifier=trained.classifier)
    assert np.mean(applied.result.labels != truth2) < 1e-3  # new noise: a pixel or two
    assert applied.seconds["train"] < trained.seconds["train"] + 1


def test_intensity_alone_cannot_separate_the_planted_materials():
    """The planted scene needs polarisation: an intensity-only classifier fails."""
    stack, truth, strokes = planted_scene()
    i = stack.mean(axis=0)
    f = pixel_features(
        i,
        np.zeros_like(i),
        np.zeros_like(i),
        PixelFeatureParams(scales=(1.0, 2.0), groups=("intensity",)),
    )
    clf = train_pixel_classifier(f, strokes, NO_SMOOTHING)
    labels = predict_pixels(clf, f).labels
    assert adjusted_rand_score(truth.ravel(), labels.ravel()) < 0.5
    smoothing = train_pixel_classifier(f, strokes)
    with pytest.raises(PolarsegError, match="guide"):
        predict_pixels(smoothing, f)


def test_training_pixels_sampling_and_errors():
    s = np.zeros((50, 50), dtype=np.int64)
    s[:20] = 1
    s[30:, :5] = 2
    index, values = training_pixels(s, ClassifierParams(max_pixels_per_class=100))
    assert np.bincount(values).tolist() == [0, 100, 100]
    assert np.all(s.ravel()[index] == values)
    again, _ = training_pixels(s, ClassifierParams(max_pixels_per_class=100))
    np.testing.assert_array_equal(index, again)  # seeded
    valid = np.ones_like(s, dtype=bool)
    valid[30:] = False
    with pytest.raises(PolarsegError, match="at least 2 materials"):
        training_pixels(s, ClassifierParams(), valid)
    with pytest.raises(PolarsegError, match="integer"):
        train_pixel_classifier(
            pixel_features(
                np.ones((50, 50)),
                np.ones((50, 50)) * 0.1,
                np.zeros((50, 50)),
                PixelFeatureParams(scales=(1.0,)),
            ),
            s + 0.5,
        )


def test_feature_mismatch_and_cancel(planted):
    _, _, strokes, seg = planted
    f1 = seg.features(PixelFeatureParams(scales=(0.5, 1.0)))
    clf = train_pixel_classifier(f1, strokes)
    f2 = seg.features(PixelFeatureParams(scales=(1.0,)))
    with pytest.raises(PolarsegError, match="do not match"):
        predict_pixels(clf, f2)
    with pytest.raises(Cancelled):
        predict_pixels(clf, f1, cancel=lambda: True)


def test_metadata_round_trip(planted):
    _, _, strokes, seg = planted
    clf = seg.train(strokes, PixelFeatureParams(scales=(0.5, 1.0)), ClassifierParams(seed=3))
    again = PixelClassifier.from_metadata(clf.model, clf.metadata())
    assert again.feature_names == clf.feature_names
    assert again.params == clf.params and again.feature_params == clf.feature_params
    bad = clf.metadata() | {"classes": [1, 2]}
    with pytest.raises(PolarsegError, match="classes"):
        PixelClassifier.from_metadata(clf.model, bad)
    imp = clf.importances()
    assert abs(sum(imp.values()) - 1) < 1e-6 and list(imp) != []


def test_guided_filter_smooths_flat_regions_and_keeps_guide_edges():
    rng = np.random.default_rng(0)
    guide = np.zeros((60, 60), dtype=np.float32)
    guide[:, 30:] = 1
    noisy = np.clip(guide + 0.3 * rng.standard_normal(guide.shape), 0, 1)[None]
    out = guided_filter(guide, noisy.astype(np.float32), radius=5, eps=1e-3)[0]
    assert out[:, 5:25].std() < 0.3 * noisy[0, :, 5:25].std()
    # the step stays sharp: the columns beside the edge keep their sides' means
    assert out[:, 28].mean() < 0.3 and out[:, 31].mean() > 0.7
    blurred = ndimage.uniform_filter(noisy[0], 11)
    assert abs(out[:, 31].mean() - 1) < abs(blurred[:, 31].mean() - 1)
    const = np.full((1, 20, 20), 0.25, dtype=np.float32)
    np.testing.assert_allclose(guided_filter(rng.random((20, 20)), const, 3), const, atol=1e-5)


def test_margin_uncertainty():
    p = np.array([[0.5, 0.9, 1 / 3], [0.5, 0.1, 1 / 3], [0.0, 0.0, 1 / 3]])[:, :, None]
    np.testing.assert_allclose(
        margin_uncertainty(p.astype(np.float32))[:, 0], [1, 0.2, 1], atol=1e-6
    )
