"""Real inputs: camera mosaics, frame files, registration, robust fitting, masks, bad input.

The real polarisation-camera frames (Sony IMX250MZR, polanalyser, MIT licence) live in
``<repo>/../shared/data/polanalyser``; the tests that need them are skipped, with the path
in the reason, when that folder is absent.
"""

from __future__ import annotations

import json
import os
import struct
import tempfile
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from skimage import io as skio

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import Pipeline, PolarsegError, SegmentParams, polarisation_image
from napari_polarseg.engine.limits import (
    DEFAULT_MAX_BYTES,
    ENV_VAR,
    check_bytes,
    default_max_bytes,
    format_bytes,
    memory_limit,
    parse_bytes,
    physical_memory,
)
from napari_polarseg.engine.physics.mosaic import (
    demosaic,
    demosaic_interpolated,
    demosaic_superpixel,
    mosaic_superpixel,
    spread_flags_interpolated,
    subtract_dark,
)
from napari_polarseg.engine.physics.pixel_mask import (
    PixelMask,
    auto_saturation_level,
    validity_mask,
)
from napari_polarseg.engine.physics.polarimage import (
    angle_groups,
    average_duplicate_angles,
    duplicate_angle_frames,
)
from napari_polarseg.engine.physics.registration import register_stack
from napari_polarseg.engine.run_memory import estimate_pipeline_bytes
from napari_polarseg.engine.synthetic.scenes import make_scene

REPO = Path(__file__).resolve().parents[1]
REAL_DIR = (REPO / ".." / "shared" / "data" / "polanalyser").resolve()
REAL_FRAMES = ["camera", "carps", "fruits", "polarizer"]
LAYOUT = (90.0, 45.0, 135.0, 0.0)
#: Median ρ measured over each real frame (super-pixel demosaicing, least squares; the
#: saturated samples left out of their pixel's fit), with a tolerance band around it.
REAL_MEDIAN_RHO = {
    "camera": (0.020, 0.050),  # measured 0.034: mostly matte mat and camera body
    "carps": (0.40, 0.65),  # measured 0.520: strong reflection from the water surface
    "fruits": (0.05, 0.12),  # measured 0.080: diffuse fruit skin on a white background
    "polarizer": (0.03, 0.09),  # measured 0.053: window light, a quarter of it saturated
}

needs_real_data = pytest.mark.skipif(
    not REAL_DIR.is_dir(),
    reason="real polarisation-camera frames not found in ../shared/data/polanalyser "
    "(beside the repository; docs/data.md, 'Optional real data')",
)

#: The default memory limit as an error names it (16 GiB, less on a smaller machine).
DEFAULT_LIMIT = format_bytes(default_max_bytes())
#: The machine's physical memory, bytes.
RAM = physical_memory() or float("inf")


def real_frame(name: str) -> Path:
    return REAL_DIR / f"{name}_IMX250MZR.png"


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def sinusoid_stack(i0, rho, phi, angles_deg):
    a = np.deg2rad(np.asarray(angles_deg, dtype=float))[:, None, None]
    return i0 * (1 + rho * np.cos(2 * a - 2 * phi))


