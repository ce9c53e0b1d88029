"""Fresnel physics: corrected eq. 3.13 against the Fresnel-coefficient route, inverses."""

import numpy as np
import pytest

from napari_polarseg.engine import (
    PolarsegError,
    azimuth_from_phase,
    brewster_angle,
    diffuse_dop,
    diffuse_dop_ceiling,
    diffuse_dop_fresnel,
    fresnel_reflectance,
    specular_dop,
    specular_dop_fresnel,
    zenith_from_diffuse_dop,
    zenith_from_dop,
    zenith_from_specular_dop,
)

N_VALUES = np.linspace(1.2, 2.0, 17)
# eq. 3.12 is 0/0 exactly at grazing exit (both transmittances vanish): stop 1e-6 short
THETA = np.linspace(0.0, np.pi / 2 - 1e-6, 2001)


@pytest.mark.parametrize("n", N_VALUES)
def test_corrected_eq_313_equals_fresnel_coefficient_route(n):
    assert np.max(np.abs(diffuse_dop(THETA, n) - diffuse_dop_fresnel(THETA, n))) < 1e-9


def test_printed_eq_313_typo_would_be_wrong():
    # the thesis's "(1 + 1/n)^2" term disagrees with eq. 3.12 by far more than round-off
    n, t = 1.5, np.deg2rad(60.0)
    s2 = np.sin(t) ** 2
    printed = (
        (n - 1 / n) ** 2
        * s2
        / (2 + 2 * n * n - (1 + 1 / n) ** 2 * s2 + 4 * np.cos(t) * np.sqrt(n * n - s2))
    )
    assert abs(printed - diffuse_dop_fresnel(t, n)) > 1e-3
    assert abs(diffuse_dop(t, n) - diffuse_dop_fresnel(t, n)) < 1e-12


def test_reference_values_at_n_145():
    degrees = [15, 30, 45, 60, 75]
    expected = [0.0034, 0.0148, 0.0386, 0.0851, 0.1767]
    got = diffuse_dop(np.deg2rad(degrees), 1.45)
    np.testing.assert_allclose(got, expected, atol=5e-5)
    assert diffuse_dop(np.pi / 2, 1.45) == pytest.approx(0.3554, abs=1e-4)


@pytest.mark.parametrize("n", [1.3, 1.5, 1.8])
def test_ceiling_at_grazing(n):
    assert diffuse_dop(np.pi / 2, n) == pytest.approx((n * n - 1) / (n * n + 1), abs=1e-12)
    assert diffuse_dop_ceiling(n) == pytest.approx((n * n - 1) / (n * n + 1))
    assert diffuse_dop_ceiling(1.5) == pytest.approx(0.3846, abs=1e-4)


@pytest.mark.parametrize("n", N_VALUES)
def test_diffuse_inverse_recovers_zenith(n):
    theta = np.linspace(0.0, np.pi / 2 - 1e-4, 5001)
    est = zenith_from_diffuse_dop(diffuse_dop(theta, n), n)
    assert np.max(np.abs(est.zenith - theta)) < 1e-6
    assert not est.clamped.any()


def test_diffuse_dop_is_monotonic():
    for n in (1.2, 1.45, 2.0):
        assert np.all(np.diff(diffuse_dop(THETA, n)) > 0)


def test_above_ceiling_is_clamped_and_counted_not_nan():
    n = 1.5
    rho = np.array([0.0, 0.2, 0.3846, 0.39, 0.8, 1.0])
    est = zenith_from_diffuse_dop(rho, n)
    assert np.all(np.isfinite(est.zenith))
    np.testing.assert_array_equal(est.clamped, [False, False, False, True, True, True])
    assert est.n_clamped == 3
    np.testing.assert_allclose(est.zenith[est.clamped], np.pi / 2)
    assert est.zenith[0] == 0.0


@pytest.mark.parametrize("n", [1.3, 1.5, 2.0])
def test_specular_closed_form_equals_fresnel(n):
    theta = np.linspace(0, np.pi / 2 - 1e-6, 3001)
    np.testing.assert_allclose(specular_dop(theta, n), specular_dop_fresnel(theta, n), atol=1e-9)


@pytest.mark.parametrize("n", [1.3, 1.5, 2.0])
def test_specular_peaks_at_brewster_and_both_branches_invert(n):
    tb = brewster_angle(n)
    assert tb == pytest.approx(np.arctan(n))
    assert specular_dop(tb, n) == pytest.approx(1.0, abs=1e-12)
    low = np.linspace(0.0, tb - 1e-3, 500)
    high = np.linspace(tb + 1e-3, np.pi / 2 - 1e-3, 500)
    got_low = zenith_from_specular_dop(specular_dop(low, n), n, "below-brewster").zenith
    got_high = zenith_from_specular_dop(specular_dop(high, n), n, "above-brewster").zenith
    assert np.max(np.abs(got_low - low)) < 1e-6
    assert np.max(np.abs(got_high - high)) < 1e-6
    # the same rho gives two different zeniths, one on each side of Brewster's angle
    rho = specular_dop(np.deg2rad(30.0), n)
    a = zenith_from_dop(rho, n, "specular", "below-brewster").zenith
    b = zenith_from_dop(rho, n, "specular", "above-brewster").zenith
    assert a < tb < b


def test_fresnel_reflectance_normal_incidence_and_brewster():
    n = 1.5
    r_perp, r_par = fresnel_reflectance(n, 0.0)
    expected = ((n - 1) / (n + 1)) ** 2
    assert r_perp == pytest.approx(expected) and r_par == pytest.approx(expected)
    _, r_par_b = fresnel_reflectance(n, np.arctan(n))
    assert r_par_b == pytest.approx(0.0, abs=1e-15)
    # beyond the critical angle inside the dielectric: total internal reflection
    r_perp_t, r_par_t = fresnel_reflectance(1 / n, np.deg2rad(60.0))
    assert r_perp_t == 1.0 and r_par_t == 1.0


def test_azimuth_from_phase_per_model():
    phase = np.array([0.0, 0.3, np.pi / 2, 3.0])
    np.testing.assert_allclose(azimuth_from_phase(phase, "diffuse"), phase)
    spec = azimuth_from_phase(phase, "specular")
    np.testing.assert_allclose(spec, np.mod(phase + np.pi / 2, np.pi))
    assert np.all((spec >= 0) & (spec < np.pi))
    with pytest.raises(PolarsegError, match="model"):
        azimuth_from_phase(phase, "metal")


@pytest.mark.parametrize("n", [1.0, 0.5, float("nan"), float("inf")])
def test_bad_refractive_index(n):
    with pytest.raises(PolarsegError, match="refractive index"):
        diffuse_dop(0.3, n)
