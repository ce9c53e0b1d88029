"""Reading and writing stacks and results (napari_polarseg.io), mosaics and registration."""

from __future__ import annotations

import io
import json
import os
import re
import zipfile

import numpy as np
import PIL.Image
import pytest
import tifffile
from scipy import ndimage
from skimage import io as skio

from napari_polarseg import io as pio
from napari_polarseg.engine import PolarsegError, polarisation_image
from napari_polarseg.engine.physics.mosaic import demosaic_superpixel, mosaic_superpixel
from napari_polarseg.engine.physics.registration import estimate_shift, register_stack

ANGLES = np.array([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])


def render(h=12, w=15, angles=ANGLES, seed=0, scale=1000.0):
    """Stack from I(a) = I0 (1 + rho cos(2a - 2 phi)) with known per-pixel I0, rho, phi."""
    rng = np.random.default_rng(seed)
    i0 = scale * (1 + rng.random((h, w)))
    rho = 0.05 + 0.5 * rng.random((h, w))
    phi = np.pi * rng.random((h, w))
    a = np.deg2rad(np.asarray(angles, dtype=float))[:, None, None]
    return i0 * (1 + rho * np.cos(2 * a - 2 * phi)), (i0, rho, phi)


def uint16_stack(**kw):
    stack, truth = render(**kw)
    return np.round(stack).astype(np.uint16), truth


# -- parsing helpers --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "angle"),
    [
        ("leaf_030.png", 30.0),
        ("nir_45_aligned.tif", 45.0),
        ("scene-b_22.5deg.png", 22.5),
        ("img2_090.jpeg", 90.0),
        ("/some/dir_7/pol135.tiff", 135.0),
        ("dark.png", None),
    ],
)
def test_angle_from_name_takes_last_number_of_stem(name, angle):
    assert pio.angle_from_name(name) == angle


def test_parse_angles_good_and_bad():
    assert pio.parse_angles(" 0,45 , 90,135.5").tolist() == [0.0, 45.0, 90.0, 135.5]
    for bad in ["0,,90", "0,x,90", "", "0,nan,90", "0,45,", "0:45:90"]:
        with pytest.raises(PolarsegError, match="comma-separated"):
            pio.parse_angles(bad)


@pytest.mark.parametrize("text", ["0 45; 90 135", "0;45;90;135", "0 45 90 135", " 0, 45 ;90\t135 "])
def test_parse_angles_takes_spaces_and_semicolons(text):
    assert pio.parse_angles(text).tolist() == [0.0, 45.0, 90.0, 135.0]
    assert pio.parse_angles(text, option=None).tolist() == [0.0, 45.0, 90.0, 135.0]


def test_parse_angles_messages_name_the_option_or_none():
    with pytest.raises(PolarsegError, match=r"^bad --mosaic value '0,x': .*\(problem at 'x'\)$"):
        pio.parse_angles("0,x", option="--mosaic")
    with pytest.raises(PolarsegError) as typed:
        pio.parse_angles("0, 30, sixty", option=None)
    assert str(typed.value) == "angles must be numbers in degrees, got 'sixty'"
    for empty in ("", "  "):
        with pytest.raises(PolarsegError) as typed:
            pio.parse_angles(empty, option=None)
        assert str(typed.value) == (
            "give the polariser angles in degrees, one per frame (e.g. 0,45,90,135)"
        )


def test_to_grey_uses_bt601_luma_or_one_channel():
    rgb = np.array([[[100, 50, 200], [0, 255, 0]]], dtype=np.uint8)
    grey = pio.to_grey(rgb)
    assert grey[0, 0] == pytest.approx(0.299 * 100 + 0.587 * 50 + 0.114 * 200)
    assert grey[0, 1] == pytest.approx(0.587 * 255)
    assert pio.to_grey(np.dstack([rgb, np.full((1, 2), 7, np.uint8)]))[0, 0] == grey[0, 0]
    assert pio.to_grey(rgb, channel=2).tolist() == [[200, 0]]
    with pytest.raises(PolarsegError, match="channel 3"):
        pio.to_grey(rgb, channel=3)


# -- TIFF ----------------------------------------------------------------------------------


def test_stack_tiff_round_trip_keeps_values_dtype_and_angles(tmp_path):
    stack, _ = uint16_stack()
    path = tmp_path / "stack.tif"
    pio.write_stack_tiff(path, stack, ANGLES)
    data = pio.read_stack(path)
    assert data.stack.dtype == np.uint16
    np.testing.assert_array_equal(data.stack, stack)
    np.testing.assert_array_equal(data.angles_deg, ANGLES)
    np.testing.assert_allclose(data.angles_rad, np.deg2rad(ANGLES))
    assert data.source == str(path)
    assert data.metadata["format"] == "tiff"
    assert data.metadata["angles_from"] == "tiff"
    # the angles are JSON in the ImageDescription, as tifffile's shaped metadata
    with tifffile.TiffFile(path) as tif:
        assert tif.shaped_metadata[0]["angles"] == ANGLES.tolist()
        assert len(tif.pages) == len(ANGLES)


