"""Polarisation image by linear least squares (replaces thesis eqs. 4.8-4.12)."""

import numpy as np
import pytest

from napari_polarseg.engine import PolarsegError, distinct_angle_count, polarisation_image


def render(intensity, dop, phase, angles):
    return intensity * (1 + dop * np.cos(2 * angles[:, None, None] - 2 * phase))


def known_image(shape=(64, 80), seed=0):
    rng = np.random.default_rng(seed)
    intensity = rng.uniform(0.3, 0.8, shape)
    dop = rng.uniform(0.0, 0.4, shape)
    phase = rng.uniform(0.0, np.pi, shape)
    return intensity, dop, phase


@pytest.mark.parametrize(
    "angles_deg",
    [
        [0, 45, 90, 135],
        [0, 30, 60, 90, 120, 150, 180],
        list(range(0, 181, 10)),
        [3, 47, 101],  # any 3 distinct angles
        [10, 10, 80, 150, 150],  # repeats allowed
    ],
)
def test_exact_recovery_without_noise(angles_deg):
    intensity, dop, phase = known_image()
    a = np.deg2rad(angles_deg)
    p = polarisation_image(render(intensity, dop, phase, a), a)
    np.testing.assert_allclose(p.intensity, intensity, atol=1e-12)
    np.testing.assert_allclose(p.dop, dop, atol=1e-12)
    dphi = np.angle(np.exp(2j * (p.phase - phase))) / 2
    assert np.max(np.abs(dphi[dop > 1e-6])) < 1e-9
    assert np.all((p.phase >= 0) & (p.phase < np.pi))
    assert np.max(p.residual) < 1e-12


def test_phase_covers_whole_half_turn():
    # the thesis's arccos estimator folds phase into [0, pi/2]; the fit must not
    phase = np.linspace(0, np.pi, 50, endpoint=False)[None, :]
    a = np.deg2rad([0, 30, 60, 90, 120, 150])
    p = polarisation_image(render(np.ones_like(phase), 0.3 * np.ones_like(phase), phase, a), a)
    np.testing.assert_allclose(p.phase, phase, atol=1e-12)
    assert p.phase.max() > 3.0


def test_seven_angles_12bit_noise_acceptance():
    """Median |error| of rho < 0.005 and of phi < 2 degrees (rho > 0.05), 12-bit noise."""
    rng = np.random.default_rng(7)
    intensity, dop, phase = known_image((200, 200), seed=3)
    a = np.deg2rad([0, 30, 60, 90, 120, 150, 180])
    full = 4095.0
    stack = render(intensity, dop, phase, a) * full / 1.6
    stack = stack + rng.normal(0, 0.002 * full, stack.shape)  # 0.2 % of full scale
    stack = np.clip(np.round(stack), 0, full).astype(np.uint16)
    p = polarisation_image(stack, a)
    assert np.median(np.abs(p.dop - dop)) < 0.005
    sel = dop > 0.05
    dphi = np.abs(np.angle(np.exp(2j * (p.phase - phase))) / 2)
    assert np.rad2deg(np.median(dphi[sel])) < 2.0
    np.testing.assert_allclose(np.median(p.intensity / (intensity * full / 1.6)), 1, atol=2e-3)


def test_thesis_moment_estimator_is_biased_by_sqrt_pi():
    # documents the thesis error: eq. 4.9 with a mean over evenly spaced angles gives
    # rho * sqrt(1/pi); the least-squares fit gives rho
    a = np.deg2rad(np.arange(0, 180, 10))
    rho = 0.3
    x = rho * np.cos(2 * a - 0.8)
    sigma = np.sqrt(np.mean(x**2))
    assert np.sqrt(2 / np.pi) * sigma == pytest.approx(rho / np.sqrt(np.pi), rel=1e-9)
    p = polarisation_image((1 + x)[:, None, None], a)
    assert p.dop[0, 0] == pytest.approx(rho, abs=1e-12)


def test_distinct_angle_count_mod_180():
    assert distinct_angle_count(np.deg2rad([0, 180, 90])) == 2
    assert distinct_angle_count(np.deg2rad([0, 30, 60, 90, 120, 150, 180])) == 6
    assert distinct_angle_count(np.deg2rad([10, 10, 10])) == 1


@pytest.mark.parametrize(
    ("stack_shape", "angles_deg", "match"),
    [
        ((3, 8, 8), [0, 90, 180], "distinct"),
        ((2, 8, 8), [0, 45], "distinct"),
        ((4, 8, 8), [0, 45, 90], "frames"),
        ((8, 8), [0, 45, 90], "3 dimensions"),
    ],
)
def test_bad_stacks_raise(stack_shape, angles_deg, match):
    with pytest.raises(PolarsegError, match=match):
        polarisation_image(np.ones(stack_shape), np.deg2rad(angles_deg))


