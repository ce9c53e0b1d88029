"""Tests of the synthetic angle-stack renderer (napari_polarseg.engine.synthetic)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.synthetic.optics import (
    diffuse_dop_from_transmission,
    fresnel_transmission_amplitudes,
    render_stack,
)
from napari_polarseg.engine.synthetic.scenes import DEFAULT_ANGLES_DEG, SCENES, make_scene
from napari_polarseg.engine.synthetic.surface import MATERIALS, Material, render_surface

SAMPLE_DIR = Path(__file__).resolve().parents[1] / "napari_polarseg" / "sample_data"


@pytest.fixture(scope="module")
def scenes():
    return {name: make_scene(name) for name in SCENES}


def _lsq_fit(stack: np.ndarray, angles: np.ndarray):
    """Independent estimator: I = c0 + c1 cos 2α + c2 sin 2α by least squares."""
    a = np.column_stack([np.ones_like(angles), np.cos(2 * angles), np.sin(2 * angles)])
    c = np.linalg.pinv(a) @ stack.reshape(len(angles), -1).astype(float)
    c = c.reshape(3, *stack.shape[1:])
    i_hat = c[0]
    rho = np.hypot(c[1], c[2]) / i_hat
    phi = np.mod(0.5 * np.arctan2(c[2], c[1]), np.pi)
    return i_hat, rho, phi


def _axial_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Difference of two orientations mod π, in (−π/2, π/2]."""
    return np.angle(np.exp(2j * (a - b))) / 2


# --------------------------------------------------------------------------------------
# Fresnel transmission route
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("zenith_deg", "expected"),
    [(15, 0.0034), (30, 0.0148), (45, 0.0386), (60, 0.0851), (75, 0.1767)],
)
def test_diffuse_dop_sanity_values(zenith_deg, expected):
    rho = diffuse_dop_from_transmission(np.deg2rad(zenith_deg), 1.45)
    assert abs(float(rho) - expected) < 1e-4


@pytest.mark.parametrize("n", [1.3, 1.45, 1.5, 1.8])
def test_diffuse_dop_ceiling_at_grazing(n):
    rho = diffuse_dop_from_transmission(np.pi / 2, n)
    assert np.isfinite(rho)
    assert float(rho) == pytest.approx((n**2 - 1) / (n**2 + 1), abs=1e-12)
    assert float(diffuse_dop_from_transmission(0.0, n)) == pytest.approx(0.0, abs=1e-15)


def test_diffuse_dop_equals_corrected_closed_form():
    # Corrected thesis eq. 3.13 ((n + 1/n)², not (1 + 1/n)²), written out here on purpose.
    theta = np.linspace(0.0, np.pi / 2, 401)
    for n in (1.3, 1.45, 1.6, 1.8):
        s2 = np.sin(theta) ** 2
        closed = ((n - 1 / n) ** 2 * s2) / (
            2 + 2 * n**2 - (n + 1 / n) ** 2 * s2 + 4 * np.cos(theta) * np.sqrt(n**2 - s2)
        )
        np.testing.assert_allclose(diffuse_dop_from_transmission(theta, n), closed, atol=1e-10)


def test_diffuse_dop_is_monotonic_and_grows_with_n():
    theta = np.linspace(0.0, np.pi / 2, 200)
    rho = diffuse_dop_from_transmission(theta, 1.5)
    assert np.all(np.diff(rho) > 0)
    assert np.all(
        diffuse_dop_from_transmission(theta[1:], 1.6)
        > diffuse_dop_from_transmission(theta[1:], 1.4)
    )


def test_transmittances_conserve_energy():
    # T = 1 − R with the reflection coefficients for light inside the medium.
    theta = np.deg2rad(np.array([0.0, 10.0, 35.0, 60.0, 80.0, 89.0]))
    n = 1.5
    cos_t = np.cos(theta)
    cos_i = np.sqrt(1 - (np.sin(theta) / n) ** 2)
    r_s = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    r_p = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    t_s, t_p = fresnel_transmittances(theta, n)
    np.testing.assert_allclose(t_s, 1 - r_s**2, atol=1e-12)
    np.testing.assert_allclose(t_p, 1 - r_p**2, atol=1e-12)
    # Normal incidence: T = 4n / (n + 1)², amplitudes 2n / (n + 1).
    amp_s, amp_p = fresnel_transmission_amplitudes(0.0, n)
    assert float(amp_s) == pytest.approx(2 * n / (n + 1))
    assert float(amp_p) == pytest.approx(2 * n / (n + 1))
    assert float(t_s[0]) == pytest.approx(4 * n / (n + 1) ** 2)