def test_tiff_with_plain_json_description(tmp_path):
    stack, _ = uint16_stack()
    path = tmp_path / "plain.tiff"
    tifffile.imwrite(
        path,
        stack,
        photometric="minisblack",
        metadata=None,
        description=json.dumps({"angles": ANGLES.tolist()}),
    )
    data = pio.read_stack(path)
    np.testing.assert_array_equal(data.angles_deg, ANGLES)
    np.testing.assert_array_equal(data.stack, stack)


def test_given_angles_override_metadata(tmp_path):
    stack, _ = uint16_stack()
    path = tmp_path / "stack.tif"
    pio.write_stack_tiff(path, stack, ANGLES)
    given = [10, 40, 70, 100, 130, 160]
    data = pio.read_stack(path, angles_deg=given)
    assert data.angles_deg.tolist() == [10.0, 40.0, 70.0, 100.0, 130.0, 160.0]
    assert data.metadata["angles_from"] == "given"


def test_tiff_without_angles_needs_them(tmp_path):
    stack, _ = uint16_stack()
    path = tmp_path / "bare.tif"
    tifffile.imwrite(path, stack, photometric="minisblack", metadata=None)
    with pytest.raises(PolarsegError, match=r"bare\.tif: no polariser angles"):
        pio.read_stack(path)
    assert pio.read_stack(path, angles_deg=ANGLES).stack.shape == stack.shape


def test_colour_tiff_stack_becomes_luma(tmp_path):
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 255, (4, 6, 7, 3), dtype=np.uint8)
    path = tmp_path / "rgb.tif"
    tifffile.imwrite(path, rgb, photometric="rgb", metadata={"angles": [0, 45, 90, 135]})
    data = pio.read_stack(path)
    np.testing.assert_allclose(data.stack, rgb @ np.array([0.299, 0.587, 0.114]))
    np.testing.assert_array_equal(pio.read_stack(path, channel=1).stack, rgb[..., 1])


def test_truncated_tiff_is_an_error_naming_the_file(tmp_path):
    stack, _ = uint16_stack(h=40, w=50)
    good = tmp_path / "good.tif"
    pio.write_stack_tiff(good, stack, ANGLES)
    raw = good.read_bytes()
    for cut in (0.3, 0.7, 0.99):
        bad = tmp_path / f"cut{int(cut * 100)}.tif"
        bad.write_bytes(raw[: int(len(raw) * cut)])
        with pytest.raises(PolarsegError, match=rf"{bad.name}: .*(truncated|cannot read)"):
            pio.read_stack(bad)


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("notes.tif", b"hello, not a tiff\n", "cannot read the TIFF file"),
        ("notes.txt", b"hello\n", "unsupported file type '.txt'"),
        ("data.npz", b"not a zip file", "cannot read the NumPy file"),
        ("frame.png", b"\x89PNG\r\n\x1a\n truncated", "single image is not an angle stack"),
    ],
)
def test_non_image_files_are_errors(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(PolarsegError, match=match) as info:
        pio.read_stack(path)
    assert str(info.value).startswith(str(path))
    assert "\n" not in str(info.value)


def test_missing_file_is_an_error(tmp_path):
    with pytest.raises(PolarsegError, match="no such file"):
        pio.read_stack(tmp_path / "nope.tif")


def test_angle_validation(tmp_path):
    stack, _ = uint16_stack(angles=[0, 45, 90, 135])
    path = tmp_path / "s.tif"
    pio.write_stack_tiff(path, stack, [0, 45, 90, 135])
    with pytest.raises(PolarsegError, match="4 frames but 3 angles"):
        pio.read_stack(path, angles_deg=[0, 45, 90])
    # 0 and 180 are one polariser state, so is 90 and 270
    with pytest.raises(PolarsegError, match="at least 3 distinct .* got 2"):
        pio.read_stack(path, angles_deg=[0, 180, 90, 270])
    with pytest.raises(PolarsegError, match="finite"):
        pio.read_stack(path, angles_deg=[0, 45, np.nan, 135])


def test_nan_only_data_is_an_error(tmp_path):
    path = tmp_path / "nan.tif"
    pio.write_stack_tiff(path, np.full((4, 5, 6), np.nan, np.float32), [0, 45, 90, 135])
    with pytest.raises(PolarsegError, match=r"nan\.tif: the data has no finite values"):
        pio.read_stack(path)


# -- npz -----------------------------------------------------------------------------------


def test_npz_round_trip_with_ground_truth_and_params(tmp_path):
    stack, _ = uint16_stack()
    labels = (np.arange(stack.shape[2]) >= 7).astype(np.uint8)[None, :].repeat(stack.shape[1], 0)
    path = tmp_path / "scene.npz"
    np.savez(path, stack=stack, angles=ANGLES, labels=labels, params=json.dumps({"window": 4}))
    data = pio.read_stack(path)
    np.testing.assert_array_equal(data.stack, stack)
    np.testing.assert_array_equal(data.angles_deg, ANGLES)
    np.testing.assert_array_equal(data.ground_truth, labels)
    assert data.metadata["params"] == {"window": 4}


def test_npz_errors(tmp_path):
    path = tmp_path / "nostack.npz"
    np.savez(path, frames=np.zeros((3, 4, 4)), angles=[0, 60, 120])
    with pytest.raises(PolarsegError, match="no array named 'stack'.*found: frames, angles"):
        pio.read_stack(path)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, stack=np.array([None, 1], dtype=object), angles=[0, 60])
    with pytest.raises(PolarsegError, match="pickled.npz: cannot read"):
        pio.read_stack(pickled)
    single = tmp_path / "single.npz"
    np.savez(single, stack=np.zeros((4, 4)), angles=[0, 60, 120])
    with pytest.raises(PolarsegError, match=r"expected a stack of frames"):
        pio.read_stack(single)


