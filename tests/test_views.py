"""The standard polarisation views: the AoLP/DoLP HSV composite and the Stokes components.

Known answers: the composite's hue read back from its RGB (scikit-image's rgb2hsv, not
the matplotlib conversion that drew it) is the AoLP, its saturation the DoLP over ρ_max;
the Stokes components of a rendered four-angle stack are I(0°) + I(90°), I(0°) − I(90°)
and I(45°) − I(135°).
"""

from __future__ import annotations

import numpy as np
import pytest
from skimage.color import rgb2hsv

from napari_polarseg.engine import PolarsegError, polarisation_image
from napari_polarseg.engine.analysis.views import (
    CompositeParams,
    aolp_dolp_composite,
    auto_dolp_max,
    hsv_planes,
    intensity_value,
)
from napari_polarseg.engine.physics.stokes import (
    STOKES_COMPONENTS,
    STOKES_CONVENTION,
    stokes_components,
)

RNG = np.random.default_rng(14)


def circular_difference_deg(a: np.ndarray, b: np.ndarray, period: float) -> np.ndarray:
    """|a − b| on a circle of ``period`` (degrees)."""
    d = np.mod(np.asarray(a) - np.asarray(b), period)
    return np.minimum(d, period - d)


def test_hue_is_the_aolp_and_saturation_the_dolp_over_its_maximum():
    phi_deg = np.arange(0.0, 180.0, 2.5)  # 72 angles over the half circle
    rho = np.linspace(0.05, 0.6, 12)
    phase = np.deg2rad(phi_deg)[:, None] * np.ones(rho.size)
    dop = np.ones(phi_deg.size)[:, None] * rho
    intensity = np.full(phase.shape, 500.0)
    params = CompositeParams(dolp_max=0.4)
    rgb = aolp_dolp_composite(intensity, dop, phase, params)
    assert rgb.shape == phase.shape + (3,) and rgb.dtype == np.uint8
    hsv = rgb2hsv(rgb)
    want_saturation = np.clip(dop / 0.4, 0.0, 1.0)
    # saturation within the uint8 rounding of the three channels
    np.testing.assert_allclose(hsv[..., 1], want_saturation, atol=2.5 / 255)
    # value: constant Î is its own 99th percentile, so value 1
    np.testing.assert_allclose(hsv[..., 2], 1.0, atol=0.5 / 255)
    # hue over [0, 180) degrees of AoLP = the full hue circle; uint8 rounding of a pixel
    # with saturation s moves the hue by up to about 0.5 / (255 s) of the circle
    colourful = want_saturation >= 0.3
    hue_deg = hsv[..., 0] * 180.0
    err = circular_difference_deg(hue_deg, phi_deg[:, None] * np.ones(rho.size), 180.0)
    assert np.all(err[colourful] < 1.5), err[colourful].max()
    # the hue turns once round the circle over 180 degrees: 90 degrees is the opposite hue
    np.testing.assert_allclose(
        hsv_planes(intensity, dop, phase, params)[..., 0],
        np.deg2rad(phi_deg)[:, None] / np.pi * np.ones(rho.size),
        atol=1e-12,
    )


@pytest.mark.parametrize(
    ("phi_deg", "colour"),
    [
        (0.0, (255, 0, 0)),  # red
        (30.0, (255, 255, 0)),  # yellow
        (60.0, (0, 255, 0)),  # green
        (90.0, (0, 255, 255)),  # cyan
        (120.0, (0, 0, 255)),  # blue
        (150.0, (255, 0, 255)),  # magenta
        (180.0, (255, 0, 0)),  # φ is taken modulo π: 180° is 0°
    ],
)
def test_fully_polarised_pixels_take_the_primary_colours(phi_deg, colour):
    one = np.ones((1, 1))
    rgb = aolp_dolp_composite(one, one, np.deg2rad(phi_deg) * one)
    assert tuple(rgb[0, 0]) == colour


def test_unpolarised_pixels_are_grey_at_their_normalised_intensity():
    intensity = np.linspace(1.0, 100.0, 100).reshape(10, 10)
    rgb = aolp_dolp_composite(intensity, np.zeros((10, 10)), RNG.uniform(0, np.pi, (10, 10)))
    assert np.all(rgb[..., 0] == rgb[..., 1]) and np.all(rgb[..., 1] == rgb[..., 2])
    top = np.percentile(intensity, 99.0)
    want = np.round(np.clip(intensity / top, 0, 1) * 255)
    np.testing.assert_array_equal(rgb[..., 0], want)
    assert rgb[..., 0].max() == 255 and rgb[0, 0, 0] == round(255 / top)


def test_dolp_max_scales_and_clips_the_saturation():
    one = np.ones((1, 3))
    dop = np.array([[0.05, 0.1, 0.3]])
    sat = hsv_planes(one, dop, one * 0.2, CompositeParams(dolp_max=0.1))[..., 1]
    np.testing.assert_allclose(sat, [[0.5, 1.0, 1.0]])
    sat = hsv_planes(one, dop, one * 0.2, CompositeParams(dolp_max=1.0))[..., 1]
    np.testing.assert_allclose(sat, dop)