def test_transmission_rejects_bad_input():
    with pytest.raises(PolarsegError, match="n"):
        diffuse_dop_from_transmission(0.3, 0.9)
    with pytest.raises(PolarsegError, match="zenith"):
        diffuse_dop_from_transmission(2.0, 1.5)
    with pytest.raises(PolarsegError, match="zenith"):
        diffuse_dop_from_transmission(np.nan, 1.5)


# --------------------------------------------------------------------------------------
# render_stack
# --------------------------------------------------------------------------------------


def test_render_stack_follows_eq_3_14_exactly():
    rng = np.random.default_rng(1)
    i_hat = rng.uniform(0.1, 0.9, (9, 11))
    rho = rng.uniform(0.0, 0.5, (9, 11))
    phi = rng.uniform(0.0, np.pi, (9, 11))
    angles = np.deg2rad([0.0, 17.0, 45.0, 90.0, 133.0, 180.0])
    stack = render_stack(i_hat, rho, phi, angles)
    assert stack.dtype == np.float64 and stack.shape == (6, 9, 11)
    for k, a in enumerate(angles):
        np.testing.assert_allclose(
            stack[k], i_hat * (1 + rho * np.cos(2 * a - 2 * phi)), rtol=1e-14, atol=0
        )


def test_render_stack_extremes_at_phase():
    # Maximum Î(1+ρ) through a polariser at α = φ, minimum Î(1−ρ) at α = φ + π/2.
    phi = np.full((3, 4), 0.7)
    stack = render_stack(np.full((3, 4), 0.5), np.full((3, 4), 0.2), phi, [0.7, 0.7 + np.pi / 2])
    np.testing.assert_allclose(stack[0], 0.6)
    np.testing.assert_allclose(stack[1], 0.4)


@pytest.mark.parametrize(("bits", "dtype"), [(8, np.uint8), (12, np.uint16), (16, np.uint16)])
def test_render_stack_quantisation(bits, dtype):
    top = 2**bits - 1
    i_hat = np.array([[0.5, 0.25], [2.0, -0.1]])  # 2.0 over range, −0.1 below zero
    stack = render_stack(i_hat, np.zeros((2, 2)), np.zeros((2, 2)), [0.0, 1.0], bit_depth=bits)
    assert stack.dtype == dtype
    assert stack[0, 0, 0] == np.rint(0.5 * top)
    assert stack[0, 0, 1] == np.rint(0.25 * top)
    assert stack[0, 1, 0] == top
    assert stack[0, 1, 1] == 0
    # full_scale sets the value that maps to the top code.
    s2 = render_stack(
        np.full((2, 2), 50.0),
        np.zeros((2, 2)),
        np.zeros((2, 2)),
        [0.0],
        bit_depth=bits,
        full_scale=100.0,
    )
    assert s2[0, 0, 0] == np.rint(0.5 * top)


def test_render_stack_noise_level_and_seed():
    shape = (200, 200)
    kw = dict(noise_sigma=0.01, full_scale=2.0)
    a = render_stack(np.ones(shape), np.zeros(shape), np.zeros(shape), [0.0, 1.0], rng=5, **kw)
    b = render_stack(np.ones(shape), np.zeros(shape), np.zeros(shape), [0.0, 1.0], rng=5, **kw)
    c = render_stack(np.ones(shape), np.zeros(shape), np.zeros(shape), [0.0, 1.0], rng=6, **kw)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.std(a - 1.0) == pytest.approx(0.02, rel=0.03)  # sigma × full_scale
    assert abs(np.mean(a - 1.0)) < 1e-3


def test_render_stack_shifts_move_frames():
    yy, xx = np.mgrid[0:64, 0:72]
    spot = np.exp(-((yy - 30.0) ** 2 + (xx - 35.0) ** 2) / (2 * 3.0**2))
    shifts = np.array([[0.0, 0.0], [1.5, -2.25], [-0.3, 0.7], [4.0, 3.0]])
    stack = render_stack(spot, np.zeros_like(spot), np.zeros_like(spot), np.zeros(4), shifts=shifts)
    com0 = np.array(ndimage.center_of_mass(stack[0]))
    np.testing.assert_allclose(com0, [30.0, 35.0], atol=1e-6)
    for k in range(1, 4):
        com = np.array(ndimage.center_of_mass(stack[k]))
        np.testing.assert_allclose(com - com0, shifts[k], atol=1e-3)