def test_npy_needs_angles(tmp_path):
    stack, _ = uint16_stack()
    path = tmp_path / "s.npy"
    np.save(path, stack)
    with pytest.raises(PolarsegError, match="no polariser angles"):
        pio.read_stack(path)
    np.testing.assert_array_equal(pio.read_stack(path, angles_deg=ANGLES).stack, stack)


# -- folders -------------------------------------------------------------------------------


def test_folder_of_png_frames_sorted_by_angle_in_name(tmp_path):
    stack, _ = uint16_stack()
    folder = tmp_path / "frames"
    folder.mkdir()
    names = {}
    for k in [3, 0, 5, 1, 4, 2]:  # written out of order; names are not zero-padded alike
        name = f"leaf_{int(ANGLES[k])}deg.png" if k % 2 else f"leaf_{int(ANGLES[k]):03d}.png"
        skio.imsave(folder / name, stack[k], check_contrast=False)
        names[k] = name
    (folder / "notes.txt").write_text("ignored")
    (folder / ".hidden_999.png").write_bytes(b"ignored")
    data = pio.read_stack(folder)
    np.testing.assert_array_equal(data.angles_deg, ANGLES)
    np.testing.assert_array_equal(data.stack, stack)
    assert data.metadata["files"] == [names[k] for k in range(6)]


def test_folder_with_given_angles_uses_natural_name_order(tmp_path):
    stack, _ = uint16_stack(angles=[0, 45, 90, 135])
    for k, name in enumerate(["f2.tif", "f10.tif", "f11.tif", "f100.tif"]):
        tifffile.imwrite(tmp_path / name, stack[k], photometric="minisblack")
    data = pio.read_stack(tmp_path, angles_deg=[0, 45, 90, 135])
    np.testing.assert_array_equal(data.stack, stack)
    assert data.metadata["files"] == ["f2.tif", "f10.tif", "f11.tif", "f100.tif"]


def test_folder_of_colour_frames(tmp_path):
    rng = np.random.default_rng(5)
    rgb = rng.integers(0, 255, (3, 5, 6, 3), dtype=np.uint8)
    for k, a in enumerate([0, 60, 120]):
        skio.imsave(tmp_path / f"c_{a}.png", rgb[k], check_contrast=False)
    data = pio.read_stack(tmp_path)
    np.testing.assert_allclose(data.stack, rgb @ pio.LUMA_BT601)
    np.testing.assert_array_equal(pio.read_stack(tmp_path, channel=0).stack, rgb[..., 0])


def test_folder_errors(tmp_path):
    stack, _ = uint16_stack(angles=[0, 45, 90])
    for k, a in enumerate([0, 45, 90]):
        skio.imsave(tmp_path / f"p_{a}.png", stack[k], check_contrast=False)
    skio.imsave(tmp_path / "p_135.png", stack[0, :-1], check_contrast=False)
    with pytest.raises(
        PolarsegError, match=r"p_135\.png: frame is 11 x 15 pixels but p_0\.png is 12 x 15"
    ):
        pio.read_stack(tmp_path)
    (tmp_path / "p_135.png").unlink()
    skio.imsave(tmp_path / "dark.png", stack[0], check_contrast=False)
    with pytest.raises(PolarsegError, match=r"dark\.png: no angle in the file name"):
        pio.read_stack(tmp_path)
    (tmp_path / "dark.png").unlink()
    (tmp_path / "p_20.png").write_bytes(b"\x89PNG\r\n\x1a\n cut short")
    with pytest.raises(PolarsegError, match=r"p_20\.png: cannot read the image"):
        pio.read_stack(tmp_path)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(PolarsegError, match="no image frames"):
        pio.read_stack(empty)


# -- mosaic --------------------------------------------------------------------------------


