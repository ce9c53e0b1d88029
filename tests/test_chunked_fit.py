"""The polarisation fit (eq. 3.14) chunk by chunk: the same maps to the bit as one
whole-image pass, in bounded memory; the normals stage likewise (issue 39)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from napari_polarseg.engine import Pipeline, SegmentParams
from napari_polarseg.engine.errors import Cancelled
from napari_polarseg.engine.physics import fresnel, polarimage
from napari_polarseg.engine.physics.fit_maps import FIT_MAP_BYTES
from napari_polarseg.engine.physics.pixel_mask import PixelMask

A4 = np.deg2rad([0, 45, 90, 135])
A7 = np.deg2rad([0, 30, 60, 90, 120, 150, 170])
MAPS = ("intensity", "dop", "phase", "residual", "invalid")


def _stack(n: int, shape: tuple[int, int], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.2, 2.0, (n, *shape))  # a few pixels with Î <= 0 too


def _fit(monkeypatch, chunk: int, *args, **kwargs) -> polarimage.PolarisationImage:
    """The fit with both chunk sizes set to ``chunk`` pixels."""
    monkeypatch.setattr(polarimage, "PLAIN_CHUNK_PIXELS", chunk)
    monkeypatch.setattr(polarimage, "FIT_CHUNK_PIXELS", chunk)
    return polarimage.polarisation_image(*args, **kwargs)


def _assert_same(a: polarimage.PolarisationImage, b: polarimage.PolarisationImage) -> None:
    for name in MAPS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert x.tobytes() == y.tobytes(), name  # to the bit, NaN and signed zeros too
    for name in ("sample_weights", "angles"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None)
        if x is not None:
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize(
    "case",
    ["plain", "uint8", "float32", "nan", "weights", "bool weights", "duplicates", "robust"],
)
def test_the_chunked_fit_equals_one_whole_image_pass_to_the_bit(monkeypatch, case):
    shape = (61, 173)  # 10553 pixels: chunks of 1000 leave a short last one
    angles, kwargs = A7, {}
    stack = _stack(7, shape)
    if case == "uint8":
        stack, angles = (stack[:4] * 100).clip(0).astype(np.uint8), A4
    elif case == "float32":
        stack = stack.astype(np.float32)
    elif case == "nan":
        stack[2, 5:9, 10:20] = np.nan
        stack[:, 7, 7] = np.inf
    elif case in ("weights", "bool weights"):
        weights = np.ones(stack.shape, dtype=bool)
        weights[1, 30:50, 50:90] = False
        weights[:5, 9, 9] = False  # too few angles left: no fit
        kwargs["weights"] = weights if case == "bool weights" else weights.astype(float)
    elif case == "duplicates":
        angles = np.deg2rad([0, 45, 90, 135, 180, 45, 60])
        kwargs["weights"] = np.where(stack > 1.9, 0.0, 1.0)
    elif case == "robust":
        kwargs.update(robust=True, weights=np.where(stack > 1.95, 0.0, 1.0))
    whole = _fit(monkeypatch, stack[0].size, stack, angles, **kwargs)  # one chunk
    for chunk in (1000, 4096):
        _assert_same(_fit(monkeypatch, chunk, stack, angles, **kwargs), whole)
    assert whole.intensity.dtype == whole.dop.dtype == np.float64


def test_bool_and_float_weights_give_the_same_maps():
    stack = _stack(4, (40, 50), seed=2)
    weights = np.ones(stack.shape, dtype=bool)
    weights[0, :10] = False
    a = polarimage.polarisation_image(stack, A4, weights=weights)
    b = polarimage.polarisation_image(stack, A4, weights=weights.astype(np.float64))
    _assert_same(a, b)
    dropped = polarimage.polarisation_image(stack, A4, weights=weights, keep_weights=False)
    assert dropped.sample_weights is None and a.sample_weights is not None
    np.testing.assert_array_equal(dropped.dop, a.dop)


def test_the_fit_holds_its_maps_and_a_few_chunks_not_whole_image_temporaries():
    shape = (800, 1000)  # 0.8 MP, camera counts as the pipeline keeps them
    stack = (_stack(4, shape, seed=3) * 100).clip(0).astype(np.uint8)
    weights = np.ones(stack.shape, dtype=bool)
    weights[2, :100, :100] = False  # the weighted chunks too
    for kwargs in ({}, {"weights": weights, "keep_weights": False}):
        tracemalloc.start()
        try:
            polarimage.polarisation_image(stack, A4, **kwargs)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        maps = FIT_MAP_BYTES * stack[0].size  # 26 MB
        # one whole-image pass held ~130 bytes a pixel (104 MB here)
        assert maps <= peak < maps + 2 * polarimage.FIT_CHUNK_PIXELS * 4 * 8 * 6, kwargs


def test_the_stage_reports_progress_and_stops_between_chunks():
    stack = (_stack(4, (300, 400), seed=4) * 100).clip(1).astype(np.uint8)
    pipe = Pipeline(stack, A4, SegmentParams())
    shares: list[float] = []
    pipe.get("polarisation", progress=shares.append)
    assert len(shares) > 2 and shares == sorted(shares) and shares[-1] == 1.0

    def stop(share: float) -> None:
        raise Cancelled("stop")

    fresh = Pipeline(stack, A4, SegmentParams())
    with pytest.raises(Cancelled):
        fresh.get("polarisation", progress=stop)
    assert fresh.cached("polarisation") is None
    # the stage's maps are the plain function's (with the pipeline's mask)
    direct = polarimage.polarisation_image(stack, A4)
    pol = pipe.get("polarisation")
    for name in MAPS[:4]:
        assert getattr(pol, name).tobytes() == getattr(direct, name).tobytes()


@pytest.mark.parametrize("model", ["diffuse", "specular"])
def test_the_normals_stage_in_chunks_equals_the_whole_image_functions(model):
    stack = _stack(4, (300, 250), seed=5)
    flags = np.zeros(stack.shape, dtype=np.uint8)
    flags[1, :20, :30] = 1  # saturated samples: the weighted fit
    pipe = Pipeline(stack, A4, SegmentParams(model=model), mask=PixelMask(flags))
    pol, nrm = pipe.get("polarisation"), pipe.get("normals")
    est = fresnel.zenith_from_dop(pol.dop, pipe.params.refractive_index, model)
    assert nrm.zenith.tobytes() == est.zenith.tobytes()
    np.testing.assert_array_equal(nrm.clamped, est.clamped)
    azimuth = fresnel.azimuth_from_phase(pol.phase, model)
    assert nrm.azimuth.tobytes() == azimuth.tobytes()
    if model == "diffuse":  # φ itself, read-only: no copy
        assert np.shares_memory(nrm.azimuth, pol.phase) and not nrm.azimuth.flags.writeable


def test_the_mask_counts_band_by_band_equal_the_whole_masks(monkeypatch):
    """``PixelMask.counts`` counts a band at a time; the counts equal those of the whole
    (H, W) masks, with and without a region, whatever the band height."""
    from napari_polarseg.engine.physics import pixel_mask

    rng = np.random.default_rng(3)
    flags = (rng.random((4, 61, 47)) < 0.05).astype(np.uint8) * rng.choice(
        [1, 2, 4, 3], (4, 61, 47)
    )
    region = rng.random((61, 47)) < 0.7
    for reg in (None, region):
        mask = PixelMask(flags.astype(np.uint8), region=reg)
        valid = np.all(flags == 0, axis=0) & (True if reg is None else reg)
        whole = {
            "valid_pixels": int(valid.sum()),
            "masked_pixels": int(valid.size - valid.sum()),
            "saturated_pixels": int(np.any(flags & 1, axis=0).sum()),
            "dark_pixels": int(np.any(flags & 2, axis=0).sum()),
            "nonfinite_pixels": int(np.any(flags & 4, axis=0).sum()),
            "outside_region_pixels": 0 if reg is None else int((~reg).sum()),
        }
        for band_pixels in (1, 47 * 5, 1 << 20):
            monkeypatch.setattr(pixel_mask, "COUNT_ROWS_PIXELS", band_pixels)
            got = mask.counts()
            assert {k: got[k] for k in whole} == whole
        assert whole["saturated_pixels"] > 0 and whole["nonfinite_pixels"] > 0
