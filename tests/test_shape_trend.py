"""The close-up material cue (engine/unsupervised/shape_trend.py) and its use by the
unsupervised default: ρ e^{2iφ} ≈ c g² on one smooth surface (eq. 1 of the module)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.unsupervised.params import UnsupervisedParams
from napari_polarseg.engine.unsupervised.segmenter import segment_unsupervised
from napari_polarseg.engine.unsupervised.shape_trend import (
    polarisation_over_trend,
    region_polarisation,
    surface_trend_share,
)

SHAPE = (120, 130)


def close_up(ratio: float = 0.6, noise: float = 0.0, seed: int = 0):
    """(Î, ρ, φ, truth) of an ellipsoidal surface filling the frame, c = 0.05 on the
    main material and ``ratio`` · c on a disc off the centre (a bruise: same shape, same
    shading, another n or depolarisation); Gaussian noise on the Stokes components."""
    rng = np.random.default_rng(seed)
    h, w = SHAPE
    rows, cols = np.mgrid[0:h, 0:w].astype(float)
    p = (cols - 0.52 * w) / 160.0  # surface gradient g = p + i q, linear in position
    q = (rows - 0.47 * h) / 150.0
    truth = (np.hypot(rows - 0.3 * h, cols - 0.65 * w) < 0.22 * h).astype(int)
    c = np.where(truth == 1, ratio * 0.05, 0.05)
    shading = 0.6 - 0.1 * p - 0.05 * q  # a light off the view axis
    z = c * (p + 1j * q) ** 2  # eq. 1
    s0 = 2 * shading
    s1 = s0 * z.real + noise * rng.standard_normal(SHAPE)
    s2 = s0 * z.imag + noise * rng.standard_normal(SHAPE)
    dop = np.hypot(s1, s2) / s0
    phase = np.mod(0.5 * np.arctan2(s2, s1), np.pi)
    return shading, dop, phase, truth


def grid_regions(shape, side=6):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    per_row = -(-shape[1] // side)
    return (rows // side) * per_row + cols // side


def test_region_polarisation_is_the_stokes_mean():
    i, d, ph, _ = close_up()
    regions = grid_regions(SHAPE)
    z, count, centroid = region_polarisation(i, d, ph, regions)
    r0 = regions == 0
    s0, s1, s2 = (2 * i)[r0], (2 * i * d * np.cos(2 * ph))[r0], (2 * i * d * np.sin(2 * ph))[r0]
    assert z[0] == pytest.approx((s1.sum() + 1j * s2.sum()) / s0.sum())
    assert count[0] == 36
    np.testing.assert_allclose(centroid[0], [2.5, 2.5])


def test_one_smooth_surface_is_the_square_of_a_linear_field():
    regions = grid_regions(SHAPE)
    i, d, ph, _ = close_up(ratio=1.0)
    z, count, centroid = region_polarisation(i, d, ph, regions)
    assert surface_trend_share(z, count, centroid, SHAPE) == pytest.approx(1.0, abs=1e-6)


def test_several_surfaces_and_bands_are_not_one_surface():
    """Four domes side by side, and concentric AoLP over bands of ρ, are not the
    square of one linear field."""
    regions = grid_regions(SHAPE)
    rows, cols = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]].astype(float)
    i = np.full(SHAPE, 0.5)
    g = ((cols % 65) - 32.5) / 40.0 + 1j * ((rows % 60) - 30.0) / 40.0  # four domes
    z = 0.05 * g**2
    z, count, centroid = region_polarisation(i, np.abs(z), np.angle(z) / 2 % np.pi, regions)
    assert surface_trend_share(z, count, centroid, SHAPE) < 0.3
    bands = np.array([0.04, 0.12, 0.25])[np.minimum(cols * 3 // SHAPE[1], 2).astype(int)]
    spiral = np.arctan2(rows - SHAPE[0] / 2, cols - SHAPE[1] / 2) % np.pi
    z, count, centroid = region_polarisation(i, bands, spiral, regions)
    assert surface_trend_share(z, count, centroid, SHAPE) < 0.8


def test_ratio_to_the_trend_is_the_ratio_of_the_materials():
    """Away from the patch border the ratio is c'/c on the patch and 1 elsewhere."""
    regions = grid_regions(SHAPE)
    i, d, ph, truth = close_up(ratio=0.6)
    z, count, centroid = region_polarisation(i, d, ph, regions)
    ratio = polarisation_over_trend(z, count, centroid, SHAPE, reach=0.02, iterations=3)
    region_truth = np.bincount(regions.ravel(), weights=truth.ravel()) / count
    assert np.median(ratio[region_truth == 0]) == pytest.approx(1.0, abs=0.05)
    assert np.median(ratio[region_truth == 1]) == pytest.approx(0.6, abs=0.05)


def test_default_finds_the_patch_on_a_close_up():
    i, d, ph, truth = close_up(ratio=0.6, noise=0.002)
    r = segment_unsupervised(i, d, ph, 2)
    assert r.close_up and r.surface_share > 0.8
    assert r.feature_names == ("dop_over_shape_trend",)
    assert adjusted_rand_score(truth.ravel(), r.labels.ravel()) > 0.8
    off = segment_unsupervised(i, d, ph, 2, UnsupervisedParams(close_up_share=1.0))
    assert not off.close_up
    assert adjusted_rand_score(truth.ravel(), off.labels.ravel()) < 0.5


@pytest.mark.parametrize(
    "change", [{"close_up_share": 1.5}, {"trend_reach": 0.0}, {"trend_degree": 0}]
)
def test_bad_trend_parameters_refused(change):
    with pytest.raises(PolarsegError):
        UnsupervisedParams(**change)


def test_cli_says_when_it_took_the_frame_for_a_close_up(tmp_path, capsys):
    """The bundled fruit close-up (default preset) prints the close-up line and records
    it in summary.json; the leaves scene, many surfaces, does neither."""
    from napari_polarseg.cli import main

    for scene, close in (("fruit", True), ("leaves", False)):
        out = tmp_path / scene
        assert main(["demo", "--scene", scene, "--out", str(out), "--unsupervised"]) == 0
        stdout = capsys.readouterr().out
        record = json.loads((out / "summary.json").read_text())["superpixels"]
        assert record["close_up"] is close
        assert (record["surface_share"] > 0.8) is close
        assert ("one smooth surface fills the frame" in stdout) is close
