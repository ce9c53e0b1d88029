"""Block polarisation statistics (engine/features/polstats.py) against hand-computed blocks."""

import numpy as np
import pytest

from napari_polarseg.engine import Pipeline, SegmentParams
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features import polstats
from napari_polarseg.engine.synthetic.scenes import make_scene

IDX = {name: i for i, name in enumerate(polstats.STAT_NAMES)}


def stats(i, r, p, t, w, valid=None):
    return polstats.block_polarisation_statistics(i, r, p, t, w, valid)


def test_uniform_block_by_hand():
    i = np.full((4, 4), 0.5)
    r = np.full((4, 4), 0.04)
    p = np.full((4, 4), 0.3)
    t = np.full((4, 4), 0.6)
    s = stats(i, r, p, t, 4)[0, 0]
    assert s[IDX["log_stokes_dop"]] == pytest.approx(np.log(0.04))
    assert s[IDX["log_median_dop"]] == pytest.approx(np.log(0.04))
    assert s[IDX["dop_spread"]] == pytest.approx(0.0)
    assert s[IDX["phase_coherence"]] == pytest.approx(1.0)
    assert s[IDX["zenith_mean"]] == pytest.approx(0.6)
    assert s[IDX["zenith_std"]] == pytest.approx(0.0)
    assert s[IDX["log_intensity"]] == pytest.approx(np.log(0.5))
    assert s[IDX["intensity_cv"]] == pytest.approx(0.0)
    assert s[IDX["corr_intensity_dop"]] == 0.0  # no variation: defined as 0


def test_crossed_phases_cancel_in_the_stokes_average():
    # half the pixels polarised along 0, half along 90 degrees: Stokes vectors cancel
    p = np.zeros((2, 2))
    p[:, 1] = np.pi / 2
    s = stats(np.ones((2, 2)), np.full((2, 2), 0.1), p, np.zeros((2, 2)), 2)[0, 0]
    assert s[IDX["phase_coherence"]] == pytest.approx(0.0, abs=1e-12)
    assert s[IDX["log_stokes_dop"]] == pytest.approx(np.log(1e-5))  # floored
    assert s[IDX["log_median_dop"]] == pytest.approx(np.log(0.1))


def test_stokes_average_is_intensity_weighted_and_correlation_signed():
    i = np.array([[1.0, 3.0]])
    r = np.array([[0.1, 0.3]])
    t = np.zeros((1, 2))
    s = stats(i, r, np.zeros((1, 2)), t, 1)  # w = 1: one pixel per block
    assert s.shape == (1, 2, len(polstats.STAT_NAMES))
    s = polstats.block_polarisation_statistics(
        np.tile(i, (2, 1)), np.tile(r, (2, 1)), np.zeros((2, 2)), np.zeros((2, 2)), 2
    )[0, 0]
    # (1*0.1 + 3*0.3 + 1*0.1 + 3*0.3) / (1 + 3 + 1 + 3) = 0.25
    assert s[IDX["log_stokes_dop"]] == pytest.approx(np.log(0.25))
    assert s[IDX["corr_intensity_dop"]] == pytest.approx(1.0)
    assert s[IDX["intensity_cv"]] == pytest.approx(1.0 / 2.0)  # std 1, mean 2
    assert s[IDX["dop_spread"]] == pytest.approx((0.3 - 0.1) / 0.2)  # IQR / median


def test_masked_pixels_are_left_out_and_empty_blocks_take_the_mean():
    i = np.ones((2, 4))
    r = np.full((2, 4), 0.02)
    r[0, 0] = 0.9  # an outlier, masked out
    valid = np.ones((2, 4), bool)
    valid[0, 0] = False
    valid[:, 2:] = False  # second block entirely masked
    s = stats(i, r, np.zeros((2, 4)), np.zeros((2, 4)), 2, valid)
    assert s[0, 0, IDX["log_stokes_dop"]] == pytest.approx(np.log(0.02))
    np.testing.assert_allclose(s[0, 1], s[0, 0])
    with pytest.raises(PolarsegError, match="no block"):
        stats(i, r, np.zeros((2, 4)), np.zeros((2, 4)), 2, np.zeros((2, 4), bool))


def test_remainder_strips_are_dropped_and_shapes_checked():
    s = stats(np.ones((7, 9)), np.full((7, 9), 0.1), np.zeros((7, 9)), np.zeros((7, 9)), 3)
    assert s.shape == (2, 3, len(polstats.STAT_NAMES))
    with pytest.raises(PolarsegError, match="same shape"):
        stats(np.ones((4, 4)), np.ones((4, 5)), np.ones((4, 4)), np.ones((4, 4)), 2)


def test_standardise():
    x = np.array([[1.0, 5.0, 2.0], [3.0, 5.0, 4.0], [5.0, 5.0, 9.0]])
    z = polstats.standardise(x)
    np.testing.assert_allclose(z.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(z.std(axis=0), [1.0, 0.0, 1.0])


def test_materials_differ_in_stokes_dop_on_a_synthetic_scene():
    # plastic leaves (n 1.54, d 0.15) polarise more than natural ones (n 1.45, d 0.30)
    sc = make_scene("leaves", seed=1)
    pipe = Pipeline(sc.stack, sc.angles, SegmentParams(window=8, features="polstats"))
    pol, nrm = pipe.get("polarisation"), pipe.get("normals")
    s = stats(pol.intensity, pol.dop, pol.phase, nrm.zenith, 8)
    truth = sc.labels[: s.shape[0] * 8, : s.shape[1] * 8]
    block_truth = truth.reshape(s.shape[0], 8, s.shape[1], 8).transpose(0, 2, 1, 3)
    pure = block_truth.reshape(s.shape[0], s.shape[1], -1)
    same = (pure == pure[..., :1]).all(-1)
    lab = pure[..., 0]
    dop = s[..., IDX["log_stokes_dop"]]
    natural = np.median(dop[same & (lab == 1)])
    plastic = np.median(dop[same & (lab == 2)])
    assert plastic > natural + np.log(1.2)
    res = pipe.run(reconstruction=False)
    assert res.labels.shape == sc.labels.shape and res.labels.max() == 2