def test_render_stack_rejects_bad_arguments():
    img = np.ones((4, 4))
    with pytest.raises(PolarsegError, match="shifts"):
        render_stack(img, img, img, [0.0, 1.0], shifts=[[0.0, 1.0]])
    with pytest.raises(PolarsegError, match="bit_depth"):
        render_stack(img, img, img, [0.0], bit_depth=17)
    with pytest.raises(PolarsegError, match="noise_sigma"):
        render_stack(img, img, img, [0.0], noise_sigma=-1.0)
    with pytest.raises(PolarsegError, match="same shape"):
        render_stack(img, np.ones((3, 4)), img, [0.0])
    with pytest.raises(PolarsegError, match="angles"):
        render_stack(img, img, img, np.zeros((2, 2)))


# --------------------------------------------------------------------------------------
# render_surface
# --------------------------------------------------------------------------------------


def _dome(size: int, s: int, radius: float):
    """Slopes of a spherical cap (height in pixel units) on an s-times supersampled grid."""
    c = (np.arange(size * s) + 0.5) / s - 0.5
    yy, xx = np.meshgrid(c, c, indexing="ij")
    dy, dx = yy - size / 2, xx - size / 2
    r2 = (dx**2 + dy**2) / radius**2
    root = np.sqrt(np.clip(1 - r2, 1e-3, None))
    inside = r2 < 1
    p = np.where(inside, -dx / radius / root, 0.0)
    q = np.where(inside, -dy / radius / root, 0.0)
    return p, q, inside.astype(np.intp)


def test_render_surface_smooth_known_answer():
    # Without roughness and supersampling, ρ and φ follow the diffuse model exactly.
    p, q, mat = _dome(48, 1, 20.0)
    mats = [
        Material("flat", 1.5, 0.0, 0.0),
        Material("dome", 1.45, 0.2, 0.0),
    ]
    out = render_surface(p, q, mat, mats, supersample=1, rng=0)
    expected = diffuse_dop_from_transmission(out.zenith, out.refractive_index)
    expected = expected * np.where(out.labels == 1, 0.8, 1.0)
    np.testing.assert_allclose(out.dop, expected, atol=1e-12)
    pol = out.dop > 1e-6
    np.testing.assert_allclose(_axial_diff(out.phase, out.azimuth)[pol], 0.0, atol=1e-9)
    # Zenith from the slopes: tan θ = |∇z|.
    np.testing.assert_allclose(np.tan(out.zenith), np.hypot(p, q), rtol=1e-9)
    # Matched albedo: each material's mean Î equals the target.
    for k in (0, 1):
        assert out.intensity[out.labels == k].mean() == pytest.approx(0.4, rel=1e-9)


def test_render_surface_phase_convention():
    # A plane whose normal leans towards +col has azimuth 0: the polariser passes most
    # light at α = 0. Leaning towards +row: azimuth π/2, maximum at α = π/2.
    mats = [Material("m", 1.5, 0.0, 0.0)]
    mat = np.zeros((8, 8), dtype=np.intp)
    angles = np.deg2rad([0.0, 45.0, 90.0, 135.0])
    for slope_col, slope_row, best in ((-1.0, 0.0, 0), (0.0, -1.0, 2)):
        out = render_surface(
            np.full((8, 8), slope_col), np.full((8, 8), slope_row), mat, mats, supersample=1
        )
        np.testing.assert_allclose(out.zenith, np.pi / 4)
        np.testing.assert_allclose(out.dop, diffuse_dop_from_transmission(np.pi / 4, 1.5))
        stack = render_stack(out.intensity, out.dop, out.phase, angles)
        assert np.all(np.argmax(stack, axis=0) == best)


