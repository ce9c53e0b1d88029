"""The pixel features' Gaussian filter and the edge maps' gradient magnitude against
SciPy's and against their definitions."""

import numpy as np
import pytest
from scipy import ndimage

from napari_polarseg.engine.features.gaussian import (
    gaussian_filter,
    gaussian_kernel,
    gradient_magnitude,
)


@pytest.mark.parametrize("sigma", [0.5, 1.0, 1.94, 2.0, 3.97, 8.0])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_equals_scipy_gaussian_filter(sigma, dtype):
    """SciPy's kernel (truncate 3) and border (reflect), to float32 rounding."""
    rng = np.random.default_rng(3)
    for shape in [(1, 1), (1, 7), (6, 1), (3, 2), (13, 9), (97, 131)]:
        a = (rng.random(shape) * 5 - 1).astype(dtype)
        got = gaussian_filter(a, sigma)
        expected = ndimage.gaussian_filter(a, sigma, truncate=3.0)
        assert got.dtype == expected.dtype and got.shape == a.shape
        tol = 1e-6 if dtype == np.float32 else 1e-12
        np.testing.assert_allclose(got, expected, rtol=0, atol=tol * 5)


def test_impulse_gives_the_kernel_and_constants_stay():
    """G_σ of a unit impulse far from the border is the outer product of the kernel;
    a constant map stays constant (the kernel sums to 1, the border repeats it)."""
    kernel = gaussian_kernel(2.0)
    assert kernel.size == 2 * 6 + 1 and abs(kernel.sum() - 1) < 1e-12
    np.testing.assert_allclose(kernel, kernel[::-1])
    x = np.arange(-6, 7)
    np.testing.assert_allclose(kernel / kernel[6], np.exp(-(x**2) / 8.0), rtol=1e-12)
    impulse = np.zeros((41, 41))
    impulse[20, 20] = 1.0
    out = gaussian_filter(impulse, 2.0)
    np.testing.assert_allclose(out[14:27, 14:27], np.outer(kernel, kernel), atol=1e-15)
    assert abs(out.sum() - 1) < 1e-12
    flat = np.full((30, 17), 0.3, dtype=np.float32)
    np.testing.assert_allclose(gaussian_filter(flat, 3.0), flat, rtol=1e-6)


def test_views_and_wrong_shapes():
    rng = np.random.default_rng(4)
    a = rng.random((60, 80)).astype(np.float32)
    view = a[5:50:2, 3:70]  # not contiguous
    np.testing.assert_allclose(
        gaussian_filter(view, 1.0), ndimage.gaussian_filter(view, 1.0, truncate=3.0), atol=1e-6
    )
    assert gaussian_filter(np.zeros((0, 5), np.float32), 1.0).shape == (0, 5)
    with pytest.raises(ValueError, match="2-D"):
        gaussian_filter(np.zeros((2, 3, 4)), 1.0)


@pytest.mark.parametrize("sigma", [0.7, 1.5, 3.0])
def test_gradient_magnitude_equals_scipy(sigma):
    """SciPy's gaussian_gradient_magnitude (truncate 4, reflect) to float64 rounding on
    float64 maps, its dtype kept for float32 ones; a tiny map (kernel wider than it)
    too."""
    rng = np.random.default_rng(5)
    for shape in [(1, 1), (3, 2), (7, 5), (13, 40), (97, 131)]:
        a = ndimage.gaussian_filter(rng.random(shape), 1.0) * 4 - 1
        expected = ndimage.gaussian_gradient_magnitude(a, sigma)
        np.testing.assert_allclose(gradient_magnitude(a, sigma), expected, rtol=0, atol=1e-14)
        got32 = gradient_magnitude(a.astype(np.float32), sigma)
        assert got32.dtype == np.float32
        expected32 = ndimage.gaussian_gradient_magnitude(a.astype(np.float32), sigma)
        np.testing.assert_allclose(got32, expected32, rtol=0, atol=1e-6)


def test_gradient_magnitude_of_a_ramp_is_its_slope():
    """|∇(G * (a x + b y))| = √(a² + b²) away from the border, to the truncated
    kernel's first moment Σ x² G(x) / σ² (1 − 3.5e-4 at 4 σ); 0 on a constant map."""
    y, x = np.mgrid[0:60, 0:70].astype(np.float64)
    ramp = 0.3 * x - 0.4 * y
    got = gradient_magnitude(ramp, 2.0)
    np.testing.assert_allclose(got[10:-10, 10:-10], 0.5, rtol=5e-4)
    assert np.abs(gradient_magnitude(np.full((20, 20), 2.0), 1.5)).max() < 1e-12
