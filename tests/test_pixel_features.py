"""Pixel feature stacks: names, the Stokes-averaged DoLP, the coarse-grid smoothing, filters."""

import math

import numpy as np
import pytest
from scipy import ndimage

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features.feature_stack import upsample
from napari_polarseg.engine.features.pixel_feature_params import GROUPS
from napari_polarseg.engine.features.pixel_features import (
    PixelFeatureParams,
    block_mean,
    check_maps,
    gaussian_smooth,
    multichannel_features,
    pixel_features,
    pyramid_factor,
)
from napari_polarseg.engine.features.superpixels import (
    REGION_AREA,
    polarisation_superpixels,
)


def _image(shape=(96, 104), seed=0):
    rng = np.random.default_rng(seed)
    intensity = 0.4 + 0.1 * ndimage.gaussian_filter(rng.standard_normal(shape), 4)
    dop = np.clip(0.05 + 0.02 * ndimage.gaussian_filter(rng.standard_normal(shape), 3), 0, 1)
    phase = np.mod(ndimage.gaussian_filter(rng.standard_normal(shape), 5) * 3, np.pi)
    return intensity, dop, phase


def test_names_shapes_and_dtype():
    groups = tuple(g for g in GROUPS if g != "regions")
    params = PixelFeatureParams(scales=(1.0, 4.0, 16.0), groups=groups)
    f = pixel_features(*_image(), params)
    planes = f.planes()
    assert planes.dtype == np.float32
    assert planes.shape == (len(f.names), 96, 104)
    assert len(set(f.names)) == len(f.names)
    per_scale = len(f.names) // 3
    assert {n.split("@")[1] for n in f.names} == {"1", "4", "16"}
    assert all(sum(n.endswith(f"@{s}") for n in f.names) == per_scale for s in ("1", "4", "16"))
    assert np.isfinite(planes).all()
    # the σ >= 4 features are kept on their coarse grid: rows(), pixels() and the grid
    # read them interpolated exactly as the whole planes are
    data = np.moveaxis(planes, 0, -1)
    assert f.nbytes < planes.nbytes / 2
    np.testing.assert_allclose(f.rows(10, 12), data[10:12].reshape(-1, len(f.names)), atol=1e-6)
    where = np.zeros((96, 104), bool)
    where[5, 7] = where[50, 3] = where[95, 103] = True
    np.testing.assert_allclose(f.pixels(where), data[where], atol=1e-6)
    np.testing.assert_allclose(
        f.grid_rows(8), data[4::8, 4::8].reshape(-1, len(f.names)), atol=1e-6
    )


def test_region_features_are_superpixel_means_of_the_fine_scales():
    i, d, p = _image()
    i = i * np.where(np.arange(104) < 52, 1.0, 3.0)[None, :]  # an intensity edge
    params = PixelFeatureParams(scales=(2.0, 8.0), groups=("polarisation", "regions"))
    f = pixel_features(i, d, p, params)
    region_names = [n for n in f.names if n.startswith("region:")]
    fine = [n for n in f.names if n.endswith("@2") and not n.startswith("region:")]
    assert region_names == [f"region:{n}" for n in fine]
    regions = polarisation_superpixels(*check_maps(i, d, p), params.regions_of(i.shape))
    assert regions.max() + 1 == region_count(i.shape, params.regions_of(i.shape))
    # the regions follow the edge at column 52: nearly every pixel is in a region that
    # lies mostly on its side (a seed placed on the edge itself may spill a little)
    n = regions.max() + 1
    left_share = np.bincount(regions[:, :52].ravel(), minlength=n) / np.bincount(
        regions.ravel(), minlength=n
    )
    side = np.where(np.arange(104) < 52, 1.0, 0.0)[None, :] * np.ones((96, 1))
    majority = np.where(left_share >= 0.5, 1.0, 0.0)[regions]
    assert np.mean(majority == side) > 0.98
    k, src = f.names.index("region:dolp@2"), f.names.index("dolp@2")
    for r in np.unique(regions)[:20]:
        inside = regions == r
        np.testing.assert_allclose(f.plane(k)[inside], f.plane(src)[inside].mean(), rtol=1e-4)


def test_stokes_dolp_is_unbiased_where_mean_dop_is_not():
    """Noise on the sinusoid: the mean of per-pixel ρ is biased up, DoLP_σ is not."""
    rng = np.random.default_rng(1)
    shape = (128, 128)
    angles = np.deg2rad([0, 45, 90, 135])
    true_rho, true_phase = 0.02, 0.7
    stack = 1 + true_rho * np.cos(2 * angles[:, None, None] - 2 * true_phase)
    stack = stack + 0.03 * rng.standard_normal((4,) + shape)
    from napari_polarseg.engine import polarisation_image

    p = polarisation_image(stack, angles)
    f = pixel_features(p.intensity, p.dop, p.phase, PixelFeatureParams(scales=(8.0,)))
    dolp = f.plane("dolp@8")[32:-32, 32:-32]
    mean_dop = f.plane("dop@8")[32:-32, 32:-32]
    assert abs(float(np.median(dolp)) - true_rho) < 0.002
    assert float(np.median(mean_dop)) > true_rho + 0.003  # the bias the DoLP avoids
    coherence = f.plane("aolp_coherence@8")
    assert 0 < float(np.median(coherence)) < 1


@pytest.mark.parametrize("sigma", [4.0, 8.0, 16.0])
def test_coarse_grid_smoothing_matches_full_resolution(sigma):
    rng = np.random.default_rng(2)
    a = ndimage.gaussian_filter(rng.standard_normal((200, 230)), 2).cumsum(0).astype(np.float32)
    full = ndimage.gaussian_filter(a, sigma, truncate=3.0)
    fast = gaussian_smooth(a, sigma)
    assert pyramid_factor(sigma) > 1
    inner = (slice(60, -60), slice(60, -60))
    assert np.abs(full - fast)[inner].max() < 0.005 * np.ptp(full)


