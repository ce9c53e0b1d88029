"""The object-size estimate (engine/features/object_size.py) on planted scenes of known
object size, the truth measures on constructed cases, and NaN, mask and shape handling."""

from __future__ import annotations

import time

import numpy as np
import pytest

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features.object_size import (
    FALLBACK_SHARE,
    MIN_INSTANCE_AREA,
    ObjectSize,
    component_size,
    estimate_object_size,
    instance_size,
    noise_energy,
    noise_sd,
)

FACTOR = 1.5
DIAMETERS = (8, 16, 32, 64)
#: (Î, ρ, φ) of the background and the two object materials, per contrast.
MATERIALS = {
    "dop": ((0.4, 0.4, 0.4), (0.05, 0.25, 0.15), (0.2, 1.0, 2.0)),
    "intensity": ((0.4, 0.6, 0.25), (0.1, 0.1, 0.1), (0.2, 0.2, 0.2)),
}


def planted(diameter: float, layout: str, contrast: str, shape=(256, 256), seed=0):
    """Objects of one size on a background: ``layout`` ``sparse`` (non-overlapping discs
    at random, 2 px apart, about 30 % of the frame), ``touching`` (hexagonally packed
    touching discs: the frame is all objects) or ``ellipses`` (non-overlapping ellipses of
    axis ratio 1.3–2 whose equivalent diameter is ``diameter``). Two materials alternate;
    they and the background differ in ρ and φ (``dop``) or Î (``intensity``). A shading
    ramp of ±15 % across the frame, 2 % noise on Î and ρ, 0.2 rad on φ. Returns Î, ρ, φ
    and the instance ids."""
    rng = np.random.default_rng(seed)
    h, w = shape
    ids = np.zeros(shape, dtype=np.int32)
    r = diameter / 2

    def window(cy: float, cx: float, reach: float):
        # the object's bounding window only: drawing on the whole frame is slow
        y0, y1 = max(int(cy - reach), 0), min(int(cy + reach) + 2, h)
        x0, x1 = max(int(cx - reach), 0), min(int(cx + reach) + 2, w)
        rows, cols = np.mgrid[y0:y1, x0:x1].astype(float)
        return (slice(y0, y1), slice(x0, x1)), rows - cy, cols - cx

    k = 0
    if layout == "touching":
        for i, cy in enumerate(np.arange(r, h + r, diameter * np.sqrt(3) / 2)):
            for cx in np.arange(r + (i % 2) * r, w + r, diameter):
                box, dy, dx = window(cy, cx, r)
                k += 1
                ids[box][dy**2 + dx**2 <= r * r] = k
    else:
        target = max(3, int(0.3 * h * w / (np.pi * r * r)))
        for _ in range(3000):
            if k >= target:
                break
            cy, cx = rng.uniform(r, h - r), rng.uniform(r, w - r)
            ratio = rng.uniform(1.3, 2.0) if layout == "ellipses" else 1.0
            a, b = r * np.sqrt(ratio), r / np.sqrt(ratio)
            t = rng.uniform(0, np.pi)
            box, dy, dx = window(cy, cx, a + 3)
            u = dx * np.cos(t) + dy * np.sin(t)
            v = -dx * np.sin(t) + dy * np.cos(t)
            if np.any(((u / (a + 2)) ** 2 + (v / (b + 2)) ** 2 <= 1.0) & (ids[box] > 0)):
                continue
            k += 1
            ids[box][(u / a) ** 2 + (v / b) ** 2 <= 1.0] = k
    material = np.where(ids > 0, 1 + ids % 2, 0)
    i_of, rho_of, phi_of = (np.asarray(m) for m in MATERIALS[contrast])
    shading = 1.0 + 0.3 * (np.arange(w) / w - 0.5)
    intensity = i_of[material] * shading * (1.0 + 0.02 * rng.standard_normal(shape))
    dop = np.abs(rho_of[material] + 0.02 * rng.standard_normal(shape))
    phase = phi_of[material] + 0.2 * rng.standard_normal(shape)
    return intensity, dop, phase, ids


def within(estimate: float, truth: float) -> bool:
    return truth / FACTOR <= estimate <= truth * FACTOR