def test_roughness_lowers_dop_and_scatters_phase():
    p, q, mat = _dome(60, 4, 26.0)
    smooth = [Material("bg", 1.5, 0.0, 0.0), Material("obj", 1.5, 0.0, 0.0)]
    rough = [Material("bg", 1.5, 0.0, 0.0), Material("obj", 1.5, 0.0, 25.0)]
    a = render_surface(p, q, mat, smooth, supersample=4, rng=3)
    b = render_surface(p, q, mat, rough, supersample=4, rng=3)
    # Same macroscopic normals; compare where ρ is well above the facet-sampling residual
    # and away from the rim (25° < zenith < 70°).
    np.testing.assert_array_equal(a.zenith, b.zenith)
    sel = (a.labels == 1) & (a.zenith > np.deg2rad(25)) & (a.zenith < np.deg2rad(70))
    assert sel.sum() > 500
    assert b.dop[sel].mean() < 0.9 * a.dop[sel].mean()
    spread_smooth = np.abs(_axial_diff(a.phase, a.azimuth)[sel]).mean()
    spread_rough = np.abs(_axial_diff(b.phase, b.azimuth)[sel]).mean()
    assert spread_smooth < np.deg2rad(1.0)
    assert spread_rough > 3 * spread_smooth + np.deg2rad(1.0)


def test_depolarisation_scales_dop():
    p, q, mat = _dome(40, 2, 16.0)
    base = render_surface(p, q, mat, [Material("a", 1.5, 0.0, 0.0)] * 2, supersample=2)
    half = render_surface(p, q, mat, [Material("a", 1.5, 0.5, 0.0)] * 2, supersample=2)
    np.testing.assert_allclose(half.dop, 0.5 * base.dop, rtol=1e-12, atol=1e-15)


def test_render_surface_rejects_bad_input():
    z = np.zeros((8, 8))
    m = np.zeros((8, 8), dtype=np.intp)
    mats = [MATERIALS["matte_board"]]
    with pytest.raises(PolarsegError, match="supersample"):
        render_surface(z, z, m, mats, supersample=3)
    with pytest.raises(PolarsegError, match="material_map"):
        render_surface(z, z, m + 1, mats, supersample=2)
    with pytest.raises(PolarsegError, match="refractive_index"):
        Material("bad", 0.9, 0.1, 1.0)


# --------------------------------------------------------------------------------------
# Scenes
# --------------------------------------------------------------------------------------

EXPECTED_NAMES = {
    "leaves": ["background", "natural", "plastic"],
    "camouflage": ["foliage", "net"],
    "fruit": ["fruit", "bruise"],
}


def test_scene_names():
    assert set(SCENES) == set(EXPECTED_NAMES)
    with pytest.raises(PolarsegError, match="name"):
        make_scene("bananas")


@pytest.mark.parametrize("name", SCENES)
def test_scene_shapes_and_dtypes(scenes, name):
    sc = scenes[name]
    assert sc.stack.shape == (7, 120, 130)
    assert sc.stack.dtype == np.uint16
    assert sc.stack.max() <= 4095
    np.testing.assert_allclose(sc.angles, np.deg2rad(DEFAULT_ANGLES_DEG))
    np.testing.assert_allclose(sc.angles_deg, DEFAULT_ANGLES_DEG)
    for arr in (
        sc.labels,
        sc.intensity,
        sc.dop,
        sc.phase,
        sc.zenith,
        sc.azimuth,
        sc.refractive_index,
    ):
        assert arr.shape == (120, 130)
    assert np.all((sc.phase >= 0) & (sc.phase < np.pi))
    assert np.all((sc.zenith >= 0) & (sc.zenith <= np.pi / 2))
    assert np.all((sc.azimuth >= 0) & (sc.azimuth < 2 * np.pi))


@pytest.mark.parametrize("name", SCENES)
def test_scene_labels_cover_every_material(scenes, name):
    sc = scenes[name]
    assert sc.material_names == EXPECTED_NAMES[name]
    k = len(sc.material_names)
    assert set(np.unique(sc.labels)) == set(range(k))
    for label in range(k):
        assert (sc.labels == label).mean() > 0.03
    for label, mname in enumerate(sc.material_names):
        n = sc.params["materials"][mname]["refractive_index"]
        assert 1.3 <= n <= 1.8
        np.testing.assert_array_equal(sc.refractive_index[sc.labels == label], n)


@pytest.mark.parametrize("name", SCENES)
def test_scene_is_reproducible(name):
    a = make_scene(name, shape=(48, 56), seed=7)
    b = make_scene(name, shape=(48, 56), seed=7)
    c = make_scene(name, shape=(48, 56), seed=8)
    np.testing.assert_array_equal(a.stack, b.stack)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.dop, b.dop)
    assert not np.array_equal(a.stack, c.stack)
    assert set(np.unique(a.labels)) == set(range(len(a.material_names)))