def test_nan_only_stack_raises_and_nan_pixels_are_invalid():
    a = np.deg2rad([0, 45, 90, 135])
    with pytest.raises(PolarsegError, match="NaN"):
        polarisation_image(np.full((4, 5, 5), np.nan), a)
    stack = np.ones((4, 5, 5))
    stack[2, 1, 1] = np.nan
    p = polarisation_image(stack, a)
    assert p.invalid[1, 1] and p.invalid.sum() == 1
    assert np.all(np.isfinite(p.dop)) and np.all(np.isfinite(p.phase))


@pytest.mark.parametrize(
    "angles_deg", [[0, 45, 90, 135], list(range(0, 181, 10)), [10, 10, 80, 150, 150]]
)
@pytest.mark.parametrize("robust", [False, True])
def test_unweighted_fast_path_equals_weighted_fit(angles_deg, robust):
    """Finite data without weights skips the weight arrays; unit weights take the
    general path. Both are the same least-squares fit."""
    rng = np.random.default_rng(11)
    intensity, dop, phase = known_image((30, 40), seed=5)
    a = np.deg2rad(angles_deg)
    stack = render(intensity, dop, phase, a) + rng.normal(0, 0.01, (a.size, 30, 40))
    fast = polarisation_image(stack, a, robust=robust)
    slow = polarisation_image(stack, a, robust=robust, weights=np.ones(stack.shape))
    for name in ("intensity", "dop", "phase", "residual"):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), atol=1e-12)
    np.testing.assert_array_equal(fast.invalid, slow.invalid)
    assert np.array_equal(fast.angles, slow.angles)


def test_weighted_fit_in_chunks_reports_every_pixels_weights():
    """The weighted fit runs on chunks of FIT_CHUNK_PIXELS pixels: one missing sample in
    the last chunk reports the weights of every pixel (the full chunks' too), and every
    other pixel is the fit without weights."""
    from napari_polarseg.engine.physics.polarimage import FIT_CHUNK_PIXELS

    shape = (FIT_CHUNK_PIXELS // 100 + 7, 200)  # two chunks and a short third
    a = np.deg2rad([0, 30, 60, 90, 120, 150])
    stack = render(*known_image(shape, seed=3), a)
    weights = np.ones(stack.shape)
    weights[2, -1, -1] = 0.0
    fit = polarisation_image(stack, a, weights=weights)
    plain = polarisation_image(stack, a)
    assert fit.sample_weights is not None and fit.sample_weights.shape == weights.shape
    np.testing.assert_array_equal(fit.sample_weights, weights)
    for name in ("intensity", "dop", "phase"):
        np.testing.assert_allclose(getattr(fit, name), getattr(plain, name), atol=1e-12)
    assert polarisation_image(stack, a, weights=np.ones(stack.shape)).sample_weights is None


def test_integer_stack_is_fitted_without_a_float64_copy():
    """Camera counts stay integers (no float64 copy of the stack); the fit converts them
    chunk by chunk and gives the float fit's numbers, duplicate angles (0° and 180°)
    averaged, in the fast path and the robust one."""
    from napari_polarseg.engine import Pipeline, SegmentParams
    from napari_polarseg.engine.physics.polarimage import check_stack

    rng = np.random.default_rng(4)
    angles = np.deg2rad(np.arange(0, 181, 20))  # 0 and 180: one state, two frames
    zen_like = rng.random((40, 50))
    phase = np.pi * rng.random((40, 50))
    clean = 2000 * (1 + 0.4 * zen_like * np.cos(2 * angles[:, None, None] - 2 * phase))
    stack = (clean + rng.normal(0, 20, clean.shape)).astype(np.uint16)
    data, _ = check_stack(stack, angles)
    assert data.dtype == np.uint16 and np.shares_memory(data, stack)
    for robust in (False, True):
        got = polarisation_image(stack, angles, robust=robust)
        want = polarisation_image(stack.astype(np.float64), angles, robust=robust)
        for name in ("intensity", "dop", "phase", "residual"):
            np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-10)
    pipe = Pipeline(stack, angles, SegmentParams(window=5, degree=3, n_segments=2))
    assert pipe.stack is stack
    np.testing.assert_array_equal(
        pipe.run().labels,
        Pipeline(stack.astype(np.float64), angles, pipe.params).run().labels,
    )


def test_mask_reasons_name_the_nonzero_counts_in_order():
    from napari_polarseg.engine.physics.pixel_mask import mask_reasons

    counts = {"saturated_pixels": 2, "dark_pixels": 0, "nonfinite_pixels": 1}
    assert mask_reasons(counts) == ["2 saturated", "1 not finite"]
    assert mask_reasons({"dark_pixels": 3}, dark="dark") == ["3 dark"]
    assert mask_reasons({}) == []