def test_demosaic_matches_explicit_slicing_and_sorts_by_angle():
    rng = np.random.default_rng(7)
    raw = rng.integers(0, 4096, (6, 8), dtype=np.uint16)
    stack, angles = demosaic_superpixel(raw, (90, 45, 135, 0))
    assert angles.tolist() == [0.0, 45.0, 90.0, 135.0]
    assert stack.shape == (4, 3, 4) and stack.dtype == np.uint16
    # independent decoding: the pixel at (2i + di, 2j + dj) belongs to layout[2 di + dj]
    expected = {
        0.0: raw[1::2, 1::2],
        45.0: raw[0::2, 1::2],
        90.0: raw[0::2, 0::2],
        135.0: raw[1::2, 0::2],
    }
    for frame, angle in zip(stack, angles, strict=True):
        np.testing.assert_array_equal(frame, expected[angle])
    for i in range(3):
        for j in range(4):
            assert stack[2, i, j] == raw[2 * i, 2 * j]  # 90 degrees: top-left
            assert stack[0, i, j] == raw[2 * i + 1, 2 * j + 1]  # 0 degrees: bottom-right
    np.testing.assert_array_equal(mosaic_superpixel(stack, (90, 45, 135, 0)), raw)


def test_demosaic_errors():
    with pytest.raises(PolarsegError, match="even height and width, got 5 x 8"):
        demosaic_superpixel(np.zeros((5, 8)))
    with pytest.raises(PolarsegError, match="4 finite angles"):
        demosaic_superpixel(np.zeros((4, 4)), (0, 45, 90))
    with pytest.raises(PolarsegError, match="2-D"):
        demosaic_superpixel(np.zeros((2, 4, 4)))


def test_mosaic_file_recovers_polarisation(tmp_path):
    layout = (90, 45, 135, 0)
    stack, (i0, rho, phi) = render(h=10, w=12, angles=sorted(layout))
    raw = mosaic_superpixel(np.round(stack).astype(np.uint16), layout)
    path = tmp_path / "raw.png"
    skio.imsave(path, raw, check_contrast=False)
    data = pio.read_stack(path, mosaic=layout)
    assert data.stack.shape == (4, 10, 12)
    assert data.metadata["raw_shape"] == [20, 24]
    pol = polarisation_image(data.stack, data.angles_rad)
    np.testing.assert_allclose(pol.intensity, i0, rtol=1e-3)
    np.testing.assert_allclose(pol.dop, rho, atol=2e-3)
    dphi = np.angle(np.exp(2j * (pol.phase - phi))) / 2
    assert np.max(np.abs(dphi)) < 0.01


def test_mosaic_file_errors(tmp_path):
    path = tmp_path / "odd.tif"
    tifffile.imwrite(path, np.zeros((7, 8), np.uint16), photometric="minisblack")
    with pytest.raises(PolarsegError, match=r"odd\.tif: .*even height and width, got 7 x 8"):
        pio.read_stack(path, mosaic=(90, 45, 135, 0))
    with pytest.raises(PolarsegError, match="not both"):
        pio.read_stack(path, angles_deg=[0, 45, 90, 135], mosaic=(90, 45, 135, 0))
    with pytest.raises(PolarsegError, match="not a folder"):
        pio.read_stack(tmp_path, mosaic=(90, 45, 135, 0))


# -- registration --------------------------------------------------------------------------


def test_registration_recovers_subpixel_shifts():
    rng = np.random.default_rng(11)
    big = ndimage.gaussian_filter(rng.random((140, 150)), 2.0)
    true = np.array([[0, 0], [1.5, -2.25], [0.3, 0.7], [-3.4, 1.1], [2.6, -0.45]])
    # moving frames: the same scene displaced by `true`, with other brightness and noise,
    # cut from a larger field so the edges are not periodic
    frames = []
    for k, d in enumerate(true):
        moved = ndimage.shift(big, d, order=5)[40:97, 40:103]
        frames.append((0.5 + 0.2 * k) * moved + 0.1 * k + rng.normal(0, 0.003, moved.shape))
    stack = np.stack(frames)
    registered, shifts = register_stack(stack)
    assert shifts.shape == (5, 2)
    np.testing.assert_allclose(shifts, -true, atol=0.2)
    assert np.all(shifts[0] == 0)
    np.testing.assert_array_equal(registered[0], stack[0])
    # after registration the interiors line up (up to the brightness change)
    inner = (slice(6, -6), slice(6, -6))
    for k in range(1, 5):
        r = np.corrcoef(registered[k][inner].ravel(), registered[0][inner].ravel())[0, 1]
        before = np.corrcoef(stack[k][inner].ravel(), stack[0][inner].ravel())[0, 1]
        assert r > 0.975 and r > before + 0.04  # limited by the added noise