def test_noise_does_not_change_the_scene():
    a = make_scene("leaves", shape=(48, 56), seed=3)
    b = make_scene("leaves", shape=(48, 56), seed=3, noise_sigma=0.0, bit_depth=None)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    np.testing.assert_array_equal(a.phase, b.phase)


@pytest.mark.parametrize("name", SCENES)
def test_noise_free_scene_stack_is_the_model(name):
    sc = make_scene(name, shape=(48, 56), noise_sigma=0.0, bit_depth=None)
    assert sc.stack.dtype == np.float64
    for k, a in enumerate(sc.angles):
        model = sc.intensity * (1 + sc.dop * np.cos(2 * a - 2 * sc.phase))
        np.testing.assert_allclose(sc.stack[k], model, rtol=1e-14, atol=0)


@pytest.mark.parametrize("name", SCENES)
def test_scene_stack_gives_back_ground_truth(scenes, name):
    sc = scenes[name]
    i_hat, rho, phi = _lsq_fit(sc.stack / 4095.0, sc.angles)
    # 0.3 % noise at Î ≈ 0.4 with 7 frames: σ(Î) ≈ 0.0011, σ(ρ) ≈ 0.004.
    assert np.abs(i_hat - sc.intensity).mean() < 0.002
    assert np.abs(rho - sc.dop).mean() < 0.006
    strong = sc.dop > 0.03
    assert strong.sum() > 50
    assert np.median(np.abs(_axial_diff(phi, sc.phase))[strong]) < np.deg2rad(4.0)


@pytest.mark.parametrize("name", SCENES)
def test_scene_dop_below_material_ceiling(scenes, name):
    sc = scenes[name]
    for label, mname in enumerate(sc.material_names):
        m = sc.params["materials"][mname]
        n, d = m["refractive_index"], m["depolarisation"]
        ceiling = (n**2 - 1) / (n**2 + 1) * (1 - d)
        pure = ndimage.binary_erosion(sc.labels == label, iterations=2)
        assert sc.dop[pure].max() <= ceiling + 1e-12


@pytest.mark.parametrize("name", ["leaves", "camouflage"])
def test_scene_mean_intensity_matched(scenes, name):
    sc = scenes[name]
    means = [sc.intensity[sc.labels == k].mean() for k in range(len(sc.material_names))]
    assert max(means) / min(means) < 1.03
    assert np.mean(means) == pytest.approx(0.4, rel=0.03)


def _shading(sc):
    p = sc.params
    lz, la = np.deg2rad(p["light_zenith_deg"]), np.deg2rad(p["light_azimuth_deg"])
    light = np.array([np.sin(lz) * np.cos(la), np.sin(lz) * np.sin(la), np.cos(lz)])
    normal = np.stack(
        [
            np.sin(sc.zenith) * np.cos(sc.azimuth),
            np.sin(sc.zenith) * np.sin(sc.azimuth),
            np.cos(sc.zenith),
        ]
    )
    lam = np.clip(np.tensordot(light, normal, axes=1), 0, None)
    return (1 - p["ambient"]) * lam + p["ambient"]


def test_fruit_intensity_matched(scenes):
    sc = scenes["fruit"]
    fruit, bruise = (sc.labels == k for k in range(2))
    # A close-up: the fruit fills the frame, the bruise is a patch of it.
    assert 0.05 < bruise.mean() < 0.4
    # The bruise does not show yet: same albedo as the healthy skin, so once the shading
    # of the true normals is divided out, the two agree.
    mats = sc.params["materials"]
    assert mats["bruise"]["albedo"] == mats["fruit"]["albedo"]
    refl = sc.intensity / _shading(sc)
    assert np.median(refl[bruise]) == pytest.approx(np.median(refl[fruit]), rel=0.04)
    # ... while its polarisation differs: ρ relative to the smooth diffuse model at the
    # true zenith is lower by the ratio of the Fresnel terms (n 1.38 vs 1.42) times the
    # ratio of the undepolarised shares (0.65 vs 0.80), about 0.68.
    mats = sc.params["materials"]
    sel = (sc.zenith > np.deg2rad(25)) & (sc.zenith < np.deg2rad(65))
    rel = sc.dop / diffuse_dop_from_transmission(np.where(sel, sc.zenith, 1.0), 1.42)
    z = sc.zenith[sel & bruise]
    fresnel_ratio = np.median(
        diffuse_dop_from_transmission(z, mats["bruise"]["refractive_index"])
        / diffuse_dop_from_transmission(z, mats["fruit"]["refractive_index"])
    )
    expected = (
        fresnel_ratio
        * (1 - mats["bruise"]["depolarisation"])
        / (1 - mats["fruit"]["depolarisation"])
    )
    ratio = np.median(rel[sel & bruise]) / np.median(rel[sel & fruit])
    assert ratio == pytest.approx(expected, abs=0.06)
    assert ratio < 0.8


