"""PCA, Mahalanobis affinity (eqs. 4.24-4.27 with the inverse covariance), feature kinds."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from napari_polarseg.engine import (
    PolarsegError,
    affinity_matrix,
    block_coefficients,
    mahalanobis_sq,
    pca_features,
)
from napari_polarseg.engine.features.pca import harmonic_features
from napari_polarseg.engine.graph.affinity import spatial_kernel


def test_mahalanobis_uses_inverse_covariance_eq_427():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(60, 3)) @ np.array([[3.0, 0, 0], [1.0, 0.5, 0], [0, 0.2, 0.1]])
    cov = np.cov(x, rowvar=False, bias=True)  # eq. 4.26: 1/L normalisation
    want = cdist(x, x, "mahalanobis", VI=np.linalg.inv(cov)) ** 2
    np.testing.assert_allclose(mahalanobis_sq(x), want, atol=1e-9)
    # eq. 4.27 as printed (Sigma instead of its inverse) gives something else
    wrong = cdist(x, x, "mahalanobis", VI=cov) ** 2
    assert np.abs(wrong - want).max() > 1.0


def test_affinity_scale_modes():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(40, 5))
    d = mahalanobis_sq(x)
    np.testing.assert_allclose(affinity_matrix(x, 2.0), np.exp(-d / 2.0))
    med = np.median(d[~np.eye(40, dtype=bool)])
    np.testing.assert_allclose(affinity_matrix(x, 2.0, "median"), np.exp(-d / (2.0 * med)))
    np.testing.assert_allclose(np.diag(affinity_matrix(x)), 1.0)
    with pytest.raises(PolarsegError, match="scale"):
        affinity_matrix(x, 0.0)


def test_pca_keeps_share_of_variance():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(200, 6)) * np.array([10.0, 5.0, 1.0, 0.1, 0.1, 0.1])
    res = pca_features(x, 0.95)
    assert res.n_components == 2  # 125/126 of the variance in two components
    assert res.explained_variance > 0.95
    assert pca_features(x, 0.80).n_components == 1
    assert pca_features(x, 1.0).n_components == 6
    assert res.features.shape == (200, 2)
    with pytest.raises(PolarsegError, match="identical"):
        pca_features(np.ones((10, 4)), 0.95)


def test_zonal_and_energy_features_ignore_surface_azimuth():
    rng = np.random.default_rng(3)
    theta = rng.uniform(0, 1.2, (20, 20))
    phi = rng.uniform(0, np.pi, (20, 20))
    intensity = 1 + 0.5 * np.cos(theta) + 0.2 * np.sin(theta) * np.cos(phi)
    a = block_coefficients(intensity, theta, phi, 10, 6)
    b = block_coefficients(intensity, theta, phi + 0.7, 10, 6)  # every normal turned
    np.testing.assert_allclose(harmonic_features(a, "zonal"), harmonic_features(b, "zonal"))
    np.testing.assert_allclose(harmonic_features(a, "energy"), harmonic_features(b, "energy"))
    assert np.abs(harmonic_features(a, "thesis") - harmonic_features(b, "thesis")).max() > 1e-3
    assert harmonic_features(a, "zonal").shape == (4, 7)
    assert harmonic_features(a, "energy").shape == (4, 7)
    with pytest.raises(PolarsegError, match="feature kind"):
        harmonic_features(a, "colour")


def test_spatial_kernel():
    k = spatial_kernel((3, 4), radius=1.5, sigma=2.0)
    assert k.shape == (12, 12)
    assert k[0, 0] == 1.0
    assert k[0, 1] == pytest.approx(np.exp(-1 / 4))
    assert k[0, 5] == pytest.approx(np.exp(-2 / 4))  # diagonal neighbour, within 1.5
    assert k[0, 2] == 0.0  # two blocks away: beyond the radius
    np.testing.assert_allclose(k, k.T)


def test_affinity_from_kept_distances_and_float32():
    """exp(−D/s) from distances computed once equals the affinity built from scratch, in
    either mode; a float32 matrix holds the float64 values rounded."""
    from napari_polarseg.engine.graph.affinity import (
        affinity_from_distances,
        effective_scale,
        median_offdiagonal,
    )

    rng = np.random.default_rng(2)
    x = rng.normal(size=(50, 4))
    d = mahalanobis_sq(x)
    med = median_offdiagonal(d)
    assert med == pytest.approx(np.median(d[~np.eye(50, dtype=bool)]), rel=1e-12)
    for s, mode in ((1.0, "absolute"), (3.0, "absolute"), (2.0, "median")):
        scale = effective_scale(s, mode, med)
        np.testing.assert_allclose(
            affinity_from_distances(d, scale), affinity_matrix(x, s, mode), rtol=1e-12
        )
    d32 = mahalanobis_sq(x, dtype=np.float32)
    assert d32.dtype == np.float32
    np.testing.assert_allclose(d32, d, rtol=1e-6, atol=1e-6)
    w32 = affinity_matrix(x, 2.0, "median", dtype=np.float32)
    assert w32.dtype == np.float32
    np.testing.assert_allclose(w32, affinity_matrix(x, 2.0, "median"), rtol=1e-5)
    with pytest.raises(PolarsegError, match="median"):
        effective_scale(1.0, "median", None)
