"""Real spherical harmonics, block coefficients (eq. 4.21 and ridge), reconstruction."""

import numpy as np
import pytest
import scipy.special as sp

from napari_polarseg.engine import (
    PolarsegError,
    block_coefficients,
    coefficient_index,
    degree_order,
    n_coefficients,
    pixel_block_index,
    real_sph_harm,
    reconstruct_intensity,
    upsample_block_labels,
)


def sphere_quadrature(L):
    """Gauss-Legendre in cos(theta) x uniform azimuth: exact for degree <= 2L products."""
    x, wx = np.polynomial.legendre.leggauss(L + 2)
    theta = np.arccos(x)
    phi = np.linspace(0, 2 * np.pi, 2 * L + 3, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    w = wx[:, None] * (2 * np.pi / phi.size) * np.ones_like(p)
    return t.ravel(), p.ravel(), w.ravel()


@pytest.mark.parametrize("L", [0, 1, 4, 12, 30])
def test_orthonormal_under_quadrature(L):
    t, p, w = sphere_quadrature(L)
    Y = real_sph_harm(L, t, p)
    gram = (Y * w[:, None]).T @ Y
    assert gram.shape == (n_coefficients(L),) * 2
    assert np.max(np.abs(gram - np.eye(gram.shape[0]))) < 1e-6


def test_order_and_relation_to_complex_harmonics():
    # thesis vector order a00, a1-1, a10, a11, a2-2, ...
    ls, ms = degree_order(3)
    assert list(zip(ls[:6], ms[:6], strict=True)) == [
        (0, 0),
        (1, -1),
        (1, 0),
        (1, 1),
        (2, -2),
        (2, -1),
    ]
    assert coefficient_index(2, -2) == 4 and coefficient_index(3, 3) == 15
    theta, phi = 0.7, 1.3
    Y = real_sph_harm(4, np.array(theta), np.array(phi))
    for l, m in zip(ls, ms, strict=True):  # noqa: E741
        c = sp.sph_harm_y(l, abs(m), theta, phi)
        if m > 0:
            want = np.sqrt(2) * (-1.0) ** m * c.real
        elif m < 0:
            want = np.sqrt(2) * (-1.0) ** m * c.imag
        else:
            want = c.real
        assert Y[coefficient_index(l, m)] == pytest.approx(want, abs=1e-12)


def test_known_low_degree_closed_forms():
    theta, phi = np.array([0.2, 1.0]), np.array([0.5, 2.0])
    Y = real_sph_harm(1, theta, phi)
    c = np.sqrt(3 / (4 * np.pi))
    np.testing.assert_allclose(Y[:, 0], 0.5 / np.sqrt(np.pi))
    np.testing.assert_allclose(Y[:, 2], c * np.cos(theta))  # z
    np.testing.assert_allclose(Y[:, 3], c * np.sin(theta) * np.cos(phi))  # x
    np.testing.assert_allclose(Y[:, 1], c * np.sin(theta) * np.sin(phi))  # y


def random_normals(shape, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, np.pi / 2, shape), rng.uniform(0, np.pi, shape)


def test_thesis_estimator_is_block_mean_of_intensity_times_harmonic():
    theta, phi = random_normals((20, 30))
    intensity = np.random.default_rng(1).uniform(0.5, 1.0, (20, 30))
    coef = block_coefficients(intensity, theta, phi, window=10, degree=3)
    assert coef.shape == (2, 3, 16)
    block = (slice(10, 20), slice(0, 10))
    Y = real_sph_harm(3, theta[block], phi[block])
    want = (intensity[block][..., None] * Y).mean(axis=(0, 1))
    np.testing.assert_allclose(coef[1, 0], want, rtol=1e-12, atol=1e-14)


def test_ridge_fit_recovers_exact_expansion():
    L = 3
    theta, phi = random_normals((24, 24), seed=2)
    truth = np.random.default_rng(3).normal(size=n_coefficients(L))
    intensity = real_sph_harm(L, theta, phi) @ truth
    coef = block_coefficients(intensity, theta, phi, 12, L, method="ridge", ridge=1e-10)
    np.testing.assert_allclose(coef.reshape(-1, truth.size), np.tile(truth, (4, 1)), atol=1e-5)
    rec = reconstruct_intensity(intensity, theta, phi, 12, L, ridge=1e-10)
    np.testing.assert_allclose(rec, intensity, atol=1e-6)


def test_reconstruction_covers_remainder_and_error_drops_with_degree():
    theta, phi = random_normals((37, 43), seed=4)
    intensity = 1 + 0.3 * np.cos(theta) + 0.1 * np.sin(theta) ** 2 * np.cos(2 * phi)
    errs = []
    for L in (0, 1, 2, 4):
        rec = reconstruct_intensity(intensity, theta, phi, 10, L, ridge=1e-8)
        assert rec.shape == intensity.shape and np.all(np.isfinite(rec))
        errs.append(np.mean(np.abs(rec - intensity)))
    assert errs[0] > errs[1] > errs[3]
    assert errs[3] < 1e-4


def test_weights_ignore_masked_pixels():
    theta, phi = random_normals((10, 10), seed=5)
    intensity = np.ones((10, 10))
    weights = np.ones((10, 10))
    intensity[0, 0] = 1e6
    weights[0, 0] = 0
    coef = block_coefficients(intensity, theta, phi, 10, 2, weights=weights)
    Y = real_sph_harm(2, theta, phi).reshape(100, -1)
    np.testing.assert_allclose(coef[0, 0], Y[1:].mean(axis=0))


def test_labels_cover_every_pixel_for_sizes_not_multiple_of_w():
    block = np.arange(12).reshape(3, 4)
    labels = upsample_block_labels(block, (37, 45), 10)
    assert labels.shape == (37, 45)
    assert labels[36, 44] == block[2, 3]  # remainder pixels take the nearest block
    assert labels[0, 0] == 0 and labels[15, 25] == block[1, 2]
    rows, cols = pixel_block_index((37, 45), 10)
    assert rows.max() == 2 and cols.max() == 3


def test_window_larger_than_image():
    theta, phi = random_normals((8, 12))
    with pytest.raises(PolarsegError, match="larger than the image"):
        block_coefficients(np.ones((8, 12)), theta, phi, 10, 2)


@pytest.mark.parametrize("L", [0, 1, 2, 7, 12, 30])
def test_recurrence_matches_scipy_sph_harm_y_to_1e10(L):
    """The hand-written recurrence against scipy's complex Y_l^m for every (l, m)."""
    rng = np.random.default_rng(L)
    theta = np.concatenate([[0.0, np.pi / 2, np.pi, 1e-9], rng.uniform(0, np.pi, 60)])
    phi = np.concatenate([[0.3, 2.0, 5.0, 0.0], rng.uniform(0, 2 * np.pi, 60)])
    Y = real_sph_harm(L, theta, phi)
    assert Y.shape == (theta.size, n_coefficients(L))
    for l in range(L + 1):  # noqa: E741
        for m in range(-l, l + 1):
            c = sp.sph_harm_y(l, abs(m), theta, phi)
            if m > 0:
                want = np.sqrt(2) * (-1.0) ** m * c.real
            elif m < 0:
                want = np.sqrt(2) * (-1.0) ** m * c.imag
            else:
                want = c.real
            np.testing.assert_allclose(Y[:, coefficient_index(l, m)], want, rtol=0, atol=1e-10)


def test_chunked_and_threaded_evaluation_equals_small_calls():
    """Large inputs go through chunks on several threads; values must not depend on it."""
    rng = np.random.default_rng(7)
    theta, phi = rng.uniform(0, np.pi / 2, (300, 330)), rng.uniform(0, np.pi, (300, 330))
    intensity = rng.uniform(0.2, 1.0, (300, 330))
    big = block_coefficients(intensity, theta, phi, 10, 6)
    part = block_coefficients(intensity[:10, :20], theta[:10, :20], phi[:10, :20], 10, 6)
    np.testing.assert_allclose(big[:1, :2], part, rtol=1e-13, atol=1e-15)
    Y = real_sph_harm(6, theta, phi)
    np.testing.assert_allclose(Y[5, 7], real_sph_harm(6, theta[5, 7], phi[5, 7]), atol=1e-14)


@pytest.mark.parametrize("shape", [(40, 30), (43, 37)])  # whole blocks only / with strips
def test_reconstruction_shortcut_equals_ridge_expansion(shape):
    """Î − λ'α (dual form, no weights) is Y a of the ridge coefficients, strips included."""
    from napari_polarseg.engine.features.harmonics import pixel_block_index

    theta, phi = random_normals(shape, seed=6)
    rng = np.random.default_rng(7)
    intensity = 1 + 0.3 * np.cos(theta) + 0.05 * rng.normal(size=shape)
    window, L = 10, 12  # M = 100 < K = 169: the dual form
    rec = reconstruct_intensity(intensity, theta, phi, window, L, ridge=1e-3)
    coef = block_coefficients(intensity, theta, phi, window, L, method="ridge", ridge=1e-3)
    rows, cols = pixel_block_index(shape, window)
    per_pixel = coef[rows[:, None], cols[None, :]]  # (H, W, K): each pixel's block
    Y = real_sph_harm(L, theta.ravel(), phi.ravel())
    want = np.einsum("pk,pk->p", Y, per_pixel.reshape(-1, Y.shape[1])).reshape(shape)
    np.testing.assert_allclose(rec, want, rtol=1e-9, atol=1e-9)
    # with weights the general path runs; unit weights give the same numbers
    rec_w = reconstruct_intensity(
        intensity, theta, phi, window, L, ridge=1e-3, weights=np.ones(shape)
    )
    np.testing.assert_allclose(rec_w, rec, rtol=1e-9, atol=1e-9)