def smooth_scene(h=40, w=48, seed=0):
    """Smooth per-pixel (Î, ρ, φ) maps."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    i0 = 800 + 300 * np.sin(3 * xx + 2 * yy) + 20 * rng.random()
    rho = 0.1 + 0.2 * (xx + yy) / 2
    phi = np.mod(0.3 + 1.5 * xx - yy, np.pi)
    return i0, rho, phi


# -- real polarisation-camera frames ---------------------------------------------------------


@needs_real_data
@pytest.mark.parametrize("name", REAL_FRAMES)
def test_real_frame_demosaics_like_an_independent_decoding(name):
    raw = np.asarray(skio.imread(real_frame(name)))
    assert raw.shape == (2048, 2448) and raw.dtype == np.uint8
    data = pio.read_stack(real_frame(name), mosaic=pio.DEFAULT_MOSAIC)
    assert data.stack.shape == (4, 1024, 1224) and data.stack.dtype == np.uint8
    assert data.angles_deg.tolist() == [0.0, 45.0, 90.0, 135.0]
    # SOURCES.md: (row 0, col 0) = 90, (0, 1) = 45, (1, 0) = 135, (1, 1) = 0 degrees
    decoded = {0.0: raw[1::2, 1::2], 45.0: raw[0::2, 1::2], 90.0: raw[0::2, 0::2]}
    decoded[135.0] = raw[1::2, 0::2]
    for frame, angle in zip(data.stack, data.angles_deg, strict=True):
        np.testing.assert_array_equal(frame, decoded[angle])
    # Stokes check of the decoding: I0 + I90 = I45 + I135 up to noise and saturation
    s = data.stack.astype(float)
    unsaturated = np.all(data.stack < 255, axis=0)
    balance = (s[0] + s[2] - s[1] - s[3])[unsaturated] / (s.sum(0)[unsaturated] / 2 + 1)
    assert abs(float(np.median(balance))) < 0.05


@needs_real_data
@pytest.mark.parametrize("name", REAL_FRAMES)
def test_real_frame_dop_in_range_with_a_plausible_median(name):
    data = pio.read_stack(real_frame(name), mosaic=pio.DEFAULT_MOSAIC)
    mask = validity_mask(
        data.stack, saturation=data.metadata["saturation_level"], saturated=data.saturated
    )
    assert mask.saturation_level == 255.0
    pol = polarisation_image(data.stack, data.angles_rad, weights=mask.sample_weights)
    assert np.all(np.isfinite(pol.dop))
    assert pol.dop.min() >= 0.0 and pol.dop.max() <= 1.0
    assert np.all((pol.phase >= 0) & (pol.phase < np.pi))
    lo, hi = REAL_MEDIAN_RHO[name]
    assert lo < float(np.median(pol.dop)) < hi


@needs_real_data
def test_real_frame_interpolated_demosaic_keeps_samples_and_fills_bilinearly():
    raw = np.asarray(skio.imread(real_frame("fruits"))).astype(float)
    data = pio.read_stack(real_frame("fruits"), mosaic=LAYOUT, demosaic="interpolated")
    assert data.stack.shape == (4, 2048, 2448) and data.metadata["demosaic"] == "interpolated"
    by_angle = dict(zip(data.angles_deg.tolist(), data.stack, strict=True))
    f90 = by_angle[90.0]  # measured at (even, even)
    np.testing.assert_array_equal(f90[0::2, 0::2], raw[0::2, 0::2])
    # (even, odd): mean of left and right; (odd, even): up and down; (odd, odd): 4 diagonals
    np.testing.assert_allclose(f90[0::2, 1:-1:2], (raw[0::2, 0:-2:2] + raw[0::2, 2::2]) / 2)
    np.testing.assert_allclose(f90[1:-1:2, 0::2], (raw[0:-2:2, 0::2] + raw[2::2, 0::2]) / 2)
    diag = (raw[0:-2:2, 0:-2:2] + raw[0:-2:2, 2::2] + raw[2::2, 0:-2:2] + raw[2::2, 2::2]) / 4
    np.testing.assert_allclose(f90[1:-1:2, 1:-1:2], diag)
    # the saturated raw pixels reach every interpolated sample that uses them
    assert data.saturated.sum() >= 4 * np.count_nonzero(raw >= 255)
    pol = polarisation_image(data.stack, data.angles_rad)
    assert 0.05 < float(np.median(pol.dop)) < 0.12  # measured 0.080, as super-pixel


@needs_real_data
@pytest.mark.parametrize("name", ["camera", "carps", "polarizer"])
def test_real_frames_load_through_the_cli(tmp_path, capsys, name):
    out = tmp_path / "out"
    code, stdout, err = run(
        capsys, "segment", real_frame(name), "--mosaic", "90,45,135,0", "--out", out,
        *("--window", "64", "--degree", "2", "--segments", "2"),
    )  # fmt: skip
    assert code == 0, err
    assert tifffile.imread(out / "labels.tif").shape == (1024, 1224)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mask"]["saturation_level"] == 255
    assert summary["mask"]["saturated_pixels"] > 0  # all three have glints
    assert "saturated; see mask.tif" in stdout
    mask = tifffile.imread(out / "mask.tif")
    assert int((mask == 0).sum()) == summary["mask"]["masked_pixels"]


@needs_real_data
def test_fruits_frame_segments_end_to_end_with_the_mosaic_option(tmp_path, capsys):
    out = tmp_path / "fruits"
    code, stdout, err = run(
        capsys, "segment", real_frame("fruits"), "--mosaic", "90,45,135,0", "--out", out,
        *("--preset", "recommended", "--window", "16", "--degree", "6", "--segments", "4"),
    )  # fmt: skip
    assert code == 0, err
    assert "4 segments over 1024 x 1224 pixels" in stdout
    labels = tifffile.imread(out / "labels.tif")
    assert labels.shape == (1024, 1224) and set(np.unique(labels)) == {0, 1, 2, 3}
    dop = tifffile.imread(out / "dop.tif")
    assert dop.dtype == np.float32 and 0 <= dop.min() and dop.max() <= 1
    assert 0.05 < float(np.median(dop)) < 0.12
    residual = tifffile.imread(out / "residual.tif")
    assert residual.shape == (1024, 1224) and np.all(np.isfinite(residual))
    params = json.loads((out / "params.json").read_text())
    assert params["raw_shape"] == [2048, 2448] and params["demosaic"] == "superpixel"
    assert params["saturation_level"] == 255.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_segments"] == 4 and summary["block_grid"] == [64, 76]
    assert sum(summary["segment_pixels"]) == 1024 * 1224


# -- demosaicing, dark frames, bit depths --------------------------------------------------


def test_interpolated_demosaic_is_exact_for_linear_images_in_the_interior():
    h, w = 16, 20
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    truth = {a: 100 + 3 * a + 2.5 * yy - 1.5 * xx for a in (0.0, 45.0, 90.0, 135.0)}
    raw = np.empty((h, w))
    for cell, a in enumerate(LAYOUT):
        di, dj = divmod(cell, 2)
        raw[di::2, dj::2] = truth[a][di::2, dj::2]
    stack, angles = demosaic_interpolated(raw, LAYOUT)
    assert angles.tolist() == [0.0, 45.0, 90.0, 135.0]
    for frame, a in zip(stack, angles, strict=True):
        np.testing.assert_allclose(frame[1:-1, 1:-1], truth[a][1:-1, 1:-1], atol=1e-9)
    # super-pixel decoding of the same raw frame is a sub-sampling of the measured sites
    half, _ = demosaic(raw, LAYOUT, "superpixel")
    np.testing.assert_array_equal(half[0], raw[1::2, 1::2])
    with pytest.raises(PolarsegError, match="demosaic method"):
        demosaic(raw, LAYOUT, "nearest")
    with pytest.raises(PolarsegError, match="even height and width, got 15 x 20"):
        demosaic_interpolated(raw[:-1])


def test_interpolated_and_superpixel_agree_on_a_smooth_scene():
    i0, rho, phi = smooth_scene(64, 80)
    full = sinusoid_stack(i0, rho, phi, sorted(LAYOUT))
    raw = np.empty(i0.shape)
    for cell, a in enumerate(LAYOUT):
        di, dj = divmod(cell, 2)
        raw[di::2, dj::2] = full[sorted(LAYOUT).index(a)][di::2, dj::2]
    stack, angles = demosaic_interpolated(raw, LAYOUT)
    pol = polarisation_image(stack, np.deg2rad(angles))
    inner = (slice(2, -2), slice(2, -2))
    np.testing.assert_allclose(pol.dop[inner], rho[inner], atol=0.01)
    np.testing.assert_allclose(pol.intensity[inner], i0[inner], rtol=0.01)


def test_saturation_flags_follow_the_demosaicing():
    raw = np.full((8, 8), 100, np.uint8)
    raw[2, 2] = 255  # a 90-degree site (even, even)
    flags = spread_flags_interpolated(raw >= 255, LAYOUT)
    assert flags.shape == (4, 8, 8)
    assert flags[2].sum() == 9 and flags[[0, 1, 3]].sum() == 0  # 90 degrees is index 2
    assert flags[2, 1:4, 1:4].all()
    data_sp = demosaic_superpixel(raw >= 255, LAYOUT)[0]
    assert data_sp.sum() == 1 and data_sp[2, 1, 1]


@pytest.mark.parametrize(
    ("dtype", "bits", "level"),
    [
        (np.uint8, None, 255),
        (np.uint16, None, 65535),
        (np.uint16, 12, 4095),
        (np.float32, None, None),
    ],
)
def test_mosaic_bit_depths_and_float_with_saturation(tmp_path, dtype, bits, level):
    assert auto_saturation_level(np.dtype(dtype), bits) == level
    i0, rho, phi = smooth_scene(12, 16)
    top = 250.0 if dtype == np.uint8 else 4000.0
    stack = sinusoid_stack(i0 / i0.max() * top * 0.5, rho, phi, sorted(LAYOUT))
    raw = mosaic_superpixel(stack.astype(dtype), LAYOUT)
    if level is not None:
        raw[0, 0] = level  # one saturated 90-degree sample
    path = tmp_path / "raw.tif"
    tifffile.imwrite(path, raw, photometric="minisblack")
    saturation = level if bits else "auto"
    data = pio.read_stack(path, mosaic=LAYOUT, saturation=saturation)
    assert data.stack.dtype == np.dtype(dtype)
    if level is None:
        assert data.saturated is None and data.metadata["saturation_level"] is None
    else:
        assert data.metadata["saturation_level"] == level
        assert data.saturated.sum() == 1 and data.saturated[2, 0, 0]


def test_dark_frame_and_offset_are_subtracted_after_saturation_is_found(tmp_path):
    i0, rho, phi = smooth_scene(10, 12)
    stack = sinusoid_stack(i0 / 10, rho, phi, sorted(LAYOUT))
    dark = np.full((20, 24), 7.0)
    dark[0, 1] = 30.0
    raw = np.clip(mosaic_superpixel(stack, LAYOUT) + dark, 0, 255).astype(np.uint8)
    raw[1, 1] = 255
    path, dark_path = tmp_path / "raw.png", tmp_path / "dark.png"
    skio.imsave(path, raw, check_contrast=False)
    skio.imsave(dark_path, dark.astype(np.uint8), check_contrast=False)
    data = pio.read_stack(path, mosaic=LAYOUT, dark=dark_path, offset=2)
    assert data.stack.dtype == np.float64
    assert data.metadata["dark_frame"] == str(dark_path) and data.metadata["offset"] == 2.0
    expected = demosaic_superpixel(np.maximum(raw - dark - 2.0, 0), LAYOUT)[0]
    np.testing.assert_allclose(data.stack, expected)
    assert data.saturated[0, 0, 0]  # the raw 255 at (1, 1) is the 0-degree sample of (0, 0)
    # subtract_dark on its own
    np.testing.assert_array_equal(subtract_dark(np.array([[1.0, 9.0]]), offset=3), [[0.0, 6.0]])
    with pytest.raises(PolarsegError, match="dark frame is 2 x 2 pixels but the frames are 1 x 2"):
        subtract_dark(np.ones((1, 2)), np.ones((2, 2)))


# -- stacks from frame files ----------------------------------------------------------------


def test_list_of_files_with_angles_in_names_or_given(tmp_path):
    i0, rho, phi = smooth_scene(10, 12)
    angles = [0, 45, 90, 135]
    stack = np.round(sinusoid_stack(i0, rho, phi, angles)).astype(np.uint16)
    files = []
    for k, a in enumerate(angles):
        f = tmp_path / f"shot{k + 1}_{a}.tif"
        tifffile.imwrite(f, stack[k], photometric="minisblack")
        files.append(f)
    data = pio.read_stack(files[::-1])  # angles from the names, sorted
    assert data.angles_deg.tolist() == [0.0, 45.0, 90.0, 135.0]
    np.testing.assert_array_equal(data.stack, stack)
    assert data.metadata["format"] == "files" and data.metadata["angles_from"] == "names"
    given = pio.read_stack(files[::-1], angles_deg=[10, 20, 30, 40])  # order as given
    np.testing.assert_array_equal(given.stack, stack[::-1])
    assert given.angles_deg.tolist() == [10.0, 20.0, 30.0, 40.0]
    with pytest.raises(PolarsegError, match="4 files but 3 angles"):
        pio.read_stack(files, angles_deg=[0, 60, 120])


def test_imagej_slice_labels_carry_the_angles(tmp_path):
    i0, rho, phi = smooth_scene(8, 9)
    stack = np.round(sinusoid_stack(i0, rho, phi, [0, 60, 120])).astype(np.uint16)
    path = tmp_path / "fiji.tif"
    tifffile.imwrite(path, stack, imagej=True, metadata={"Labels": ["pol_000", "pol_060", "p120"]})
    data = pio.read_stack(path)
    assert data.angles_deg.tolist() == [0.0, 60.0, 120.0]
    assert data.metadata["angles_from"] == "imagej labels"


# -- registration ---------------------------------------------------------------------------

SHIFTS = np.array(
    [
        [0, 0],
        [1.37, -0.62],
        [-2.21, 0.43],
        [0.58, 1.83],
        [-0.94, -1.51],
        [2.46, 2.08],
        [0.27, -2.71],
    ]
)


def test_registration_recovers_known_synthetic_shifts_of_make_scene():
    scene = make_scene("leaves", shape=(96, 104), shifts=SHIFTS, seed=3)
    _, estimated = register_stack(scene.stack)
    # make_scene moves frame k's content by SHIFTS[k]; the correction is the opposite
    np.testing.assert_allclose(estimated, -SHIFTS, atol=0.2)


def test_cli_register_reports_the_shifts_of_a_misaligned_stack(tmp_path, capsys):
    scene = make_scene("fruit", shape=(96, 104), shifts=SHIFTS, seed=4)
    path = tmp_path / "moved.tif"
    pio.write_stack_tiff(path, scene.stack, scene.angles_deg)
    out = tmp_path / "out"
    code, stdout, err = run(
        capsys, "segment", path, "--out", out, "--register", "--window", "12", "--degree", "4"
    )
    assert code == 0, err
    assert "registered 7 frames to frame 0, largest shift" in stdout
    registration = json.loads((out / "params.json").read_text())["registration"]
    assert registration["ran"] is True and registration["reference_frame"] == 0
    np.testing.assert_allclose(registration["shifts_px"], -SHIFTS, atol=0.2)
    # without --register nothing is moved and nothing is reported
    code, stdout, _ = run(capsys, "segment", path, "--out", tmp_path / "b", "--degree", "4")
    assert code == 0 and "registered" not in stdout
    assert json.loads((tmp_path / "b" / "params.json").read_text())["registration"]["ran"] is False


def test_registration_moves_the_mask_with_the_frames():
    flags = np.zeros((3, 10, 10), np.uint8)
    flags[1, 5, 5] = 1  # saturated sample in frame 1
    mask = PixelMask(flags, None, 255.0, 0.0)
    moved = mask.shifted(np.array([[0, 0], [1.5, -2.0], [0, 0]]))
    hit = np.argwhere(moved.flags[1])
    assert {(6, 3), (7, 3)} <= set(map(tuple, hit)) and not moved.flags[1, 5, 5]
    assert moved.saturated.sum() == len(hit)


# -- robust fit ---------------------------------------------------------------------------

ANGLES7 = [0, 30, 60, 90, 120, 150, 170]


def outlier_stack(seed=0, h=30, w=36):
    rng = np.random.default_rng(seed)
    i0 = rng.uniform(500, 1500, (h, w))
    rho = rng.uniform(0.05, 0.5, (h, w))
    phi = rng.uniform(0, np.pi, (h, w))
    stack = sinusoid_stack(i0, rho, phi, ANGLES7) + rng.normal(0, 3, (7, h, w))
    bad = stack.copy()
    bad[3, : h // 2] += 600  # a glint / moving object in one frame, top half
    return bad, stack, (i0, rho, phi)


@pytest.mark.parametrize("loss", ["tukey", "huber"])
def test_robust_fit_resists_an_outlying_frame(loss):
    bad, _, (i0, rho, phi) = outlier_stack()
    a = np.deg2rad(ANGLES7)
    lsq = polarisation_image(bad, a)
    rob = polarisation_image(bad, a, robust=True, loss=loss)
    top = slice(0, 15)
    lsq_err = np.median(np.abs(lsq.dop - rho)[top])
    rob_err = np.median(np.abs(rob.dop - rho)[top])
    assert lsq_err > 0.05
    assert rob_err < (0.01 if loss == "tukey" else 0.02)
    if loss == "tukey":  # the wrong frame is rejected outright where it is wrong
        assert np.median(rob.sample_weights[3, top]) == 0.0
        assert np.median(rob.sample_weights[3, 15:]) > 0.9
    # the residual map shows where a frame disagrees
    assert np.median(lsq.residual[top]) > 20 * np.median(lsq.residual[15:])
    # on clean rows the robust fit stays close to least squares
    np.testing.assert_allclose(rob.dop[15:], lsq.dop[15:], atol=0.01)


def test_robust_fit_with_four_angles_equals_least_squares():
    i0, rho, phi = smooth_scene(8, 8)
    a = np.deg2rad([0, 45, 90, 135])
    stack = sinusoid_stack(i0, rho, phi, [0, 45, 90, 135])
    np.testing.assert_allclose(
        polarisation_image(stack, a, robust=True).dop, polarisation_image(stack, a).dop
    )


def test_fit_parameter_reaches_the_pipeline_and_its_cache():
    bad, _, (_, rho, _) = outlier_stack()
    pipe = Pipeline(bad, np.deg2rad(ANGLES7), SegmentParams(window=6, degree=2, n_segments=2))
    lsq = pipe.run()
    assert pipe.stale_stages() == []
    robust_params = pipe.params.replace(fit="robust")
    stale = pipe.stale_stages(params=robust_params)
    assert "polarisation" in stale and "normals" in stale
    robust = pipe.run(robust_params)
    assert robust.summary()["fit"] == "robust"
    assert np.median(np.abs(robust.dop - rho)[:15]) < np.median(np.abs(lsq.dop - rho)[:15]) / 5
    with pytest.raises(PolarsegError, match="fit must be one of lsq, robust"):
        SegmentParams(fit="lm")


def test_cli_fit_robust_and_residual_map(tmp_path, capsys):
    bad, _, (_, rho, _) = outlier_stack()
    path = tmp_path / "s.tif"
    pio.write_stack_tiff(path, bad.astype(np.float32), ANGLES7)
    fast = ["--window", "6", "--degree", "2", "--segments", "2"]
    for fit in ("lsq", "robust"):
        code, _, err = run(capsys, "segment", path, "--out", tmp_path / fit, "--fit", fit, *fast)
        assert code == 0, err
    dop = {f: tifffile.imread(tmp_path / f / "dop.tif") for f in ("lsq", "robust")}
    assert (
        np.median(np.abs(dop["robust"] - rho)[:15])
        < 0.01
        < np.median(np.abs(dop["lsq"] - rho)[:15])
    )
    residual = tifffile.imread(tmp_path / "lsq" / "residual.tif")
    assert np.median(residual[:15]) > 20 * np.median(residual[15:])
    assert json.loads((tmp_path / "robust" / "params.json").read_text())["params"]["fit"] == (
        "robust"
    )


# -- repeated angles ------------------------------------------------------------------------


def test_repeated_angles_are_averaged_before_the_fit():
    assert angle_groups(np.deg2rad([0, 45, 90, 180, 45.0000001, 135])).tolist() == [
        0, 1, 2, 0, 1, 3,
    ]  # fmt: skip
    assert duplicate_angle_frames(np.deg2rad([0, 45, 90, 180, 45, 135])) == [[0, 3], [1, 4]]
    i0, rho, phi = smooth_scene(6, 7)
    angles = [0, 45, 90, 135, 180, 180]
    stack = sinusoid_stack(i0, rho, phi, angles)
    stack[4] += 30.0  # the repeated shots differ (noise, drift)
    stack[5] -= 10.0
    merged, merged_angles, counts = average_duplicate_angles(stack, np.deg2rad(angles))
    assert merged.shape[0] == 4
    np.testing.assert_allclose(merged[0], (stack[0] + stack[4] + stack[5]) / 3)
    np.testing.assert_allclose(counts[:, 0, 0], [3, 1, 1, 1])  # the average weighs 3 shots
    p = polarisation_image(stack, np.deg2rad(angles))
    # ... so the fit equals ordinary least squares over all six frames
    a = np.deg2rad(angles)
    design = np.stack([np.ones_like(a), np.cos(2 * a), np.sin(2 * a)], axis=1)
    coef = np.linalg.lstsq(design, stack.reshape(6, -1), rcond=None)[0]
    np.testing.assert_allclose(p.intensity.ravel(), coef[0], rtol=1e-10)
    np.testing.assert_allclose(p.dop.ravel(), np.hypot(coef[1], coef[2]) / coef[0], atol=1e-12)
    result = Pipeline(stack, np.deg2rad(angles), SegmentParams(window=3, degree=1)).run()
    assert result.summary()["averaged_duplicate_angles"] == [[0, 4, 5]]


def test_cli_says_repeated_angles_were_averaged(tmp_path, capsys):
    i0, rho, phi = smooth_scene(30, 30)
    angles = [0, 45, 90, 135, 90]
    stack = sinusoid_stack(i0, rho, phi, angles)
    stack[4] *= 1.05
    path = tmp_path / "rep.tif"
    pio.write_stack_tiff(path, stack.astype(np.float32), angles)
    out = tmp_path / "out"
    code, stdout, err = run(
        capsys, "segment", path, "--out", out, "--window", "10", "--degree", "2"
    )
    assert code == 0, err
    assert "frames 2, 4 (90 and 90 degrees) are one polariser state: averaged" in stdout
    params = json.loads((out / "params.json").read_text())
    assert params["duplicate_angles"] == [
        {"angle_deg": 90.0, "frames": [2, 4], "handling": "averaged before the fit"}
    ]
    assert json.loads((out / "summary.json").read_text())["averaged_duplicate_angles"] == [[2, 4]]


# -- saturation, darkness and user masks ----------------------------------------------------


def test_validity_mask_flags_counts_and_region():
    stack = np.full((3, 4, 5), 100, np.uint8)
    stack[0, 0, 0] = 255  # saturated
    stack[1, 1, 1] = 0  # black
    stack[2, 2, 2] = 255
    stack[2, 2, 3] = 3
    region = np.ones((4, 5), bool)
    region[3] = False
    mask = validity_mask(stack, region=region, dark_level=5)
    counts = mask.counts()
    assert counts == {
        "valid_pixels": 20 - 4 - 5,
        "masked_pixels": 9,
        "saturated_pixels": 2,
        "dark_pixels": 2,
        "nonfinite_pixels": 0,
        "outside_region_pixels": 5,
        "saturation_level": 255.0,
        "dark_level": 5.0,
    }
    assert not mask.valid[0, 0] and not mask.valid[2, 3] and mask.valid[0, 1]
    assert validity_mask(stack, saturation=None, dark_level=None).valid.all()
    floats = np.ones((3, 2, 2))
    floats[0, 0, 0] = np.nan
    assert validity_mask(floats).counts()["nonfinite_pixels"] == 1
    assert validity_mask(floats).saturation_level is None
    with pytest.raises(PolarsegError, match="the mask is 2 x 2 pixels but the frames are 4 x 5"):
        validity_mask(stack, region=np.ones((2, 2)))


def test_pipeline_leaves_masked_pixels_out_of_the_features():
    i0, rho, phi = smooth_scene(40, 40)
    stack = np.round(sinusoid_stack(i0 / 6, rho, phi, [0, 45, 90, 135])).astype(np.uint8)
    stack[:, :, :5] = 255  # a saturated strip
    params = SegmentParams(window=10, degree=2, n_segments=2)
    angles = np.deg2rad([0, 45, 90, 135])
    result = Pipeline(stack, angles, params).run()
    counts = result.summary()["mask"]
    assert counts["saturated_pixels"] == 40 * 5 and counts["saturation_level"] == 255.0
    assert not result.valid[:, :5].any() and result.valid[:, 5:].all()
    # the features of a block do not depend on its masked pixels' values
    other = stack.copy()
    other[:, :, :5] = 255
    other[0, :, :5] = 254  # no longer saturated in frame 0 only: still masked
    again = Pipeline(other, angles, params).run()
    assert not again.valid[:, :5].any()
    np.testing.assert_allclose(again.coefficients, result.coefficients)
    # a user region restricts the fit and the features the same way
    region = np.ones((40, 40), bool)
    region[30:] = False
    masked = Pipeline(stack, angles, params, mask=region).run()
    assert masked.summary()["mask"]["outside_region_pixels"] == 400
    assert not masked.valid[30:].any()
    assert masked.mean_reconstruction_error == pytest.approx(
        float(np.mean(masked.reconstruction_error[masked.valid]))
    )


def test_cli_mask_and_saturation_options(tmp_path, capsys):
    i0, rho, phi = smooth_scene(40, 44)
    stack = np.round(sinusoid_stack(i0 * 3, rho, phi, [0, 45, 90, 135])).astype(np.uint16)
    stack[2, 10, 10] = 4095  # saturated for a 12-bit camera stored in 16 bits
    path = tmp_path / "s.tif"
    pio.write_stack_tiff(path, stack, [0, 45, 90, 135])
    region = np.zeros((40, 44), np.uint8)
    region[:, :30] = 3  # a labels layer: non-zero = segment here
    mask_path = tmp_path / "region.tif"
    tifffile.imwrite(mask_path, region)
    out = tmp_path / "out"
    fast = ["--window", "10", "--degree", "2", "--segments", "2"]
    code, stdout, err = run(
        capsys, "segment", path, "--out", out, "--mask", mask_path, "--saturation", "4095", *fast
    )
    assert code == 0, err
    assert "1 saturated, 560 outside the mask; see mask.tif" in stdout
    summary = json.loads((out / "summary.json").read_text())["mask"]
    assert summary["saturated_pixels"] == 1 and summary["outside_region_pixels"] == 560
    assert summary["saturation_level"] == 4095
    used = tifffile.imread(out / "mask.tif")
    assert used.dtype == np.uint8 and used.shape == (40, 44)
    assert not used[:, 30:].any() and used[10, 10] == 0 and used[:, :30].sum() == 40 * 30 - 1
    params = json.loads((out / "params.json").read_text())
    assert params["mask_file"] == str(mask_path.resolve()) and params["saturation_level"] == 4095
    # the written mask.tif can be given back as --mask
    code, _, err = run(capsys, "segment", path, "--out", tmp_path / "b", "--mask", out / "mask.tif")
    assert code == 0, err
    # by default uint16 saturates at 65535 only; 'none' switches the check off
    code, stdout, _ = run(capsys, "segment", path, "--out", tmp_path / "c", *fast)
    assert code == 0 and "left out" not in stdout
    code, _, _ = run(capsys, "segment", path, "--out", tmp_path / "d", "--saturation", "none")
    assert (
        json.loads((tmp_path / "d" / "summary.json").read_text())["mask"]["saturation_level"]
        is None
    )


def test_mosaic_mask_may_be_given_at_raw_size(tmp_path, capsys):
    i0, rho, phi = smooth_scene(30, 32)
    raw = mosaic_superpixel(np.round(sinusoid_stack(i0, rho, phi, sorted(LAYOUT))), LAYOUT)
    path = tmp_path / "raw.tif"
    tifffile.imwrite(path, raw.astype(np.uint16), photometric="minisblack")
    region = np.ones((60, 64), np.uint8)
    region[:20] = 0
    region[21, 5] = 0
    skio.imsave(tmp_path / "m.png", region * 255, check_contrast=False)
    keep = pio.read_mask(tmp_path / "m.png", (30, 32), raw_shape=(60, 64))
    assert keep.shape == (30, 32) and not keep[:10].any() and not keep[10, 2] and keep[11:].all()
    out = tmp_path / "out"
    code, _, err = run(
        capsys, "segment", path, "--mosaic", "90,45,135,0", "--mask", tmp_path / "m.png",
        "--out", out, "--window", "8", "--degree", "2", "--segments", "2",
    )  # fmt: skip
    assert code == 0, err
    assert json.loads((out / "summary.json").read_text())["mask"]["outside_region_pixels"] == 321


def test_cli_dark_frame_and_interpolated_demosaic(tmp_path, capsys):
    i0, rho, phi = smooth_scene(24, 28)
    raw = mosaic_superpixel(sinusoid_stack(i0 / 8, rho, phi, sorted(LAYOUT)), LAYOUT) + 12
    path, dark = tmp_path / "raw.png", tmp_path / "dark.png"
    skio.imsave(path, np.round(raw).astype(np.uint8), check_contrast=False)
    skio.imsave(dark, np.full(raw.shape, 12, np.uint8), check_contrast=False)
    out = tmp_path / "out"
    code, _, err = run(
        capsys, "segment", path, "--mosaic", "90,45,135,0", "--demosaic", "interpolated",
        "--dark-frame", dark, "--out", out, "--window", "8", "--degree", "2", "--segments", "2",
    )  # fmt: skip
    assert code == 0, err
    intensity = tifffile.imread(out / "intensity.tif")
    assert intensity.shape == (48, 56)  # full resolution
    inner = (slice(4, -4), slice(4, -4))
    expect = np.kron(i0 / 8, np.ones((2, 2)))  # smooth: close to the super-pixel truth
    np.testing.assert_allclose(intensity[inner], expect[inner], rtol=0.05, atol=1.5)
    params = json.loads((out / "params.json").read_text())
    assert params["demosaic"] == "interpolated" and params["dark_frame"] == str(dark.resolve())


# -- memory limits ------------------------------------------------------------------------


def test_memory_limit_and_estimate(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    # 16 GiB, or three quarters of the machine's memory when that is less
    assert memory_limit() == default_max_bytes() == min(DEFAULT_MAX_BYTES, 0.75 * RAM) // 1
    assert DEFAULT_MAX_BYTES == 16 * 2**30
    monkeypatch.setenv(ENV_VAR, "512MiB")
    assert memory_limit() == 512 * 2**20
    assert parse_bytes("2G") == 2 * 2**30 and parse_bytes("3e9") == 3_000_000_000
    with pytest.raises(PolarsegError, match="positive number of bytes"):
        parse_bytes("lots")
    small = estimate_pipeline_bytes((4, 100, 100), SegmentParams(window=10, degree=4))
    big = estimate_pipeline_bytes((4, 2000, 2000), SegmentParams(window=2, degree=40))
    assert small < 2**28 < 2**34 < big  # a million blocks of 1681 coefficients
    with pytest.raises(PolarsegError, match=r"x would need 1\.0 KiB of memory, more than"):
        check_bytes(1024, "x", limit=100)


# -- property-based: random files to the reader and the pipeline ----------------------------

DTYPES = [np.uint8, np.uint16, np.int16, np.int32, np.float32, np.float64, np.bool_]


def _values(draw, shape, dtype, kind):
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    if kind == "constant":
        data = np.full(shape, draw(st.integers(0, 200)), dtype=float)
    elif kind == "zeros":
        data = np.zeros(shape)
    elif kind == "negative":
        data = rng.normal(0, 50, shape)
    elif kind == "huge":
        data = rng.random(shape) * 1e38
    else:
        scale = draw(st.sampled_from([1.0, 255.0, 4095.0, 65535.0]))
        if np.dtype(dtype).kind in "iu":
            scale = min(max(scale, 255.0), float(np.iinfo(dtype).max))
        data = rng.random(shape) * scale
    with np.errstate(invalid="ignore", over="ignore"):
        data = data.astype(dtype) if np.dtype(dtype).kind != "b" else data > 0.5
    if np.dtype(dtype).kind == "f" and kind in ("with_nan", "with_inf"):
        holes = rng.random(shape) < draw(st.sampled_from([0.05, 0.5, 1.0]))
        data[holes] = np.nan if kind == "with_nan" else np.inf
    return data


@st.composite
def random_inputs(draw):
    """A random input case; half of them well formed, so the pipeline runs on many."""
    kinds = ["tiff", "npz", "npy", "folder", "files", "mosaic", "garbage", "cut"]
    well_formed = draw(st.booleans())
    if well_formed:
        kind = draw(st.sampled_from(kinds[:6]))
        n = draw(st.integers(3, 7))
        h, w = draw(st.integers(3, 14)), draw(st.integers(3, 14))
        values = draw(st.sampled_from(["random", "random", "random", "with_nan", "constant"]))
        start = draw(st.sampled_from([0.0, 10.0, 90.0]))
        angles = (start + np.arange(n) * 180.0 / draw(st.sampled_from([n, n - 1]))).tolist()
    else:
        kind = draw(st.sampled_from(kinds))
        n = draw(st.integers(1, 6))
        h, w = draw(st.integers(1, 10)), draw(st.integers(1, 10))
        values = draw(
            st.sampled_from(["random", "constant", "zeros", "with_nan", "with_inf", "negative"])
        )
        pool = st.sampled_from([0.0, 22.5, 30.0, 45.0, 60.0, 90.0, 120.0, 135.0, 180.0, 270.0])
        angles = draw(st.lists(pool, min_size=max(n - 1, 1), max_size=n + 1))
    dtype = draw(st.sampled_from(DTYPES))
    if values == "random" and draw(st.integers(0, 9)) == 0:
        values = "huge"
    give_angles = draw(st.booleans())
    data = _values(draw, (n, h, w), dtype, values)
    raw = _values(draw, (2 * h + draw(st.integers(0, int(not well_formed))), 2 * w), dtype, values)
    params = {
        "window": draw(st.integers(1, 6 if not well_formed else 4)),
        "degree": draw(st.integers(0, 3)),
        "n_segments": draw(st.integers(1, 3)),
        "coefficients": draw(st.sampled_from(["thesis", "ridge"])),
        "features": draw(st.sampled_from(["thesis", "zonal", "energy"])),
        "scale_mode": draw(st.sampled_from(["absolute", "median"])),
        "spatial_radius": draw(st.sampled_from([0.0, 1.5])),
        "min_segment_blocks": draw(st.integers(1, 2)),
        "fit": draw(st.sampled_from(["lsq", "robust"])),
    }
    garbage = draw(st.binary(min_size=0, max_size=64))
    suffix = draw(st.sampled_from([".tif", ".npz", ".npy", ".png"]))
    cut = draw(st.floats(0.05, 0.95))
    return kind, data, raw, angles, give_angles, params, garbage, suffix, cut


def _png_safe(frame):
    if frame.dtype in (np.uint8, np.uint16):
        return frame
    return np.clip(np.nan_to_num(frame.astype(float)), 0, 255).astype(np.uint8)


def _write(folder: Path, case) -> tuple[object, dict]:
    kind, data, raw, angles, give_angles, _, garbage, suffix, cut = case
    kw: dict = {"angles_deg": angles} if give_angles else {}
    if kind == "tiff":
        path = folder / "s.tif"
        tifffile.imwrite(path, data, photometric="minisblack", metadata={"angles": angles})
    elif kind == "npz":
        path = folder / "s.npz"
        np.savez(path, stack=data, angles=np.asarray(angles))
    elif kind == "npy":
        path = folder / "s.npy"
        np.save(path, data)
    elif kind in ("folder", "files"):
        path = folder / "frames"
        path.mkdir()
        files = []
        for k, frame in enumerate(data):
            a = angles[k % len(angles)]
            f = path / f"f{k}_{a:g}.png"
            skio.imsave(f, _png_safe(frame), check_contrast=False)
            files.append(f)
        path = files if kind == "files" else path
    elif kind == "mosaic":
        path = folder / "raw.tif"
        tifffile.imwrite(path, raw, photometric="minisblack")
        kw = {"mosaic": LAYOUT}
    elif kind == "garbage":
        path = folder / f"g{suffix}"
        path.write_bytes(garbage)
    else:  # a truncated good file
        good = folder / f"good{suffix}"
        if suffix == ".tif":
            tifffile.imwrite(good, data, photometric="minisblack", metadata={"angles": angles})
        elif suffix == ".npz":
            np.savez(good, stack=data, angles=np.asarray(angles))
        elif suffix == ".npy":
            np.save(good, data)
        else:
            skio.imsave(good, _png_safe(raw[: raw.shape[0] // 2 * 2]), check_contrast=False)
            kw = {"mosaic": LAYOUT}
        content = good.read_bytes()
        path = folder / f"cut{suffix}"
        path.write_bytes(content[: int(len(content) * cut)])
    return path, kw


def _gist(exc: Exception) -> str:
    """The error message without paths and numbers, to group the outcomes."""
    text = str(exc).split(": ", 1)[-1] if os.sep in str(exc).split(": ", 1)[0] else str(exc)
    return " ".join(w for w in text.split()[:6] if not any(c.isdigit() for c in w))


@settings(
    max_examples=100,
    deadline=5000,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(case=random_inputs())
def test_random_inputs_either_work_or_raise_polarseg_error(case):
    with tempfile.TemporaryDirectory() as tmp:
        path, kw = _write(Path(tmp), case)
        try:
            data = pio.read_stack(path, **kw)
        except PolarsegError as exc:
            assert "\n" not in str(exc) and str(exc)
            event(f"reader refused: {_gist(exc)}")
            return
        assert data.stack.ndim == 3 and data.angles_deg.size == data.stack.shape[0]
        try:
            params = SegmentParams(**case[5])
            result = Pipeline(data.stack, data.angles_rad, params).run()
        except PolarsegError as exc:
            assert "\n" not in str(exc) and str(exc)
            event(f"pipeline refused: {_gist(exc)}")
            return
        event("segmented")
        assert result.labels.shape == data.stack.shape[1:]
        assert np.all((result.dop >= 0) & (result.dop <= 1))
        assert np.all(np.isfinite(result.intensity))


@settings(max_examples=60, deadline=5000, suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(3, 8),
    shape=st.tuples(st.integers(2, 16), st.integers(2, 16)),
    dtype=st.sampled_from(DTYPES),
    seed=st.integers(0, 2**16),
    nan_share=st.sampled_from([0.0, 0.0, 0.02, 0.3]),
    region_share=st.sampled_from([None, 0.1, 0.7]),
    window=st.integers(1, 5),
    degree=st.integers(0, 4),
    k=st.integers(1, 4),
    fit=st.sampled_from(["lsq", "robust"]),
    repeat=st.booleans(),
)
def test_random_stacks_through_the_pipeline(
    n, shape, dtype, seed, nan_share, region_share, window, degree, k, fit, repeat
):
    rng = np.random.default_rng(seed)
    angles = np.linspace(0, np.pi, n, endpoint=False) + rng.uniform(0, 0.1)
    if repeat:
        angles[-1] = angles[0] + np.pi  # the same polariser state twice
    stack = rng.uniform(0, 1.2, (n, *shape)) * (255 if np.dtype(dtype).kind in "iub" else 1)
    stack = stack.astype(dtype) if np.dtype(dtype).kind != "b" else stack > 0.5
    if np.dtype(dtype).kind == "f" and nan_share:
        stack[rng.random(stack.shape) < nan_share] = np.nan
    region = None if region_share is None else rng.random(shape) < region_share
    params = SegmentParams(window=window, degree=degree, n_segments=k, fit=fit)
    try:
        result = Pipeline(stack, angles, params, mask=region).run()
    except PolarsegError as exc:
        assert "\n" not in str(exc) and str(exc)
        event(f"refused: {_gist(exc)}")
        return
    event("segmented")
    assert result.labels.shape == shape and result.valid.shape == shape
    assert np.all((result.dop >= 0) & (result.dop <= 1)) and np.all(np.isfinite(result.dop))
    counts = result.summary()["mask"]
    assert counts["valid_pixels"] + counts["masked_pixels"] == shape[0] * shape[1]
    assert not np.any(result.valid & (region == 0)) if region is not None else True


# -- bad input through the command line: exit code 2 and one line naming the problem --------


def _tif(t, stack, angles=(0, 45, 90, 135), name="s.tif"):
    path = t / name
    pio.write_stack_tiff(path, np.asarray(stack), list(angles))
    return path


def _good(h=30, w=32, angles=(0, 45, 90, 135)):
    i0, rho, phi = smooth_scene(h, w)
    return sinusoid_stack(i0, rho, phi, angles).astype(np.float32)


def _truncated_png(t):
    path = t / "raw.png"
    skio.imsave(path, np.random.default_rng(0).integers(0, 255, (64, 64), np.uint8))
    content = path.read_bytes()
    path.write_bytes(content[: len(content) // 2])
    return [path, "--mosaic", "90,45,135,0"]


def _truncated_npz(t):
    path = t / "s.npz"
    np.savez(path, stack=_good(), angles=[0, 45, 90, 135])
    content = path.read_bytes()
    path.write_bytes(content[: len(content) // 2])
    return [path]


def _with_frame(t, k, value):
    stack = _good()
    stack[k] = value
    return [_tif(t, stack)]


def _partial_nan(t):
    stack = _good()
    stack[1, :4, :4] = np.nan
    return [_tif(t, stack), "--window", "8", "--degree", "2"]


def _negative(t):
    stack = _good()
    stack[2, 5, 6] = -3.5
    return [_tif(t, stack)]


def _frame_files_of_different_sizes(t):
    files = []
    for a, shape in ((0, (20, 30)), (60, (20, 30)), (120, (21, 30))):
        f = t / f"p_{a}.tif"
        tifffile.imwrite(f, np.random.default_rng(a).integers(1, 200, shape, np.uint8))
        files.append(f)
    return files


def _absurd_npy(t):
    path = t / "huge.npy"
    with open(path, "wb") as handle:
        np.lib.format.write_array_header_2_0(
            handle, {"descr": "<u2", "fortran_order": False, "shape": (19, 200000, 300000)}
        )
    return [path, "--angles", ",".join(str(a) for a in range(0, 190, 10))]


def _absurd_png(t):
    def chunk(kind, body):
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", 120000, 90000, 8, 0, 0, 0, 0)
    body = chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 100)) + chunk(b"IEND", b"")
    path = t / "huge.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + body)
    return [path, "--mosaic", "90,45,135,0"]


def _tiny_window_on_a_large_image(t):
    # the thesis method: the memory estimate counts the blocks of the methods that cut them
    args = ["--method", "thesis", "--window", "1", "--degree", "60"]
    return [_tif(t, _good(h=400, w=400)), *args]


def _mask_of_another_size(t):
    tifffile.imwrite(t / "m.tif", np.ones((10, 10), np.uint8))
    return [_tif(t, _good()), "--mask", t / "m.tif"]


def _everything_masked(t):
    tifffile.imwrite(t / "m.tif", np.zeros((30, 32), np.uint8))
    return [_tif(t, _good()), "--mask", t / "m.tif"]


def _dark_frame_of_another_size(t):
    skio.imsave(t / "dark.png", np.zeros((5, 5), np.uint8), check_contrast=False)
    return [_tif(t, _good()), "--dark-frame", t / "dark.png"]


BAD_REAL_INPUTS = {
    # case: (builder of the arguments after "segment", words the error line must contain)
    "truncated PNG mosaic": (_truncated_png, "raw.png: cannot read the image"),
    "truncated npz": (_truncated_npz, "s.npz: cannot read the NumPy file"),
    "a frame entirely NaN": (
        lambda t: _with_frame(t, 2, np.nan),
        "s.tif: frame 2 (90 degrees) has no finite values",
    ),
    "infinite values only": (
        lambda t: [_tif(t, np.full((4, 6, 6), np.inf, np.float32))],
        "s.tif: the data has no finite values",
    ),
    "all-constant frames": (
        lambda t: [_tif(t, np.full((4, 30, 32), 17, np.uint8))],
        "s.tif: frame 0 (0 degrees) is constant (every pixel is 17)",
    ),
    "one blank frame": (
        lambda t: _with_frame(t, 3, 0.0),
        "s.tif: frame 3 (135 degrees) is constant (every pixel is 0)",
    ),
    "negative intensities": (
        _negative,
        "s.tif: negative intensities (down to -3.5 in frame 2 (90 degrees))",
    ),
    "frame files of different sizes": (
        _frame_files_of_different_sizes,
        "p_120.tif: frame is 21 x 30 pixels but p_0.tif is 20 x 30",
    ),
    "absurd size in an npy header": (
        _absurd_npy,
        "huge.npy: reading 19 x 200000 x 300000 values of uint16 would need 10.4 TiB of memory, "
        f"more than the limit of {DEFAULT_LIMIT}",
    ),
    "absurd size in a PNG header": (
        _absurd_png,
        "huge.png: reading 90000 x 120000 values of uint8 would need 90.5 GiB of memory",
    ),
    "run too large for memory": (
        _tiny_window_on_a_large_image,
        "segmenting 4 frames of 400 x 400 pixels with window 1 (160000 blocks) and degree 60 "
        f"would need 18.2 GiB of memory, more than the limit of {DEFAULT_LIMIT}",
    ),
    "memory limit given": (
        lambda t: [_tif(t, _good()), "--max-memory", "0.0001"],
        "segmenting 4 frames of 30 x 32 pixels would need 128.2 MiB of memory, more than "
        "the limit of 104.9 KiB",
    ),
    "memory limit given with a unit": (
        lambda t: [_tif(t, _good()), "--max-memory", "100K"],
        "segmenting 4 frames of 30 x 32 pixels would need 128.2 MiB of memory, more than "
        "the limit of 100.0 KiB",
    ),
    "mask of another size": (
        _mask_of_another_size,
        "the mask is 10 x 10 pixels but the frames are 30 x 32",
    ),
    "everything masked": (
        _everything_masked,
        "no usable pixel: all 960 pixels are excluded (960 outside the mask)",
    ),
    "dark frame of another size": (
        _dark_frame_of_another_size,
        "dark.png: the dark frame is 5 x 5 pixels but the frames are 30 x 32",
    ),
    "demosaic without a mosaic": (
        lambda t: [_tif(t, _good()), "--demosaic", "interpolated"],
        "--demosaic applies to a raw mosaic frame: give --mosaic too",
    ),
    "bad --saturation": (
        lambda t: [_tif(t, _good()), "--saturation", "high"],
        "argument --saturation: expected a number, 'auto' or 'none', got 'high'",
    ),
    "missing mask file": (
        lambda t: [_tif(t, _good()), "--mask", t / "none.tif"],
        "none.tif: no such file",
    ),
    "unknown fit": (
        lambda t: [_tif(t, _good()), "--fit", "lm"],
        "argument --fit: invalid choice: 'lm'",
    ),
}


@pytest.mark.parametrize("case", list(BAD_REAL_INPUTS))
def test_bad_real_input_one_line_error_and_no_partial_file(tmp_path, capsys, case):
    build, words = BAD_REAL_INPUTS[case]
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    args = build(inputs)
    out = tmp_path / "out"
    out.mkdir()
    good = b"a good labels.tif from an earlier run"
    (out / "labels.tif").write_bytes(good)
    code, stdout, err = run(capsys, "segment", *args, "--out", out)
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("polarseg: error: ")
    assert words in lines[0]
    assert "Traceback" not in err + stdout
    assert (out / "labels.tif").read_bytes() == good
    assert os.listdir(out) == ["labels.tif"]


def test_partial_nan_is_masked_counted_and_segmented(tmp_path, capsys):
    args = _partial_nan(tmp_path)
    out = tmp_path / "out"
    code, stdout, err = run(capsys, "segment", *args, "--out", out)
    assert code == 0, err
    assert "left out 16 of 960 pixels (16 not finite; see mask.tif)" in stdout
    assert json.loads((out / "summary.json").read_text())["mask"]["nonfinite_pixels"] == 16
    assert not tifffile.imread(out / "mask.tif")[:4, :4].any()


@needs_real_data
@pytest.mark.parametrize("name", REAL_FRAMES)
def test_real_frames_open_through_the_plugin_reader(name):
    """napari's File > Open on a raw frame: the plugin reader gives a 4-angle stack."""
    from napari_polarseg._reader import get_reader

    path = real_frame(name)
    reader = get_reader(str(path))
    assert reader is not None
    ((data, meta, kind),) = reader(str(path))
    assert kind == "image" and data.shape == (4, 1024, 1224)
    assert sorted(meta["metadata"]["angles_deg"]) == [0.0, 45.0, 90.0, 135.0]