@pytest.mark.parametrize("name", SCENES)
def test_scene_texture_statistics_similar(scenes, name):
    # Albedo texture: Î divided by the shading of the true normals has the same relative
    # spread (5 %) in every material; roughness adds a little.
    sc = scenes[name]
    refl = sc.intensity / _shading(sc)
    cvs = []
    for k in range(len(sc.material_names)):
        pure = ndimage.binary_erosion(sc.labels == k, iterations=2)
        cvs.append(refl[pure].std() / refl[pure].mean())
    assert max(cvs) < 1.3 * min(cvs)
    assert 0.04 < min(cvs) and max(cvs) < 0.08


def test_scene_other_shape_and_shifts():
    shifts = np.zeros((7, 2))
    shifts[3] = (0.5, -1.0)
    a = make_scene("camouflage", shape=(64, 80), noise_sigma=0.0, bit_depth=None)
    b = make_scene("camouflage", shape=(64, 80), noise_sigma=0.0, bit_depth=None, shifts=shifts)
    assert a.stack.shape == (7, 64, 80)
    np.testing.assert_array_equal(a.stack[0], b.stack[0])
    expected = ndimage.shift(a.stack[3], (0.5, -1.0), order=3, mode="nearest")
    np.testing.assert_allclose(b.stack[3], expected, atol=1e-12)
    assert b.params["shifts"][3] == [0.5, -1.0]
    with pytest.raises(PolarsegError, match="shifts"):
        make_scene("camouflage", shape=(64, 80), shifts=np.zeros((3, 2)))
    with pytest.raises(PolarsegError, match="shape"):
        make_scene("fruit", shape=(10, 80))


# --------------------------------------------------------------------------------------
# Bundled sample data
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", SCENES)
def test_sample_data_files(name):
    path = SAMPLE_DIR / f"{name}.npz"
    assert path.is_file(), f"run scripts/make_sample_data.py to create {path}"
    assert path.stat().st_size < 1_000_000
    with np.load(path) as data:
        assert set(data.files) == {"stack", "angles", "labels"}
        stack, angles, labels = data["stack"], data["angles"], data["labels"]
    assert stack.dtype == np.uint16 and stack.shape == (7, 120, 130)
    assert angles.dtype == np.float64
    np.testing.assert_array_equal(angles, DEFAULT_ANGLES_DEG)  # degrees
    assert labels.dtype == np.uint8 and labels.shape == (120, 130)
    # The files are make_scene(name) with the defaults (seed 0): not stale.
    sc = make_scene(name)
    np.testing.assert_array_equal(labels, sc.labels)
    np.testing.assert_array_equal(stack, sc.stack)


def fresnel_transmittances(zenith, n) -> tuple[np.ndarray, np.ndarray]:
    """Fresnel power transmittances for light leaving a dielectric into air.

    Parameters
    ----------
    zenith : array_like
        Exit angle θ in radians, in [0, π/2].
    n : array_like
        Refractive index of the material relative to air (dimensionless, >= 1).

    Returns
    -------
    T_s, T_p : ndarray
        ``T = (cos θ / (n cos θ_i)) |t|²`` for the s and p components (fractions of the
        power incident from inside). Both are 0 at grazing exit (θ = π/2).

    See Also
    --------
    fresnel_transmission_amplitudes
    """
    theta, n = np.asarray(zenith, dtype=float), np.asarray(n, dtype=float)
    t_s, t_p = fresnel_transmission_amplitudes(theta, n)
    sin_i = np.sin(theta) / n
    cos_i = np.sqrt(np.clip(1.0 - sin_i**2, 0.0, None))
    factor = np.cos(theta) / (n * cos_i)
    return factor * t_s**2, factor * t_p**2