def test_light_and_dark_variants():
    intensity = np.array([[10.0, 100.0]])
    dop = np.array([[0.0, 0.5]])
    phase = np.zeros((1, 2))
    light = aolp_dolp_composite(intensity, dop, phase, CompositeParams(mode="light"))
    dark = aolp_dolp_composite(intensity, dop, phase, CompositeParams(mode="dark"))
    # light: value 1, colour only where polarised; white where unpolarised
    assert tuple(light[0, 0]) == (255, 255, 255)
    assert tuple(light[0, 1]) == (255, 128, 128)  # half-saturated red
    # dark: saturation 1, value from ρ; black where unpolarised
    assert tuple(dark[0, 0]) == (0, 0, 0)
    assert tuple(dark[0, 1]) == (128, 0, 0)
    # neither depends on the intensity
    same = aolp_dolp_composite(intensity * 7, dop, phase, CompositeParams(mode="dark"))
    np.testing.assert_array_equal(same, dark)


def test_non_finite_pixels_are_black_and_bad_settings_are_refused():
    intensity = np.array([[1.0, np.nan, 1.0]])
    dop = np.array([[0.5, 0.5, np.inf]])
    rgb = aolp_dolp_composite(intensity, dop, np.zeros((1, 3)))
    assert tuple(rgb[0, 1]) == (0, 0, 0) and tuple(rgb[0, 2]) == (0, 0, 0)
    assert rgb[0, 0].max() == 255
    for bad in ({"dolp_max": 0.0}, {"dolp_max": 1.5}, {"mode": "bright"}):
        with pytest.raises(PolarsegError):
            CompositeParams(**bad)
    with pytest.raises(PolarsegError, match="one shape"):
        aolp_dolp_composite(np.ones((2, 2)), np.ones((2, 3)), np.ones((2, 3)))


def test_intensity_value_and_auto_dolp_max():
    assert np.all(intensity_value(np.zeros((3, 3))) == 0)  # nothing positive: black
    v = intensity_value(np.array([-1.0, 0.0, 50.0, 100.0]), percentile=100.0)
    np.testing.assert_allclose(v, [0.0, 0.0, 0.5, 1.0])
    assert auto_dolp_max(np.linspace(0, 0.08, 1001)) == pytest.approx(0.1)
    assert auto_dolp_max(np.full(10, 0.1)) == pytest.approx(0.1)  # a multiple stays
    assert auto_dolp_max(np.zeros(10)) == pytest.approx(0.05)  # never 0
    assert auto_dolp_max(np.ones(10)) == 1.0
    assert auto_dolp_max(np.array([np.nan])) == 1.0


def render_four_angles(intensity, dop, phase):
    """I(α) = Î (1 + ρ cos(2α − 2φ)) at 0°, 45°, 90°, 135° (thesis eq. 3.14)."""
    angles = np.deg2rad([0.0, 45.0, 90.0, 135.0])
    stack = intensity * (1 + dop * np.cos(2 * angles[:, None, None] - 2 * phase))
    return stack, angles


def test_stokes_components_of_a_four_angle_stack():
    shape = (9, 11)
    intensity = RNG.uniform(50.0, 200.0, shape)
    dop = RNG.uniform(0.0, 0.9, shape)
    phase = RNG.uniform(0.0, np.pi, shape)
    stack, angles = render_four_angles(intensity, dop, phase)
    pol = polarisation_image(stack, angles)
    s = stokes_components(pol.intensity, pol.dop, pol.phase)
    i0, i45, i90, i135 = stack
    np.testing.assert_allclose(s[0], i0 + i90, rtol=1e-10)
    np.testing.assert_allclose(s[1], i0 - i90, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(s[2], i45 - i135, rtol=1e-9, atol=1e-9)
    # and back: ρ = |S1, S2| / S0, φ = ½ atan2(S2, S1)
    np.testing.assert_allclose(np.hypot(s[1], s[2]) / s[0], dop, atol=1e-12)
    back = np.mod(0.5 * np.arctan2(s[2], s[1]), np.pi)
    assert circular_difference_deg(np.rad2deg(back), np.rad2deg(phase), 180.0).max() < 1e-8


def test_stokes_sign_convention():
    """Polarised along the rows (φ = 0): S1 > 0; along the columns (90°): S1 < 0; 45°: S2 > 0."""
    one = np.ones((1, 1))
    for phi_deg, (s1, s2) in {0.0: (2, 0), 90.0: (-2, 0), 45.0: (0, 2), 135.0: (0, -2)}.items():
        s = stokes_components(one, one, np.deg2rad(phi_deg) * one)[:, 0, 0]
        np.testing.assert_allclose(s, [2.0, s1, s2], atol=1e-12)
    assert STOKES_CONVENTION["components"] == list(STOKES_COMPONENTS) == ["S0", "S1", "S2"]
    assert "column axis towards the row axis" in STOKES_CONVENTION["angle_direction"]


def test_hsv_to_rgb_matches_matplotlib():
    from matplotlib.colors import hsv_to_rgb as reference

    from napari_polarseg.engine.analysis.views import hsv_to_rgb

    rng = np.random.default_rng(0)
    hsv = rng.random((50, 60, 3))
    hsv[0, :6, 0] = np.arange(6) / 6  # the sector edges
    hsv[1, :3] = [[0, 0, 1], [1, 1, 1], [0.5, 1, 0]]  # white, red, black
    for dtype, tol in ((np.float64, 1e-12), (np.float32, 1e-6)):
        x = hsv.astype(dtype)
        out = hsv_to_rgb(x)
        assert out.dtype == dtype
        np.testing.assert_allclose(out, reference(x), atol=tol)