@pytest.mark.parametrize("diameter", DIAMETERS)
@pytest.mark.parametrize("layout", ["sparse", "touching", "ellipses"])
def test_planted_objects_within_factor(diameter, layout):
    for contrast in MATERIALS:
        intensity, dop, phase, ids = planted(diameter, layout, contrast, seed=diameter)
        truth = instance_size(ids)
        assert within(truth, diameter)  # the planted size is what the truth measures
        est = estimate_object_size(intensity, dop, phase)
        assert est.estimated and not est.fallback
        assert within(est.size_px, truth), (layout, contrast, est.size_px, truth)


def test_planted_on_a_frame_of_another_shape():
    intensity, dop, phase, ids = planted(24, "sparse", "dop", shape=(240, 320), seed=3)
    est = estimate_object_size(intensity, dop, phase)
    assert within(est.size_px, instance_size(ids))


def test_diagnostics_explain_the_estimate():
    intensity, dop, phase, _ = planted(32, "sparse", "intensity", seed=1)
    est = estimate_object_size(intensity, dop, phase)
    assert len(est.scales_px) == len(est.scores) > 10
    assert np.all(np.diff(est.scales_px) > 0)
    assert sum(est.scores) == pytest.approx(1.0)
    # the scale with the most votes lies near the estimate
    peak = est.scales_px[int(np.argmax(est.scores))]
    assert est.size_px / 1.5 < peak < est.size_px * 1.5
    assert 0.0 < est.coverage <= 1.0
    assert est.channels == ("log Î", "ρ cos 2φ", "ρ sin 2φ")
    line = est.describe()
    assert line.startswith(f"object size {est.size_px:.0f} px (estimated from ")
    assert "\n" not in line


def test_given_size():
    size = ObjectSize.given(34.0)
    assert size.size_px == 34.0 and not size.estimated and not size.fallback
    assert size.describe() == "object size 34 px (given)"


def test_instance_size_exact():
    ids = np.zeros((40, 40), dtype=np.int64)
    ids[0:10, 0:10] = 5  # 100 px
    ids[20:24, 20:24] = 2  # 16 px
    ids[30:40, 30:35] = 9  # 50 px
    ids[39, 0] = 3  # 1 px: ignored
    ids[35:37, 0:4] = 4  # 8 px < MIN_INSTANCE_AREA: ignored
    ids[0, 39] = -1  # negative: not an instance
    assert MIN_INSTANCE_AREA == 9
    assert instance_size(ids) == pytest.approx(np.sqrt(4 * 50 / np.pi))
    # one id in two disjoint parts is one instance of the summed area
    ids[12:14, 30:35] = 2  # 10 more px for id 2 → 26 px
    diameters = np.sqrt(4 * np.array([100, 26, 50]) / np.pi)
    assert instance_size(ids) == pytest.approx(np.median(diameters))
    assert np.isnan(instance_size(np.zeros((5, 5), dtype=np.int32)))
    with pytest.raises(PolarsegError):
        instance_size(np.zeros((5, 5)))


def test_component_size_exact():
    labels = np.zeros((30, 30), dtype=np.uint8)
    labels[0:6, 0:6] = 2  # 36 px
    labels[0:6, 6:8] = 3  # touching the first: one component of 48 px
    labels[20:30, 20:30] = 3  # 100 px
    labels[10:12, 10:12] = 2  # 4 px: ignored
    labels[15:20, 0:30] = 1  # the floor's class: not counted
    expected = np.median(np.sqrt(4 * np.array([48, 100]) / np.pi))
    assert component_size(labels, {2, 3}) == pytest.approx(expected)
    assert component_size(labels, [1]) == pytest.approx(np.sqrt(4 * 150 / np.pi))
    # diagonal neighbours are not connected (4-connectivity)
    diag = np.zeros((10, 10), dtype=int)
    diag[0:3, 0:3] = 1
    diag[3:6, 3:6] = 1
    assert component_size(diag, [1]) == pytest.approx(np.sqrt(4 * 9 / np.pi))
    assert np.isnan(component_size(labels, [7]))


def test_nan_pixels_are_ignored():
    intensity, dop, phase, ids = planted(16, "sparse", "dop", seed=5)
    clean = estimate_object_size(intensity, dop, phase).size_px
    rng = np.random.default_rng(0)
    holes = rng.random(intensity.shape) < 0.05
    intensity, dop, phase = intensity.copy(), dop.copy(), phase.copy()
    intensity[holes] = np.nan
    dop[40:80, 40:80] = np.nan
    phase[0:10] = np.inf
    intensity[200:, 200:] = 0.0  # Î ≤ 0: no log, not used
    est = estimate_object_size(intensity, dop, phase)
    assert np.isfinite(est.size_px) and not est.fallback
    assert within(est.size_px, instance_size(ids))
    assert est.size_px == pytest.approx(clean, rel=0.25)