@pytest.mark.parametrize("f", [2, 3, 4, 8])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_block_mean_is_the_mean_of_each_block_with_the_edge_repeated(f, dtype):
    """The f × f block means equal numpy's mean over the blocks of the edge-padded image
    to the bit (the strided sums add in its order), on a frame whose sides are not
    multiples of f."""
    rng = np.random.default_rng(f)
    a = (rng.normal(size=(37, 50)) * 100).astype(dtype)
    padded = np.pad(a, ((0, -37 % f), (0, -50 % f)), mode="edge")
    h, w = padded.shape
    want = padded.reshape(h // f, f, w // f, f).mean(axis=(1, 3), dtype=np.float32)
    got = block_mean(a, f)
    assert got.dtype == np.float32 and got.shape == (-(-37 // f), -(-50 // f))
    assert np.array_equal(got, want)


@pytest.mark.parametrize("f", [2, 4])
def test_upsample_is_linear_interpolation_on_the_pixel_area_grid(f):
    small = np.random.default_rng(3).random((17, 23)).astype(np.float32)
    expected = ndimage.zoom(small, f, order=1, grid_mode=True, mode="nearest")
    np.testing.assert_allclose(upsample(small, f, expected.shape), expected, atol=1e-6)
    cropped = upsample(small, f, (17 * f - 1, 23 * f - 3))
    np.testing.assert_allclose(cropped, expected[: 17 * f - 1, : 23 * f - 3], atol=1e-6)
    # a band of rows, from the coarse rows it needs, equals those rows of the whole map
    for start, stop in ((0, 1), (3, 9), (5 * f + 1, 5 * f + 2), (17 * f - 4, 17 * f)):
        band = upsample(small, f, expected.shape, (start, stop))
        np.testing.assert_allclose(band, expected[start:stop], atol=1e-6)


@pytest.mark.parametrize("sigma", [1.0, 4.0, 16.0])
def test_filters_are_in_per_pixel_units_at_every_scale(sigma):
    """A log-intensity ramp of slope 0.01/px and a paraboloid of known curvature."""
    rows, cols = np.mgrid[0:160, 0:160].astype(float)
    ramp = np.exp(0.01 * cols)  # log Î = 0.01 · col
    shape = ramp.shape
    params = PixelFeatureParams(scales=(sigma,), groups=("filters",))
    f = pixel_features(ramp, np.full(shape, 0.05), np.zeros(shape), params)
    inner = (slice(60, 100), slice(60, 100))
    grad = f.plane(f"log_intensity_gradient@{sigma:g}")[inner]
    np.testing.assert_allclose(grad, 0.01, rtol=0.02)
    dop = 0.05 + 1e-4 * ((rows - 80) ** 2 + 3 * (cols - 80) ** 2)
    f = pixel_features(np.ones(shape), dop, np.zeros(shape), params)
    lap = f.plane(f"dop_laplacian@{sigma:g}")[inner]
    hmax = f.plane(f"dop_hessian_max@{sigma:g}")[inner]
    hmin = f.plane(f"dop_hessian_min@{sigma:g}")[inner]
    np.testing.assert_allclose(lap, 8e-4, rtol=0.03)
    np.testing.assert_allclose(hmax, 6e-4, rtol=0.03)
    np.testing.assert_allclose(hmin, 2e-4, rtol=0.05)


def test_invariant_features_do_not_change_with_the_shading_level():
    i, d, p = _image()
    params = PixelFeatureParams(scales=(2.0, 8.0), groups=("intensity", "invariant"))
    a = pixel_features(i, d, p, params)
    b = pixel_features(3.0 * i, d, p, params)
    for k, name in enumerate(a.names):
        if name.startswith("log_intensity@"):
            np.testing.assert_allclose(b.plane(k) - a.plane(k), np.log(3.0), atol=1e-5)
        else:
            # float32 local covariances: differences of means, ~1 % of a small value
            np.testing.assert_allclose(b.plane(k), a.plane(k), rtol=1e-2, atol=2e-4)


def test_multichannel_names_carry_the_channel():
    i, d, p = _image()
    params = PixelFeatureParams(scales=(2.0,), groups=("polarisation",))
    f = multichannel_features([(i, d, p), (2 * i, d / 2, p)], params, ["red", "green"])
    assert f.names[0].startswith("red:") and f.names[-1].startswith("green:")
    assert f.n_features == 2 * len(pixel_features(i, d, p, params).names)
    assert multichannel_features([(i, d, p)], params).names == pixel_features(i, d, p, params).names


def test_bad_parameters_and_maps_raise():
    with pytest.raises(PolarsegError, match="scales"):
        PixelFeatureParams(scales=(0.0,))
    with pytest.raises(PolarsegError, match="groups"):
        PixelFeatureParams(groups=("colour",))
    with pytest.raises(PolarsegError, match="one shape"):
        pixel_features(np.ones((4, 4)), np.ones((4, 5)), np.ones((4, 4)))
    with pytest.raises(PolarsegError, match="unknown"):
        PixelFeatureParams.from_dict({"scales": [1], "colour": 1})
    p = PixelFeatureParams(scales=(1.0, 3.0), groups=("intensity",))
    assert PixelFeatureParams.from_dict(p.to_dict()) == p


def region_count(shape: tuple[int, int], region_area: int = REGION_AREA) -> int:
    """Number of seeds :func:`superpixels` places on an image of ``shape``."""
    return max(1, int(round(math.prod(shape) / region_area)))