def test_registration_edge_cases():
    flat = np.ones((3, 16, 16))
    registered, shifts = register_stack(flat)
    assert np.all(shifts == 0)
    np.testing.assert_array_equal(registered, flat)
    assert estimate_shift(np.zeros((8, 8)), np.ones((8, 8))).tolist() == [0.0, 0.0]
    with pytest.raises(PolarsegError, match="reference frame 3"):
        register_stack(flat, reference=3)
    with pytest.raises(PolarsegError, match="upsample"):
        register_stack(flat, upsample=0)
    with pytest.raises(PolarsegError, match="shape"):
        register_stack(np.ones((4, 4)))


# -- writers -------------------------------------------------------------------------------


def test_write_tiff_round_trip_with_metadata(tmp_path):
    array = np.linspace(0, 1, 35, dtype=np.float32).reshape(5, 7)
    path = tmp_path / "dop.tif"
    pio.write_tiff(path, array, {"unit": "1"})
    with tifffile.TiffFile(path) as tif:
        np.testing.assert_array_equal(tif.asarray(), array)
        assert tif.shaped_metadata[0]["unit"] == "1"
    assert sorted(os.listdir(tmp_path)) == ["dop.tif"]


def test_write_json_converts_numpy_and_non_finite(tmp_path):
    path = tmp_path / "s.json"
    pio.write_json(path, {"a": np.float32(1.5), "b": np.arange(3), "c": float("nan"), "d": (1, 2)})
    assert json.loads(path.read_text()) == {"a": 1.5, "b": [0, 1, 2], "c": None, "d": [1, 2]}


def test_write_png_round_trip(tmp_path):
    image = np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000
    path = tmp_path / "a.png"
    pio.write_png(path, image)
    np.testing.assert_array_equal(skio.imread(path), image)
    with pytest.raises(PolarsegError, match="uint8 or uint16"):
        pio.write_png(path, image.astype(float))


def _failing_writer(*args, **kwargs):
    """Write half a file to the target, then fail like a full disk."""
    target = args[0] if args else kwargs.get("fname") or kwargs.get("file")
    with open(target, "wb") as handle:
        handle.write(b"partial")
    raise OSError(28, "No space left on device")


def test_atomic_writers_leave_the_old_file_intact(tmp_path, monkeypatch):
    tif, js, png = tmp_path / "labels.tif", tmp_path / "params.json", tmp_path / "o.png"
    pio.write_tiff(tif, np.ones((4, 4), np.uint16))
    pio.write_json(js, {"good": True})
    pio.write_png(png, np.ones((4, 4), np.uint8))
    before = {p: p.read_bytes() for p in (tif, js, png)}

    monkeypatch.setattr(tifffile, "imwrite", _failing_writer)
    with pytest.raises(OSError, match="No space"):
        pio.write_tiff(tif, np.zeros((8, 8), np.uint16))
    with pytest.raises(OSError, match="No space"):
        pio.write_stack_tiff(tif, np.zeros((3, 8, 8)), [0, 60, 120])
    monkeypatch.setattr(PIL.Image.Image, "save", lambda self, fp, **kw: _failing_writer(fp))
    with pytest.raises(OSError, match="No space"):
        pio.write_png(png, np.zeros((8, 8), np.uint8))
    with pytest.raises(TypeError):
        pio.write_json(js, {"not serialisable": object()})

    for p, content in before.items():
        assert p.read_bytes() == content
    assert sorted(os.listdir(tmp_path)) == ["labels.tif", "o.png", "params.json"]  # no temp files


def test_atomic_output_replaces_only_on_success(tmp_path):
    path = tmp_path / "x.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError), pio.atomic_output(path) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".txt"
        tmp.write_text("new but broken")
        raise RuntimeError("boom")
    assert path.read_text() == "old"
    with pio.atomic_output(path) as tmp:
        tmp.write_text("new")
    assert path.read_text() == "new"
    assert os.listdir(tmp_path) == ["x.txt"]


# -- real-input checks: saturation, masks, header sizes, bad values ------------------------


def test_colour_frames_flag_saturation_per_channel(tmp_path):
    rng = np.random.default_rng(9)
    rgb = rng.integers(10, 200, (3, 6, 7, 3), dtype=np.uint8)
    rgb[1, 2, 3, 0] = 255  # red saturated: the luma is not 255, the sample is still bad
    rgb[2, 4, 4, 2] = 255
    for k, a in enumerate([0, 60, 120]):
        skio.imsave(tmp_path / f"c_{a}.png", rgb[k], check_contrast=False)
    data = pio.read_stack(tmp_path)
    assert data.metadata["saturation_level"] == 255.0
    assert data.stack[1, 2, 3] < 255
    assert np.argwhere(data.saturated).tolist() == [[1, 2, 3], [2, 4, 4]]
    green = pio.read_stack(tmp_path, channel=1)  # only the chosen channel counts
    assert not green.saturated.any()
    assert pio.read_stack(tmp_path, saturation=None).saturated is None


