"""Parameter sweep (engine/analysis/sweep.py): scores, best cell, cache reuse, cancel, tables."""

from __future__ import annotations

import csv
import io as io_module
import json
import math
from typing import Any

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score, silhouette_score

from napari_polarseg import io as pio
from napari_polarseg.engine import Cancelled, PolarsegError, SegmentParams, diffuse_dop
from napari_polarseg.engine.analysis.sweep import (
    block_silhouette,
    combined_score,
    iter_sweep,
    neighbour_stability,
    sweep,
)
from napari_polarseg.engine.analysis.sweep_result import (
    COLUMNS,
    SCORE_COLUMNS,
    SCORES,
    SweepCell,
    SweepResult,
)
from napari_polarseg.engine.features.pca import whiten
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.engine.synthetic.scenes import make_scene

ANGLES = np.deg2rad(np.arange(0.0, 180.0, 30.0))
BASE = SegmentParams(method="thesis", n_segments=2)
WINDOWS = (7, 10, 64)  # 10 matches the domes; 64 is wider than the image
DEGREES = (2, 4)


def domes_scene(h=40, w=60, seed=0):
    """Two materials (left / right half) made of domes of period 10 pixels.

    With w = 10 every block holds one whole dome, so the blocks of a material are alike
    and the two materials separate perfectly; w = 7 mixes parts of domes.
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    cy, cx = (yy % 10) - 4.5, (xx % 10) - 4.5
    zenith = np.clip(np.hypot(cx, cy) / 6.0, 0, 1) * 1.3
    azimuth = np.arctan2(cy, cx)
    truth = (xx >= w // 2).astype(np.int64)
    i0 = np.where(
        truth == 0,
        100 + 80 * np.cos(zenith),
        60 + 120 * np.sin(zenith) ** 2 * (1 + 0.5 * np.cos(azimuth)),
    )
    rho = diffuse_dop(zenith, 1.45)
    phi = np.mod(azimuth, np.pi)
    a = ANGLES[:, None, None]
    stack = i0 * (1 + rho * np.cos(2 * a - 2 * phi)) + rng.normal(0, 0.5, (len(a), h, w))
    return stack, truth


@pytest.fixture(scope="module")
def scene():
    return domes_scene()


@pytest.fixture(scope="module")
def result(scene):
    stack, truth = scene
    return sweep(
        stack, ANGLES, BASE, WINDOWS, DEGREES, refractive_indices=[1.45, 1.6], ground_truth=truth
    )


def test_grid_cells_and_failed_window(result):
    assert result.shape == (2, 3, 2)
    assert len(result.cells) == 12
    assert result.windows == WINDOWS and result.degrees == DEGREES
    # run order: n outermost, then w, then L
    order = [(c.refractive_index, c.window, c.degree) for c in result.cells]
    assert order == sorted(order)
    for c in result.cells:
        if c.window == 64:
            assert not c.ok and "larger than the image" in c.error
            assert math.isnan(c.score) and c.labels is None
        else:
            assert c.ok and c.error is None
            assert c.n_segments == 2 and len(c.ncut_values) == 1
            assert c.mean_ncut == pytest.approx(c.ncut_values[0])
            assert -1 <= c.silhouette <= 1 and 0 <= c.score <= 1
            assert c.labels.shape == (40, 60) and c.seconds > 0
    grid = result.grid("score")
    assert grid.shape == (2, 3, 2)
    assert np.isnan(grid[:, 2]).all() and np.isfinite(grid[:, :2]).all()
    assert result.total_seconds >= sum(c.seconds for c in result.cells) * 0.99


def test_the_right_window_is_best_by_every_criterion(result):
    for c in result.cells:
        if c.window == 10:
            assert c.ari == pytest.approx(1.0)
            assert c.silhouette > 0.9
        elif c.window == 7:
            assert c.ari < 0.6 and c.silhouette < 0.6
    for by in ("stability", "combined", "silhouette", "ari"):
        assert result.best(by).window == 10, by
    # the mean Ncut is no reliable criterion across settings: each cell cuts another graph
    # (other blocks, other PCA components); here w = 7, L = 4 has the lowest
    assert result.best("ncut").window in (7, 10)
    best = result.best()  # default criterion: stability
    assert best == BASE.replace(
        window=10, degree=best.degree, refractive_index=best.refractive_index
    )
    assert result.best("ari").refractive_index in (1.45, 1.6)


def test_best_is_the_argmax_of_the_grid(result):
    for by, (column, larger) in SCORE_COLUMNS.items():
        values = result.grid(by)
        assert np.array_equal(values, result.grid(column), equal_nan=True)
        pick = np.nanargmax(values) if larger else np.nanargmin(values)
        idx = np.unravel_index(pick, values.shape)
        cell = result.best_cell(by)
        assert cell.index == idx
        assert result.cells[int(np.ravel_multi_index(idx, result.shape))] is cell
        assert result.best(by) == cell.params(BASE)


def test_the_pipeline_cache_is_reused(result):
    calls = result.stage_calls
    assert calls["polarisation"] == 1
    assert calls["normals"] == 2  # once per refractive index
    ran = sum(c.ok for c in result.cells)
    for stage in ("harmonics", "pca", "affinity", "cut", "labels"):
        assert calls[stage] == ran == 8
    assert "reconstruction" not in calls
    first, second, later_n = result.cells[0], result.cells[1], result.cells[6]
    assert first.recomputed[:2] == ["polarisation", "normals"]
    assert second.recomputed[0] == "harmonics"  # polarisation and normals cached
    assert later_n.recomputed[0] == "normals"  # new n: polarisation still cached


def test_stability_on_a_hand_made_grid():
    lr = np.repeat([[0, 0, 1, 1]], 4, axis=0)  # left | right
    tb = lr.T  # top / bottom
    noisy = lr.copy()
    noisy[0, 0] = 1
    # grid (1 n, 2 w, 2 L): (0,0,0) lr, (0,0,1) lr renumbered, (0,1,0) tb, (0,1,1) failed
    labels = {(0, 0, 0): lr, (0, 0, 1): 1 - lr, (0, 1, 0): tb, (0, 1, 1): None}
    out = neighbour_stability(labels, (1, 2, 2))
    a_tb = adjusted_rand_score(lr.ravel(), tb.ravel())
    assert out[0, 0, 0] == pytest.approx((1.0 + a_tb) / 2)
    assert out[0, 0, 1] == pytest.approx(1.0)  # its w neighbour failed
    assert out[0, 1, 0] == pytest.approx(a_tb)  # its L neighbour failed
    assert np.isnan(out[0, 1, 1])
    # a 1 x 3 row: the middle cell averages both sides; no diagonal neighbours
    labels = {(0, 0, 0): lr, (0, 0, 1): noisy, (0, 0, 2): tb}
    out = neighbour_stability(labels, (1, 1, 3))
    a_noisy = adjusted_rand_score(lr.ravel(), noisy.ravel())
    a_nt = adjusted_rand_score(noisy.ravel(), tb.ravel())
    np.testing.assert_allclose(out[0, 0], [a_noisy, (a_noisy + a_nt) / 2, a_nt])
    # different n are never neighbours
    out = neighbour_stability({(0, 0, 0): lr, (1, 0, 0): lr}, (2, 1, 1))
    assert np.isnan(out).all()


def test_stability_of_a_sweep_matches_its_labels(result):
    c = result.cell(1.45, 7, 2)
    right, below = result.cell(1.45, 7, 4), result.cell(1.45, 10, 2)
    expected = np.mean(
        [
            adjusted_rand_score(c.labels.ravel(), right.labels.ravel()),
            adjusted_rand_score(c.labels.ravel(), below.labels.ravel()),
        ]
    )
    assert c.stability == pytest.approx(expected)
    assert c.score == pytest.approx(combined_score(c.silhouette, c.mean_ncut, c.stability))


def test_combined_score_and_silhouette_helpers():
    assert combined_score(1.0, 0.0, 1.0) == 1.0
    assert combined_score(-1.0, 2.0, -0.5) == 0.0
    assert combined_score(0.0, math.nan, math.nan) == 0.5
    assert math.isnan(combined_score(math.nan, math.nan, math.nan))
    rng = np.random.default_rng(1)
    # in the whitened (Mahalanobis) space, as the affinity sees the features
    x = np.concatenate([rng.normal(0, 1, (20, 3)), rng.normal(3, 1, (20, 3))])
    y = np.repeat([0, 1], 20)
    assert block_silhouette(x, y) == pytest.approx(silhouette_score(whiten(x), y))
    x = np.concatenate([rng.normal(0, 1, 1500), rng.normal(8, 1, 1500)])[:, None]
    y = np.repeat([0, 1], 1500)
    s = block_silhouette(x, y)  # 3000 blocks: a fixed sample of 2000
    assert s > 0.7 and s == block_silhouette(x, y)
    assert math.isnan(block_silhouette(x, np.zeros(3000, int)))
    with pytest.raises(PolarsegError):
        block_silhouette(x, y[:10])


def test_progress_and_cancel(scene):
    stack, _ = scene
    seen = []
    res = sweep(stack, ANGLES, BASE, [10], [2, 4], progress=lambda d, t: seen.append((d, t)))
    assert seen == [(1, 2), (2, 2)]
    assert math.isnan(res.cells[0].ari) and not res.has_ground_truth
    calls = []

    def cancel():
        calls.append(1)
        return len(seen) >= 3

    with pytest.raises(Cancelled):
        sweep(
            stack,
            ANGLES,
            BASE,
            [7, 10],
            [2, 4],
            progress=lambda d, t: seen.append(d),
            cancel=cancel,
        )
    assert len(seen) == 3  # stopped after the first cell of the second sweep
    # the generator form stops when closed
    gen = iter_sweep(stack, ANGLES, BASE, [7, 10], [2, 4])
    assert next(gen)[:2] == (1, 4)
    gen.close()


def test_csv_and_json_round_trip(result, tmp_path):
    rows = result.to_rows()
    assert list(rows[0]) == list(COLUMNS)
    back = read_csv_rows(result.to_csv())
    assert len(back) == len(rows)
    for a, b in zip(rows, back, strict=True):
        for key in COLUMNS:
            if isinstance(a[key], float):
                assert a[key] == pytest.approx(b[key], nan_ok=True), key
            else:
                assert a[key] == b[key], key
    pio.write_json(tmp_path / "sweep.json", result.to_dict())  # NaN -> null
    data = json.loads((tmp_path / "sweep.json").read_text())
    assert data["best"]["params"] == result.best().to_dict()
    assert data["n_failed"] == 4
    again = SweepResult.from_dict(data)
    assert again.best() == result.best()
    assert again.best("ari") == result.best("ari")
    np.testing.assert_allclose(again.grid("score"), result.grid("score"), equal_nan=True)
    assert again.stage_calls == result.stage_calls
    with pytest.raises(PolarsegError, match="no labels"):
        again.labels(again.cells[0])
    with pytest.raises(PolarsegError):
        SweepResult.from_dict({"cells": []})


def test_nonsense_inputs_raise(scene):
    stack, truth = scene
    bad = [
        ({"windows": []}, "at least one window"),
        ({"windows": [0, 8]}, "window"),
        ({"windows": [8.5]}, "whole numbers"),
        ({"degrees": [99]}, "degree"),
        ({"degrees": ["4"]}, "numbers"),
        ({"refractive_indices": [0.9]}, "refractive index"),
        ({"score": "best"}, "score must be one of"),
        ({"score": "ari"}, "needs a ground truth"),
        ({"ground_truth": truth[:10]}, "ground truth is 10 x 60"),
        ({"base": BASE.replace(n_segments=1)}, "at least 2"),
    ]
    for change, message in bad:
        kwargs = {"base": BASE, "windows": [10], "degrees": [2], **change}
        with pytest.raises(PolarsegError, match=message):
            sweep(stack, ANGLES, **kwargs)
    with pytest.raises(PolarsegError):
        sweep(stack[:2], ANGLES[:2], BASE, [10], [2])  # fewer than 3 angles
    # every cell failing is not an error of the sweep itself, but has no best cell
    res = sweep(stack, ANGLES, BASE, [64, 100], [2])
    assert not any(c.ok for c in res.cells)
    with pytest.raises(PolarsegError, match="no cell"):
        res.best()
    with pytest.raises(PolarsegError, match="metric"):
        res.grid("nonsense")
    with pytest.raises(PolarsegError, match="ground truth"):
        res.best("ari")


def test_axes_are_sorted_and_deduplicated(scene):
    stack, _ = scene
    res = sweep(stack, ANGLES, BASE, [10, 7, 10], [4, 2], keep_labels=False)
    assert res.windows == (7, 10) and res.degrees == (2, 4)
    assert res.refractive_indices == (BASE.refractive_index,)
    assert all(c.labels is None for c in res.cells)
    assert np.isfinite(res.grid("stability")).all()  # computed before the labels went


def test_synthetic_leaves_small_grid():
    scene = make_scene("leaves", shape=(64, 72))
    res = sweep(
        scene.stack, scene.angles, RECOMMENDED, [6, 8, 30], [4, 8], ground_truth=scene.labels
    )
    assert [c.ok for c in res.cells] == [True, True, True, True, True, True]
    # w = 30 leaves 2 x 2 blocks, below the minimum segment size: one segment
    assert all(c.n_segments == 1 for c in res.cells if c.window == 30)
    for by in SCORES:
        assert res.best(by).window in (6, 8)
    assert max(c.ari for c in res.cells if c.window == 30) < min(
        c.ari for c in res.cells if c.window != 30
    )


def read_csv_rows(text: str) -> list[dict[str, Any]]:
    """Rows of a :meth:`SweepResult.to_csv` table with their types (empty → NaN/None)."""
    rows = []
    for raw in csv.DictReader(io_module.StringIO(text)):
        cell = SweepCell.from_dict(raw)
        rows.append(cell.row())
    return rows
