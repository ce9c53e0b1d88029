"""The scribble loop's scripting API (issue 23): ScribbleSession and the coarse-to-fine
prediction it runs."""

from __future__ import annotations

import numpy as np
import pytest

from napari_polarseg.engine import (
    ClassifierParams,
    PixelFeatureParams,
    PolarsegError,
    ScribbleSession,
)
from napari_polarseg.engine.classifier.refined_prediction import (
    border_cells,
    grid_probabilities,
    refined_probabilities,
)
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes

ANGLES = [0, 45, 90, 135]
#: Stroke value of material m (truth label m): far from 1, 2, 3 so a label that is the
#: class index instead of the scribble's value shows.
VALUES = np.array([0, 10, 20, 30])


@pytest.fixture(scope="module")
def scene():
    s = make_scene("leaves", shape=(120, 130), angles_deg=ANGLES)
    strokes = VALUES[scribble_strokes(s.labels, seed=0, per_material=6, length=16)]
    return s, strokes


@pytest.fixture(scope="module")
def session(scene):
    s, strokes = scene
    session = ScribbleSession(s.stack, ANGLES)
    session.update(strokes)
    return session


def test_update_twice_reuses_the_features(scene):
    s, strokes = scene
    session = ScribbleSession(s.stack, ANGLES)
    assert session.feature_runs == 0 and session.cached_features is None
    first = session.update(np.where(np.isin(strokes, [10, 20]), strokes, 0))
    features = session.cached_features
    assert session.feature_runs == 1 and set(np.unique(first)) == {10, 20}
    second = session.update(strokes)  # a third material painted
    assert session.feature_runs == 1 and session.cached_features is features
    assert set(np.unique(second)) == {10, 20, 30}
    assert session.classifier.n_scribbled_pixels == np.count_nonzero(strokes)


def test_labels_are_the_scribbles_own_values(scene, session):
    s, strokes = scene
    labels = session.labels
    assert labels.shape == s.labels.shape and labels.dtype.kind == "i"
    np.testing.assert_array_equal(session.classes, [10, 20, 30])
    # each material is labelled mostly with the value its strokes carry
    for m in np.unique(s.labels):
        values, counts = np.unique(labels[s.labels == m], return_counts=True)
        assert values[np.argmax(counts)] == VALUES[m + 1]
    # the scribbled pixels themselves are labelled with their own value
    marked = strokes > 0
    assert np.mean(labels[marked] == strokes[marked]) > 0.95


def test_probabilities_and_uncertainty(session):
    p, u = session.probabilities, session.uncertainty
    assert p.shape == (3, *session.labels.shape) and p.dtype == np.float32
    np.testing.assert_allclose(p.sum(axis=0), 1, atol=1e-5)
    assert u.shape == session.labels.shape and 0 <= u.min() and u.max() <= 1
    np.testing.assert_array_equal(session.classes[np.argmax(p, axis=0)], session.labels)


def test_save_load_predicts_the_same(scene, session, tmp_path):
    from napari_polarseg.classifier_file import load_pixel_classifier, save_pixel_classifier

    s, _ = scene
    path = tmp_path / "loop.polarseg-clf"
    save_pixel_classifier(path, session.classifier)
    loaded = load_pixel_classifier(path)
    other = ScribbleSession(s.stack, ANGLES)
    other.use(loaded)
    other.refine()
    # the classifier in memory, applied the same way (without the strokes, which the
    # region walk of the trained session also started from)
    reference = ScribbleSession(s.stack, ANGLES)
    reference.use(session.classifier)
    reference.refine()
    np.testing.assert_array_equal(other.labels, reference.labels)
    np.testing.assert_allclose(other.probabilities, reference.probabilities, atol=1e-6)
    assert np.mean(other.labels == session.labels) > 0.9


def test_nothing_to_save_or_show_before_an_update(scene):
    s, _ = scene
    session = ScribbleSession(s.stack, ANGLES)
    assert session.classifier is None
    with pytest.raises(PolarsegError, match="no classifier yet"):
        session.preview()
    with pytest.raises(PolarsegError, match="nothing predicted"):
        session.labels  # noqa: B018


def test_preview_is_the_grid_and_refine_fixes_the_borders(scene, session):
    s, strokes = scene
    session.train(strokes)
    preview = session.classes[session.preview().labels]
    n_grid = session.n_predicted
    assert n_grid == 15 * 17  # ⌈120 / 8⌉ × ⌈130 / 8⌉ samples of the preview's grid
    refined = session.classes[session.refine().labels]
    assert n_grid < session.n_predicted < refined.size
    # the preview (8 px grid, on a small noisy scene) agrees with most of the labels
    assert np.mean(preview == refined) > 0.8


def test_coarse_to_fine_equals_every_pixel_off_the_borders(scene, session):
    feats = session.cached_features
    model = session.classifier.model
    full = refined_probabilities(model, feats, 1).probabilities
    fine = refined_probabilities(model, feats, 4)
    coarse = grid_probabilities(model, feats, 4)
    cells = np.kron(border_cells(np.argmax(coarse, axis=0)), np.ones((4, 4), bool))
    cells = cells[: full.shape[1], : full.shape[2]]
    # border cells: every pixel predicted on its own features, as by stride 1
    np.testing.assert_allclose(fine.probabilities[:, cells], full[:, cells], atol=1e-6)
    # elsewhere the nine grid samples around agree, and so does the interpolation
    inner = ~cells
    assert np.mean(np.argmax(fine.probabilities, 0)[inner] == np.argmax(full, 0)[inner]) > 0.99
    assert fine.n_predicted == coarse[0].size + int(cells.sum())


def test_sampled_training_pixels_are_said(scene):
    s, strokes = scene
    params = ClassifierParams(max_pixels_per_class=20)
    features = PixelFeatureParams(scales=(1.0, 4.0))
    session = ScribbleSession(s.stack, ANGLES, features, params)
    session.update(strokes)
    clf = session.classifier
    assert clf.subsampled and clf.n_training_pixels == 60
    assert clf.n_scribbled_pixels == np.count_nonzero(strokes)
    assert f"60 of {clf.n_scribbled_pixels} scribbled pixels train" in clf.training_text()
    assert "at most 20 per material" in clf.training_text()


def test_plane_by_plane_reductions_match_numpy():
    from napari_polarseg.engine.classifier.pixel_classifier import (
        margin_uncertainty,
        most_probable,
    )

    rng = np.random.default_rng(1)
    for k in (2, 3, 5):
        p = rng.random((k, 40, 50)).astype(np.float32)
        p[:, :5] = 0.25  # ties: the first class wins, the margin is 0
        p /= p.sum(axis=0)
        np.testing.assert_array_equal(most_probable(p), np.argmax(p, axis=0))
        top = np.sort(p, axis=0)
        np.testing.assert_allclose(margin_uncertainty(p), 1 - (top[-1] - top[-2]), atol=1e-6)
        assert np.all(margin_uncertainty(p)[:5] == 1)
