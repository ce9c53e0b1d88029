"""The coarse-to-fine prediction's reading of many pixels (issue 40, point 12): a forest
predicts row chunks on every core with the trees' sum in a fixed order, what it
returns equals scikit-learn's own prediction; the border cells' pixels come sorted."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.ensemble import ExtraTreesClassifier, HistGradientBoostingClassifier

from napari_polarseg.engine import Cancelled
from napari_polarseg.engine.classifier import refined_prediction
from napari_polarseg.engine.classifier.refined_prediction import (
    border_pixels,
    predict_read,
    predict_rows,
)


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(600, 6)).astype(np.float32)
    y = (x[:, 0] + 0.5 * x[:, 1] > 0).astype(int) + (x[:, 2] > 1)
    rows = rng.normal(size=(3000, 6)).astype(np.float32)
    return x, y, rows


@pytest.fixture(scope="module")
def forest(data):
    x, y, _ = data
    return ExtraTreesClassifier(n_estimators=12, n_jobs=-1, random_state=0).fit(x, y)


@pytest.mark.parametrize("n", [1, 7, 1000, 3000])
def test_a_forest_predicts_as_scikit_learn_in_chunks_on_threads(data, forest, monkeypatch, n):
    monkeypatch.setattr(refined_prediction, "FOREST_CHUNK", 256)  # many chunks, rounds
    rows = data[2][:n]
    got = predict_rows(forest, rows)
    assert got.dtype == np.float32 and got.shape == (n, 3)
    # the trees summed in their order: exactly what one thread of scikit-learn gives
    forest.set_params(n_jobs=1)
    try:
        one = forest.predict_proba(rows).astype(np.float32)
    finally:
        forest.set_params(n_jobs=-1)
    np.testing.assert_array_equal(got, one)
    np.testing.assert_allclose(got, forest.predict_proba(rows), atol=1e-6)
    assert forest.n_jobs == -1  # the model itself is left as it was


def test_every_row_is_read_once_in_chunks(data, forest, monkeypatch):
    monkeypatch.setattr(refined_prediction, "FOREST_CHUNK", 256)
    rows = data[2]
    spans: list[tuple[int, int]] = []

    def read(a: int, b: int) -> np.ndarray:
        spans.append((a, b))
        return rows[a:b]

    got = predict_read(forest, rows.shape[0], read)
    spans.sort()
    assert spans[0][0] == 0 and spans[-1][1] == rows.shape[0]
    assert all(b == c for (_, b), (c, _) in zip(spans, spans[1:], strict=False))
    assert max(b - a for a, b in spans) <= 256 and len(spans) % refined_prediction.N_THREADS == 0
    np.testing.assert_array_equal(got, predict_rows(forest, rows))


def test_another_model_predicts_in_the_calling_thread(data):
    x, y, rows = data
    model = HistGradientBoostingClassifier(max_iter=5, random_state=0).fit(x, y)
    got = predict_rows(model, rows)
    np.testing.assert_allclose(got, model.predict_proba(rows).astype(np.float32))


@pytest.mark.parametrize("n", [100, 3000])
def test_a_cancel_stops_the_prediction(data, forest, monkeypatch, n):
    monkeypatch.setattr(refined_prediction, "FOREST_CHUNK", 256)
    with pytest.raises(Cancelled):
        predict_rows(forest, data[2][:n], cancel=lambda: True)


@pytest.mark.parametrize("shape", [(40, 52), (37, 51), (1, 9)])
@pytest.mark.parametrize("stride", [1, 3, 4])
def test_border_pixels_are_every_pixel_of_the_cells_sorted(shape, stride):
    rng = np.random.default_rng(stride)
    cells = rng.random((-(-shape[0] // stride), -(-shape[1] // stride))) < 0.3
    got = border_pixels(cells, stride, shape)
    pixels = np.kron(cells, np.ones((stride, stride), bool))[: shape[0], : shape[1]]
    np.testing.assert_array_equal(got, np.flatnonzero(pixels))
    assert got.dtype == np.intp


@pytest.mark.parametrize("kind", ["extra", "random"])
def test_the_trees_summed_equal_the_forest_to_the_bit(data, kind):
    from sklearn.ensemble import RandomForestClassifier

    from napari_polarseg.engine.classifier.refined_prediction import TreeSum, one_thread

    x, y, rows = data
    model = (ExtraTreesClassifier if kind == "extra" else RandomForestClassifier)(
        n_estimators=9, max_depth=5, random_state=1
    ).fit(x, y)
    summed = one_thread(model)
    assert isinstance(summed, TreeSum)
    np.testing.assert_array_equal(summed.predict_proba(rows), model.predict_proba(rows))
    # rows with a NaN go to the forest itself, which answers (or refuses) as it does
    bad = rows[:5].copy()
    bad[2, 1] = np.nan
    try:
        want = model.predict_proba(bad)
    except ValueError:
        with pytest.raises(ValueError):
            summed.predict_proba(bad)
    else:
        np.testing.assert_array_equal(summed.predict_proba(bad), want)
    # not a forest of one output: no TreeSum
    assert TreeSum.of(HistGradientBoostingClassifier(max_iter=3).fit(x, y)) is None


def test_no_tree_sum_where_scikit_learn_keeps_counts(data, forest, monkeypatch):
    """Before scikit-learn 1.4 the trees kept class counts, normalised by each tree's
    ``predict_proba``: the forest is then predicted by its own copy, as before."""
    import sklearn

    from napari_polarseg.engine.classifier.refined_prediction import TreeSum

    monkeypatch.setattr(sklearn, "__version__", "1.3.2")
    assert TreeSum.of(forest) is None
    got = predict_rows(forest, data[2])
    monkeypatch.setattr(forest, "n_jobs", 1)  # the trees summed in their order
    np.testing.assert_array_equal(got, forest.predict_proba(data[2]).astype(np.float32))