def test_read_mask_formats_and_errors(tmp_path):
    labels = np.zeros((6, 8), np.uint16)
    labels[1:4, 2:6] = 7
    tifffile.imwrite(tmp_path / "m.tif", labels)
    np.save(tmp_path / "m.npy", labels.astype(float))
    np.savez(tmp_path / "m.npz", labels=labels)
    skio.imsave(tmp_path / "m.png", np.dstack([labels > 0] * 3).astype(np.uint8) * 255)
    for name in ("m.tif", "m.npy", "m.npz", "m.png"):
        keep = pio.read_mask(tmp_path / name, (6, 8))
        np.testing.assert_array_equal(keep, labels > 0, err_msg=name)
    with pytest.raises(PolarsegError, match=r"m\.tif: the mask is 6 x 8 pixels but the frames"):
        pio.read_mask(tmp_path / "m.tif", (5, 8))
    with pytest.raises(PolarsegError, match="no such file"):
        pio.read_mask(tmp_path / "none.tif", (6, 8))
    (tmp_path / "m.txt").write_text("1 0")
    with pytest.raises(PolarsegError, match="unsupported mask file type"):
        pio.read_mask(tmp_path / "m.txt", (6, 8))


def test_read_arrays_picks_one_array_the_same_way_for_every_caller(tmp_path):
    a, b = np.arange(6).reshape(2, 3), np.ones((2, 3))
    np.save(tmp_path / "one.npy", a)
    np.savez(tmp_path / "two.npz", labels=a, mask=b, angles=np.arange(3.0))
    np.savez(tmp_path / "only.npz", whatever=b)
    array, more = pio.read_arrays(tmp_path / "one.npy", ("stack",), optional=("angles",))
    assert array.tolist() == a.tolist() and more == {}
    array, more = pio.read_arrays(tmp_path / "two.npz", ("mask", "labels"), optional=("angles",))
    assert array.tolist() == b.tolist() and more["angles"].tolist() == [0.0, 1.0, 2.0]
    assert pio.read_arrays(tmp_path / "only.npz", ("mask",))[0].tolist() == b.tolist()
    with pytest.raises(PolarsegError) as missing:
        pio.read_arrays(tmp_path / "only.npz", ("a", "b", "c"), only=False)
    assert str(missing.value) == (
        f"{tmp_path / 'only.npz'}: no array named 'a', 'b' or 'c' in the .npz file "
        "(found: whatever)"
    )
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(PolarsegError, match=r"bad\.npz: cannot read the NumPy file \("):
        pio.read_arrays(tmp_path / "bad.npz", ("mask",))


def test_masks_and_labels_share_one_reading_path(tmp_path):
    labels = np.zeros((6, 8), np.uint8)
    labels[2:4, 1:5] = 3
    np.savez(tmp_path / "only.npz", drawn=labels)
    np.save(tmp_path / "cube.npy", np.zeros((2, 6, 8), np.uint8))
    np.savez(tmp_path / "two.npz", a=labels, b=labels)
    assert pio.read_mask(tmp_path / "only.npz", (6, 8)).sum() == 8
    assert pio.read_labels(tmp_path / "only.npz", (6, 8), "scribbles").max() == 3
    for name, words in [
        ("cube.npy", "one 2-D image, got an array of shape (2, 6, 8)"),
        ("two.npz", "no array named"),
        ("none.npy", "no such file"),
        ("x.txt", "file type '.txt'"),
    ]:
        for read, what in [(pio.read_mask, "mask"), (pio.read_labels, "ground truth")]:
            args = (tmp_path / name, (6, 8)) + (() if read is pio.read_mask else (what,))
            with pytest.raises(PolarsegError, match=re.escape(words)) as err:
                read(*args)
            assert str(err.value).startswith(f"{tmp_path / name}: ")
            if name == "cube.npy":
                assert f"the {what} must be one 2-D image" in str(err.value)
    big = tmp_path / "big.npy"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<i8", "fortran_order": False, "shape": (90000, 90000)}
    )
    big.write_bytes(header.getvalue())
    with pytest.raises(PolarsegError, match=r"big\.npy: reading 90000 x 90000 values of int64"):
        pio.read_labels(big, (6, 8), "scribbles")


def test_header_sizes_are_checked_before_reading(tmp_path):
    path = tmp_path / "big.npz"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (7, 90000, 90000)}
    )
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("stack.npy", header.getvalue())
        archive.writestr("angles.npy", b"")
    with pytest.raises(PolarsegError, match=r"big\.npz: reading 7 x 90000 x 90000 values of "):
        pio.read_stack(path)
    stack, _ = uint16_stack()
    small = tmp_path / "s.tif"
    pio.write_stack_tiff(small, stack, ANGLES)
    with pytest.raises(PolarsegError, match=r"s\.tif: reading 6 x 12 x 15 values of uint16"):
        pio.read_stack(small, max_bytes=1000)
    assert pio.read_stack(small, max_bytes=10**6).stack.shape == (6, 12, 15)