def test_mask_selects_the_pixels():
    small = planted(12, "sparse", "intensity", shape=(128, 256), seed=1)
    large = planted(48, "sparse", "intensity", shape=(128, 256), seed=2)
    both = [np.concatenate([a, b]) for a, b in zip(small[:3], large[:3], strict=True)]
    mask = np.zeros(both[0].shape, dtype=bool)
    mask[:128] = True
    top = estimate_object_size(*both, mask=mask)
    bottom = estimate_object_size(*both, mask=~mask)
    assert within(top.size_px, instance_size(small[3]))
    assert within(bottom.size_px, instance_size(large[3]))
    # masked pixels may hold anything
    garbage = [a.copy() for a in both]
    garbage[0][~mask] = np.nan
    garbage[1][~mask] = 7.0
    assert estimate_object_size(*garbage, mask=mask).size_px == pytest.approx(top.size_px, rel=0.1)


def test_fallbacks():
    shape = (64, 80)
    nan = np.full(shape, np.nan)
    est = estimate_object_size(nan, nan, nan)
    assert est.fallback and np.isfinite(est.size_px)
    assert "fallback" in est.describe()
    flat = np.ones(shape)
    est = estimate_object_size(flat, 0 * flat, 0 * flat)
    assert est.fallback and est.size_px == pytest.approx(FALLBACK_SHARE * np.sqrt(64 * 80))
    tiny = np.zeros(shape, dtype=bool)
    tiny[10:14, 10:30] = True
    assert estimate_object_size(flat, flat, flat, mask=tiny).fallback


def test_bad_shapes_raise():
    a = np.ones((20, 20))
    with pytest.raises(PolarsegError):
        estimate_object_size(a, a, np.ones((20, 21)))
    with pytest.raises(PolarsegError):
        estimate_object_size(a, a, a, mask=np.ones((21, 20), dtype=bool))
    with pytest.raises(PolarsegError):
        estimate_object_size(np.ones(20), np.ones(20), np.ones(20))


def test_large_frame_is_fast_and_scaled_back():
    # a 1224 × 1024 frame of 64 px discs: estimated on a block-averaged image, given
    # back in pixels of the frame
    intensity, dop, phase, ids = planted(64, "touching", "intensity", shape=(1024, 1224))
    t0 = time.perf_counter()
    est = estimate_object_size(intensity, dop, phase)
    seconds = time.perf_counter() - t0
    assert est.work_factor > 1
    assert within(est.size_px, instance_size(ids))
    assert max(est.scales_px) > 64
    assert seconds < 2.0  # about 0.2 s on one core; slack for a loaded machine


def test_banded_block_means_equal_the_whole_frame(monkeypatch):
    # a large frame's channels are made and block-averaged band by band of rows (no
    # full-size float64 temporaries); bands of a few block rows give the very same
    # estimate as one band over the whole frame, with a mask cutting through them
    from napari_polarseg.engine.features import object_size

    intensity, dop, phase, _ = planted(32, "touching", "dop", shape=(700, 900))
    mask = np.ones(intensity.shape, bool)
    mask[100:400, 50:300] = False
    monkeypatch.setattr(object_size, "BAND_PIXELS", 1 << 40)
    whole = estimate_object_size(intensity, dop, phase, mask)
    monkeypatch.setattr(object_size, "BAND_PIXELS", 5000)
    banded = estimate_object_size(intensity, dop, phase, mask)
    assert whole.work_factor > 1
    assert banded == whole


def test_noise_helpers():
    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, 0.5, (200, 200))
    assert noise_sd(noise) == pytest.approx(0.5, rel=0.05)
    # smooth structure hardly enters the estimate
    ramp = np.add.outer(np.arange(200.0), np.arange(200.0)) / 10.0
    assert noise_sd(noise + ramp) == pytest.approx(0.5, rel=0.05)
    assert noise_sd(np.ones((10, 10))) == 0.0
    # the normalised LoG's noise energy approaches 1 / (2π σ²)
    assert noise_energy(8.0) == pytest.approx(1.0 / (2.0 * np.pi * 64.0), rel=0.05)
