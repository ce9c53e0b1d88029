"""The npe2 reader and writer, directly and through a napari viewer."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import tifffile
from napari.layers import Image

from napari_polarseg import _reader, _writer
from napari_polarseg.io import write_png, write_stack_tiff

pytestmark = pytest.mark.gui

SAMPLE = Path(_reader.__file__).parent / "sample_data" / "leaves.npz"


@pytest.fixture(scope="module")
def leaves() -> tuple[np.ndarray, np.ndarray]:
    with np.load(SAMPLE) as data:
        return data["stack"], data["angles"]


def _make_tiff(tmp_path: Path, stack: np.ndarray, angles: np.ndarray) -> Path:
    path = tmp_path / "stack.tif"
    write_stack_tiff(path, stack, angles)
    return path


def _make_npz(tmp_path: Path, stack: np.ndarray, angles: np.ndarray) -> Path:
    path = tmp_path / "stack.npz"
    np.savez(path, stack=stack, angles=angles)
    return path


def _make_folder(tmp_path: Path, stack: np.ndarray, angles: np.ndarray) -> Path:
    folder = tmp_path / "frames"
    folder.mkdir()
    order = np.random.default_rng(1).permutation(len(angles))  # written in any order
    for i in order:
        write_png(folder / f"leaf_{int(angles[i]):03d}.png", stack[i])
    return folder


MAKERS = {"tiff": _make_tiff, "npz": _make_npz, "folder": _make_folder}


@pytest.mark.parametrize("kind", list(MAKERS))
def test_reader_returns_one_image_layer_with_angles(tmp_path, leaves, kind):
    stack, angles = leaves
    path = MAKERS[kind](tmp_path, stack, angles)
    for given in (str(path), [str(path)]):
        reader = _reader.get_reader(given)
        assert callable(reader)
        layers = reader(given)
        assert len(layers) == 1
        data, meta, layer_type = layers[0]
        assert layer_type == "image"
        np.testing.assert_array_equal(data, stack)
        assert meta["metadata"]["angles_deg"] == [float(a) for a in angles]
        assert meta["metadata"]["source"] == str(path)


@pytest.mark.parametrize("kind", list(MAKERS))
def test_viewer_opens_stacks_with_the_plugin(make_napari_viewer, tmp_path, leaves, kind):
    stack, angles = leaves
    path = MAKERS[kind](tmp_path, stack, angles)
    viewer = make_napari_viewer()
    layers = viewer.open(str(path), plugin="napari-polarseg")
    assert len(layers) == 1 and len(viewer.layers) == 1
    layer = layers[0]
    assert isinstance(layer, Image) and layer.data.shape == stack.shape
    assert layer.metadata["angles_deg"] == [float(a) for a in angles]


def test_get_reader_declines_what_it_does_not_handle(tmp_path, leaves):
    stack, angles = leaves
    single_png = tmp_path / "photo.png"
    write_png(single_png, stack[0])
    plain_tiff = tmp_path / "plain.tif"
    tifffile.imwrite(plain_tiff, stack)  # a stack, but no angles in the metadata
    two_angles = tmp_path / "two.tif"
    write_stack_tiff(two_angles, stack[:2], angles[:2])
    no_angles_npz = tmp_path / "noangles.npz"
    np.savez(no_angles_npz, stack=stack)
    other_npz = tmp_path / "other.npz"
    np.savez(other_npz, image=stack[0])
    text = tmp_path / "notes.txt"
    text.write_text("not an image")
    unnamed = tmp_path / "unnamed"
    unnamed.mkdir()
    for name in ("a.png", "b.png", "c.png"):
        write_png(unnamed / name, stack[0])
    too_few = tmp_path / "too_few"
    too_few.mkdir()
    for a in (0, 90):
        write_png(too_few / f"f_{a}.png", stack[0])
    empty = tmp_path / "empty"
    empty.mkdir()
    good = _make_npz(tmp_path, stack, angles)
    for path in (
        single_png,
        plain_tiff,
        two_angles,
        no_angles_npz,
        other_npz,
        text,
        unnamed,
        too_few,
        empty,
        tmp_path / "missing.npz",
        [str(good), str(good)],  # one stack at a time
    ):
        given = path if isinstance(path, list) else str(path)
        assert _reader.get_reader(given) is None, path


def test_writer_saves_labels_atomically(tmp_path, monkeypatch):
    labels = np.arange(12, dtype=np.int64).reshape(3, 4) % 5
    out = tmp_path / "segments.tif"
    written = _writer.write_labels(str(out), labels, {"name": "segments"})
    assert written == [str(out)]
    back = tifffile.imread(out)
    np.testing.assert_array_equal(back, labels)
    assert back.dtype == np.uint8  # smallest integer type that holds the labels
    assert sorted(os.listdir(tmp_path)) == ["segments.tif"]  # no temporary file left

    # another extension gets .tif appended; big labels keep their values
    big = labels.astype(np.int64) * 100_000
    written = _writer.write_labels(str(tmp_path / "big"), big, {})
    assert written == [str(tmp_path / "big.tif")]
    np.testing.assert_array_equal(tifffile.imread(written[0]), big)

    # a failure while writing leaves the previous file as it was and no temporary file
    def broken(path, *args, **kwargs):
        Path(path).write_bytes(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(_writer.tifffile, "imwrite", broken)
    with pytest.raises(OSError, match="disk full"):
        _writer.write_labels(str(out), labels + 1, {})
    np.testing.assert_array_equal(tifffile.imread(out), labels)
    assert sorted(os.listdir(tmp_path)) == ["big.tif", "segments.tif"]


def test_segments_layer_saves_through_the_plugin_writer(make_napari_viewer, qtbot, tmp_path):
    from _gui_helpers import run_and_wait

    viewer = make_napari_viewer()
    viewer.open_sample("napari-polarseg", "leaves")
    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
    widget.set_params(degree=4)
    run_and_wait(qtbot, widget)
    segments = widget.output("segments")
    out = tmp_path / "labels.tif"
    saved = segments.save(str(out), plugin="napari-polarseg")
    assert saved == [str(out)]
    np.testing.assert_array_equal(tifffile.imread(out), segments.data)


def test_raw_polarisation_camera_frames_open_as_four_angle_stacks(tmp_path):
    """A PNG/TIFF named after a Sony polarisation sensor is read as a 2 x 2 mosaic."""
    import tifffile
    from skimage import io as skio

    from napari_polarseg._reader import get_reader

    rng = np.random.default_rng(0)
    raw = rng.integers(0, 255, (8, 10), dtype=np.uint8)
    named = tmp_path / "scene_IMX250MZR.png"
    skio.imsave(named, raw, check_contrast=False)
    reader = get_reader(str(named))
    assert reader is not None
    ((data, meta, kind),) = reader(str(named))
    assert kind == "image" and data.shape == (4, 4, 5)
    assert sorted(meta["metadata"]["angles_deg"]) == [0.0, 45.0, 90.0, 135.0]
    # the 0-degree image is the bottom-right pixel of every super-pixel (90/45 over 135/0)
    zero = list(meta["metadata"]["angles_deg"]).index(0.0)
    np.testing.assert_array_equal(data[zero], raw[1::2, 1::2])
    # an ordinary image is left to napari's own readers
    plain = tmp_path / "holiday.png"
    skio.imsave(plain, raw, check_contrast=False)
    assert get_reader(str(plain)) is None
    tifffile.imwrite(tmp_path / "frame_imx253mzr.tif", raw)
    assert get_reader(str(tmp_path / "frame_imx253mzr.tif")) is not None


def _colour_scene(h: int = 32, w: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Raw IMX250MYR-like frame (4h x 4w, uint16) of two halves with one luminance but
    R polarised on the left and B on the right; and the truth (h x w)."""
    from napari_polarseg.engine.physics.colour_mosaic import LUMINANCE_WEIGHTS, colour_mosaic

    truth = np.zeros((h, w), dtype=np.uint8)
    truth[:, w // 2 :] = 1
    rho = np.zeros((3, h, w))
    rho[0][truth == 0] = 0.25
    rho[2][truth == 1] = 0.25 * LUMINANCE_WEIGHTS[0] / LUMINANCE_WEIGHTS[2]
    theta = np.deg2rad([0.0, 45.0, 90.0, 135.0])[None, :, None, None]
    stack = 800.0 * (1 + rho[:, None] * np.cos(2 * theta - 1.4))
    raw = colour_mosaic(stack) + np.random.default_rng(0).normal(0, 8.0, (4 * h, 4 * w))
    return np.round(raw).astype(np.uint16), truth


def test_a_colour_polarisation_frame_opens_as_colour_and_scribbles_use_every_colour(
    tmp_path, make_napari_viewer, qtbot
):
    """``…_IMX250MYR.png`` opens as a colour-polarisation frame (RGGB, 90/45 over 135/0):
    the luminance stack as the layer, the colour stacks beside it, which the scribble
    mode's pixel classifier takes as features."""
    from _gui_helpers import run_and_wait
    from skimage import io as skio

    from napari_polarseg.engine.physics.colour_mosaic import demosaic_colour_superpixel, luminance
    from napari_polarseg.widgets._layers import source_key

    raw, truth = _colour_scene()
    named = tmp_path / "bench_IMX250MYR.png"
    skio.imsave(named, raw, check_contrast=False)
    assert _reader.get_reader(str(named)) is _reader.read_mosaic_frame
    viewer = make_napari_viewer()
    (layer,) = viewer.open(str(named), plugin="napari-polarseg")
    expected, angles = demosaic_colour_superpixel(raw)
    assert layer.data.shape == (4, 32, 40)
    np.testing.assert_allclose(layer.data, luminance(expected))
    meta = layer.metadata
    assert meta["angles_deg"] == angles.tolist()
    assert meta["reader"]["bayer"] == "RGGB" and meta["reader"]["sensor"] == "IMX250MYR"
    np.testing.assert_array_equal(meta["colour_stack"], expected)

    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
    widget.set_params(window=4, degree=4)
    scribbles = widget.new_scribbles_layer()
    strokes = np.zeros(truth.shape, dtype=np.int32)
    strokes[4:8, 3:15] = 1
    strokes[24:28, 25:37] = 2
    scribbles.data = strokes
    run_and_wait(qtbot, widget)
    features = widget.store.segmenter(source_key(layer), meta["colour_stack"]).cached_features
    assert features is not None
    assert {n.split(":")[0] for n in features.names} >= {"R", "G", "B"}
    segments = np.asarray(widget.output("segments").data)
    assert np.mean((segments == 2) == (truth == 1)) > 0.95