def test_reader_refuses_negative_blank_and_constant_data(tmp_path):
    stack, _ = render(h=6, w=7, angles=[0, 45, 90, 135])
    cases = {
        "neg": (stack - stack.min() - 1.0, "negative intensities (down to -1 in frame"),
        "blank": (np.concatenate([stack[:3], np.zeros((1, 6, 7))]), "frame 3 (135 degrees) is "),
        "nanframe": (
            np.concatenate([stack[:1], np.full((1, 6, 7), np.nan), stack[2:]]),
            "frame 1 (45 degrees) has no finite values",
        ),
    }
    for name, (data, match) in cases.items():
        path = tmp_path / f"{name}.tif"
        pio.write_stack_tiff(path, data.astype(np.float32), [0, 45, 90, 135])
        with pytest.raises(PolarsegError, match=re.escape(match)):
            pio.read_stack(path)
    # an offset large enough to go negative is clipped at 0 instead (counted as black later)
    path = tmp_path / "ok.tif"
    pio.write_stack_tiff(path, stack.astype(np.float32), [0, 45, 90, 135])
    shifted = pio.read_stack(path, offset=float(np.median(stack)))
    assert shifted.stack.min() == 0.0 and shifted.metadata["offset"] == float(np.median(stack))
    with pytest.raises(PolarsegError, match="too large to process"):
        polarisation_image(np.full((3, 2, 2), 1e200), np.deg2rad([0, 60, 120]))


def test_mosaic_reader_options(tmp_path):
    layout = (90, 45, 135, 0)
    stack, _ = render(h=10, w=12, angles=sorted(layout))
    raw = mosaic_superpixel(np.round(stack).astype(np.uint16), layout)
    path = tmp_path / "raw.tif"
    tifffile.imwrite(path, raw, photometric="minisblack")
    full = pio.read_stack(path, mosaic=layout, demosaic="interpolated")
    assert full.stack.shape == (4, 20, 24) and full.stack.dtype == np.float64
    assert full.metadata["demosaic"] == "interpolated"
    with pytest.raises(PolarsegError, match="demosaic method must be one of"):
        pio.read_stack(path, mosaic=layout, demosaic="bicubic")
    with pytest.raises(PolarsegError, match="saturation must be a number"):
        pio.read_stack(path, mosaic=layout, saturation="max")
    with pytest.raises(PolarsegError, match="a mosaic layout needs a single raw frame"):
        pio.read_stack([path, path], mosaic=layout)


# -- angles in TIFF metadata (napari_polarseg.tiff_angles) ---------------------------------


def test_tiff_plain_json_description_beside_tifffiles_shaped_one(tmp_path):
    """tifffile writes its own shaped description after the user's: both are read."""
    stack, _ = uint16_stack()
    path = tmp_path / "described.tif"
    tifffile.imwrite(path, stack, description=json.dumps({"angles": ANGLES.tolist()}))
    with tifffile.TiffFile(path) as tif:  # the case of the issue: the shaped one has no angles
        assert "angles" not in tif.shaped_metadata[0]
    data = pio.read_stack(path)
    np.testing.assert_array_equal(data.angles_deg, ANGLES)
    np.testing.assert_array_equal(data.stack, stack)
    assert data.metadata["angles_from"] == "tiff"


def test_tiff_json_angles_on_a_later_page(tmp_path):
    stack, _ = uint16_stack()
    path = tmp_path / "later.tif"
    with tifffile.TiffWriter(path) as tif:
        for k, frame in enumerate(stack):
            text = json.dumps({"angles": ANGLES.tolist()}) if k == 2 else f"frame {k}"
            tif.write(frame, description=text, metadata=None, contiguous=False)
    data = pio.read_stack(path)
    np.testing.assert_array_equal(data.angles_deg, ANGLES)
    np.testing.assert_array_equal(data.stack, stack)


def test_imagej_hyperstack_angle_labels(tmp_path):
    stack = render(angles=np.array([0.0, 45.0, 90.0, 135.0]))[0].astype(np.float32)
    labels = ["0°", "45°", "pol 90 deg", "img_135.tif"]
    path = tmp_path / "imagej.tif"
    tifffile.imwrite(path, stack, imagej=True, metadata={"axes": "CYX", "Labels": labels})
    data = pio.read_stack(path)
    assert data.angles_deg.tolist() == [0.0, 45.0, 90.0, 135.0]
    assert data.metadata["angles_from"] == "imagej labels"
    np.testing.assert_allclose(data.stack, stack)


def test_ome_tiff_channel_names_carry_the_angles(tmp_path):
    stack = render(angles=np.array([0.0, 45.0, 90.0, 135.0]))[0].astype(np.float32)
    path = tmp_path / "stack.ome.tif"
    names = ["0°", "45", "90 deg", "135"]
    tifffile.imwrite(path, stack, ome=True, metadata={"axes": "CYX", "Channel": {"Name": names}})
    data = pio.read_stack(path)
    assert data.angles_deg.tolist() == [0.0, 45.0, 90.0, 135.0]
    assert data.metadata["angles_from"] == "ome channel names"
    np.testing.assert_allclose(data.stack, stack)


def test_labels_without_a_number_on_every_frame_are_not_angles(tmp_path):
    stack = render(angles=np.array([0.0, 45.0, 90.0, 135.0]))[0].astype(np.float32)
    path = tmp_path / "unlabelled.ome.tif"
    names = ["red", "45", "90", "135"]
    tifffile.imwrite(path, stack, ome=True, metadata={"axes": "CYX", "Channel": {"Name": names}})
    with pytest.raises(PolarsegError, match=r"unlabelled\.ome\.tif: no polariser angles"):
        pio.read_stack(path)


def test_angles_from_tiff_metadata_reach_the_cli(tmp_path, capsys):
    from napari_polarseg.cli import main

    stack, _ = uint16_stack(h=40, w=48)
    path = tmp_path / "described.tif"
    tifffile.imwrite(path, stack, description=json.dumps({"angles": ANGLES.tolist()}))
    out = tmp_path / "out"
    assert main(["segment", str(path), "--out", str(out), "--segments", "2", "--window", "4"]) == 0
    params = json.loads((out / "params.json").read_text())
    assert params["angles_deg"] == ANGLES.tolist()
    assert params["angles_from"] == "tiff"


def test_a_text_file_named_png_is_refused_in_one_clean_line(tmp_path):
    path = tmp_path / "notes_045.png"
    path.write_text("hello\n")
    with pytest.raises(PolarsegError) as caught:
        pio.read_frame(path)
    message = str(caught.value)
    assert message == (
        f"{path}: cannot read the image (its content is not a PNG image that any reader recognises)"
    )
    assert "`" not in message and message.count(str(path)) == 1


@pytest.mark.parametrize("n", [3, 4])
def test_planar_stack_from_tifffile_imwrite_is_an_angle_stack(tmp_path, n):
    """``tifffile.imwrite(path, stack)`` stores a (3|4, H, W) array as one planar RGB(A)
    page (axes SYX; spelled out here, as tifffile's default is to become one page a
    frame): each sample is read as one angle's frame, in order; so are the pages of the
    coming default (axes QYX)."""
    rng = np.random.default_rng(n)
    stack = rng.integers(0, 4000, (n, 9, 11), dtype=np.uint16)
    angles = [0.0, 60.0, 120.0] if n == 3 else [0.0, 45.0, 90.0, 135.0]
    planar = {"photometric": "rgb", "planarconfig": "separate"}
    path = tmp_path / "planar.tif"
    tifffile.imwrite(path, stack, metadata={"angles": angles}, **planar)
    with tifffile.TiffFile(path) as tif:  # the layout this test is about
        assert len(tif.pages) == 1 and tif.series[0].axes == "SYX"
    data = pio.read_stack(path)
    np.testing.assert_array_equal(data.stack, stack)
    assert data.angles_deg.tolist() == angles
    pages = tmp_path / "pages.tif"
    tifffile.imwrite(pages, stack, metadata={"angles": angles}, photometric="minisblack")
    with tifffile.TiffFile(pages) as tif:
        assert len(tif.pages) == n
    np.testing.assert_array_equal(pio.read_stack(pages).stack, stack)
    bare = tmp_path / "bare.tif"
    tifffile.imwrite(bare, stack, **planar)
    with pytest.raises(PolarsegError, match="no polariser angles"):
        pio.read_stack(bare)
    np.testing.assert_array_equal(pio.read_stack(bare, angles_deg=angles).stack, stack)


def test_colour_image_with_samples_last_is_still_one_image(tmp_path):
    """A colour image stored the usual way (samples last, YXS) stays one image."""
    rgb = np.random.default_rng(0).integers(0, 255, (9, 11, 3), dtype=np.uint8)
    path = tmp_path / "photo.tif"
    tifffile.imwrite(path, rgb, photometric="rgb")
    with pytest.raises(PolarsegError, match="single image, not an angle stack"):
        pio.read_stack(path)


def test_a_damaged_tiff_leaves_no_raw_library_line(tmp_path, caplog, capsys):
    """tifffile logs a damaged file's offsets; every opening of a user's TIFF keeps those
    lines to itself and says what is wrong once, in one line naming the file."""
    import logging

    from napari_polarseg.io.frames import single_frame_file

    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"II*\x00" + b"\xff" * 60)
    with caplog.at_level(logging.DEBUG):
        assert not single_frame_file(bad)
        with pytest.raises(PolarsegError, match=r"bad\.tif: "):
            pio.read_stack(bad)
    assert not [r for r in caplog.records if r.name.startswith("tifffile")]
    captured = capsys.readouterr()
    assert "TiffPages" not in captured.out + captured.err
