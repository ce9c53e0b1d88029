"""Big files in and out (issue 39, point 4): tiled BigTIFF and OME-Zarr angle stacks read
lazily in bounded memory, results written as tiled BigTIFF or OME-Zarr (``--format
zarr``), a rerun in the other format leaving one run's files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import dask.array as da
import numpy as np
import pytest
import tifffile
import zarr

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.io import tiff_tiles
from napari_polarseg.io.ome_zarr import write_ome_zarr

ANGLES = [0.0, 45.0, 90.0, 135.0]
#: A big stack: 4 x 6144 x 6144 uint16, 288 MiB decoded (above pio.LAZY_BYTES).
BIG = (4, 6144, 6144)
SAMPLE = Path(__file__).parents[1] / "napari_polarseg" / "sample_data" / "leaves.npz"


def _tile(k: int, top: int, left: int, rows: int, cols: int) -> np.ndarray:
    """The block of frame ``k`` at (top, left): a pattern of positive values."""
    r = np.arange(top, top + rows, dtype=np.uint32)[:, None]
    c = np.arange(left, left + cols, dtype=np.uint32)[None, :]
    return (100 + 500 * k + (r * 7 + c * 13) % 3001).astype(np.uint16)


def _big_tiff(path: Path) -> Path:
    """A tiled BigTIFF of :data:`BIG`, written tile by tile (never held whole)."""
    n, h, w = BIG

    def tiles():
        for k in range(n):
            for top in range(0, h, 256):
                for left in range(0, w, 256):
                    yield _tile(k, top, left, 256, 256)

    tifffile.imwrite(
        path,
        tiles(),
        shape=BIG,
        dtype=np.uint16,
        tile=(256, 256),
        bigtiff=True,
        photometric="minisblack",
        metadata={"angles": ANGLES},
    )
    return path


def _big_ome_zarr(path: Path) -> Path:
    """An OME-Zarr image (c, y, x) of :data:`BIG`, uncompressed, the angles in the
    group's attributes; written one band of chunks at a time."""
    n, h, w = BIG
    root = zarr.open_group(path, mode="w", zarr_format=2)
    array = root.create_array(
        "0", shape=BIG, dtype=np.uint16, chunks=(1, 512, 512), compressors=None
    )
    for k in range(n):
        for top in range(0, h, 512):
            array[k, top : top + 512] = _tile(k, top, 0, 512, w)
    axes = [{"name": "c", "type": "channel"}, {"name": "y", "type": "space"}]
    axes.append({"name": "x", "type": "space"})
    scale = [{"type": "scale", "scale": [1.0, 1.0, 1.0]}]
    datasets = [{"path": "0", "coordinateTransformations": scale}]
    root.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": datasets}]
    root.attrs[pio.ANGLES_ATTR] = ANGLES
    return path


#: Reads ``sys.argv[1]`` lazily and one tile of it, then the whole file for comparison;
#: prints the peak RSS growth (bytes) of each over the RSS before it.
MEASURE = """
import sys, json
import numpy as np, tifffile, zarr, dask.array
from napari_polarseg import io as pio

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024

base = status("VmRSS:")
data = pio.read_stack(sys.argv[1])
tile = np.asarray(data.stack[:, 1024:1280, 2048:2304])
lazy_peak = status("VmHWM:") - base
assert pio.is_lazy(data.stack) and tile.shape == (4, 256, 256)
base = status("VmRSS:")
whole = pio.read_stack(sys.argv[1], lazy="never").stack
whole_peak = status("VmHWM:") - base
same = bool(np.array_equal(whole[:, 1024:1280, 2048:2304], tile))
print(json.dumps({"lazy": lazy_peak, "whole": whole_peak, "same": same,
                  "angles": data.angles_deg.tolist(), "format": data.metadata["format"]}))
"""


def _measure(path: Path) -> dict:
    # glibc gives each reading thread (Zarr's, Dask's) a malloc arena that keeps freed
    # blocks; two arenas keep the RSS near the memory really in use
    env = {"OMP_NUM_THREADS": "1", "MALLOC_ARENA_MAX": "2", "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", MEASURE, str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
        env=env,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("make", [_big_tiff, _big_ome_zarr], ids=["bigtiff", "ome-zarr"])
def test_a_big_stack_is_read_lazily_in_memory_far_below_its_size(tmp_path, make):
    """Opening a 288 MiB stack (its checks read every block once) and one tile of it
    raises the peak RSS by less than a quarter of the stack; reading it whole, by more
    than the stack (the measure sees a whole read)."""
    path = make(tmp_path / ("big.tif" if make is _big_tiff else "big.ome.zarr"))
    nbytes = int(np.prod(BIG)) * 2
    assert nbytes > pio.LAZY_BYTES
    found = _measure(path)
    assert found["same"] and found["angles"] == ANGLES
    assert found["format"] == ("tiff" if make is _big_tiff else "zarr")
    assert found["lazy"] < nbytes / 4, found
    assert found["whole"] > nbytes, found


def _stack(seed: int = 0, shape=(4, 40, 56)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    stack = rng.integers(10, 4000, shape, dtype=np.uint16)
    stack[1, 3, 5] = 65535  # one saturated sample
    return stack


def _same(lazy: pio.StackData, whole: pio.StackData) -> None:
    assert pio.is_lazy(lazy.stack) and not pio.is_lazy(whole.stack)
    np.testing.assert_array_equal(np.asarray(lazy.stack), whole.stack)
    np.testing.assert_array_equal(np.asarray(lazy.saturated), whole.saturated)
    np.testing.assert_array_equal(lazy.angles_deg, whole.angles_deg)
    assert lazy.metadata["saturation_level"] == whole.metadata["saturation_level"]


def test_a_lazy_tiff_read_equals_the_whole_read_with_dark_frame_and_offset(tmp_path):
    stack = _stack()
    path = tmp_path / "stack.tif"
    tifffile.imwrite(
        path, stack, tile=(16, 16), photometric="minisblack", metadata={"angles": ANGLES}
    )
    dark = np.full(stack.shape[1:], 3.0)
    dark[0, 0] = 50.0
    kwargs = {"dark": dark, "offset": 2.0}
    lazy = pio.read_stack(path, lazy="always", **kwargs)
    whole = pio.read_stack(path, lazy="never", **kwargs)
    _same(lazy, whole)
    assert lazy.stack.dtype == np.float64 and lazy.metadata["lazy"] is True
    assert lazy.metadata["angles_from"] == "tiff"


def test_a_lazy_colour_tiff_stack_becomes_grey_as_the_whole_read(tmp_path):
    rgb = np.random.default_rng(3).integers(1, 250, (4, 24, 32, 3), dtype=np.uint8)
    path = tmp_path / "colour.tif"
    tifffile.imwrite(path, rgb, photometric="rgb", metadata={"angles": ANGLES})
    _same(pio.read_stack(path, lazy="always"), pio.read_stack(path, lazy="never"))
    one = pio.read_stack(path, lazy="always", channel=1)
    np.testing.assert_array_equal(np.asarray(one.stack), rgb[..., 1])


@pytest.mark.filterwarnings("ignore:<tifffile.TiffWriter.write> data with shape")
@pytest.mark.parametrize("n", [3, 4])
def test_a_planar_tifffile_imwrite_stack_is_an_angle_stack_read_lazily_too(tmp_path, n):
    """``tifffile.imwrite(path, stack)`` of a (3|4, H, W) stack: one planar page, read as
    that many frames (tests/test_io.py checks the whole read)."""
    stack = _stack(n, (n, 30, 20))
    path = tmp_path / "planar.tif"
    tifffile.imwrite(path, stack)
    angles = ANGLES[:n] if n == 4 else [0.0, 60.0, 120.0]
    data = pio.read_stack(path, angles_deg=angles, lazy="always")
    np.testing.assert_array_equal(np.asarray(data.stack), stack)


def test_zarr_angles_round_trip_and_a_small_store_is_read_whole(tmp_path):
    stack = _stack(1)
    path = tmp_path / "scene.zarr"
    array = zarr.open_array(path, mode="w", shape=stack.shape, chunks=(1, 16, 16), dtype="u2")
    array[:] = stack
    array.attrs[pio.ANGLES_ATTR] = [0, 30, 60, 90]
    data = pio.read_stack(path)
    assert isinstance(data.stack, np.ndarray) and data.metadata["format"] == "zarr"
    np.testing.assert_array_equal(data.stack, stack)
    assert data.angles_deg.tolist() == [0.0, 30.0, 60.0, 90.0]
    _same(pio.read_stack(path, lazy="always"), data)
    from napari_polarseg.io.stack_formats import STACK_FORMATS

    assert STACK_FORMATS[".zarr"].carries_angles(path)


def test_an_ome_zarr_stack_with_singleton_axes_and_group_angles(tmp_path):
    """A (t, c, z, y, x) OME-Zarr image with t = z = 1 is one frame per channel; the
    angles come from the group's attributes."""
    stack = _stack(2)
    path = tmp_path / "scene.ome.zarr"
    write_ome_zarr(path, stack)
    root = zarr.open_group(path, mode="a")
    five = root.create_array("5d", shape=(1, 4, 1, 40, 56), dtype="u2", chunks=(1, 1, 1, 40, 56))
    five[:] = stack[None, :, None]
    names = [("t", "time"), ("c", "channel"), ("z", "space"), ("y", "space"), ("x", "space")]
    axes = [{"name": a, "type": t} for a, t in names]
    datasets = [{"path": "5d", "coordinateTransformations": [{"type": "scale", "scale": [1] * 5}]}]
    root.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": datasets}]
    root.attrs[pio.ANGLES_ATTR] = ANGLES
    data = pio.read_stack(path, lazy="always")
    np.testing.assert_array_equal(np.asarray(data.stack), stack)
    assert data.angles_deg.tolist() == ANGLES and data.metadata["ome_axes"][1] == "c"


def test_a_zarr_store_without_angles_or_image_is_refused_in_one_line(tmp_path):
    bare = tmp_path / "bare.zarr"
    zarr.open_array(bare, mode="w", shape=(4, 8, 8), dtype="u2")[:] = _stack(0, (4, 8, 8))
    with pytest.raises(PolarsegError, match=r"bare\.zarr: no polariser angles"):
        pio.read_stack(bare)
    group = tmp_path / "group.zarr"
    zarr.open_group(group, mode="w").create_array("a", shape=(2, 2), dtype="u1")
    with pytest.raises(PolarsegError, match=r"group\.zarr: the Zarr group is not an OME-Zarr"):
        pio.read_stack(group, angles_deg=ANGLES)


def test_large_and_lazy_images_are_written_as_tiled_bigtiff(tmp_path, monkeypatch):
    monkeypatch.setattr(tiff_tiles, "TILED_PIXELS", 600 * 700)
    labels = np.random.default_rng(0).integers(0, 7, (600, 700)).astype(np.uint16)
    maps = np.random.default_rng(1).random((3, 600, 700)).astype(np.float32)
    pio.write_tiff(tmp_path / "labels.tif", labels, {"quantity": "segment labels"})
    pio.write_tiff(tmp_path / "maps.tif", da.from_array(maps, chunks=(3, 200, 300)))
    pio.write_tiff(tmp_path / "small.tif", labels[:100])
    for name, expected in (("labels.tif", labels), ("maps.tif", maps)):
        with tifffile.TiffFile(tmp_path / name) as tif:
            assert tif.is_bigtiff and all(p.is_tiled for p in tif.pages)
            assert tif.pages[0].tilelength == 256 and tif.pages[0].tilewidth == 256
            np.testing.assert_array_equal(tif.asarray(), expected)
    with tifffile.TiffFile(tmp_path / "labels.tif") as tif:
        assert tif.shaped_metadata[0]["quantity"] == "segment labels"
        assert tif.pages[0].compression != 1  # zlib for integer images
    with tifffile.TiffFile(tmp_path / "small.tif") as tif:
        assert not tif.is_bigtiff and not tif.pages[0].is_tiled
    lazy = zarr.open_array(tifffile.imread(tmp_path / "maps.tif", aszarr=True), mode="r")
    assert lazy.chunks[-2:] == (256, 256)


def _segment(out: Path, *extra: str) -> None:
    args = ["segment", str(SAMPLE), "-o", str(out), "--method", "superpixels", *extra]
    assert cli.main(args) == 0


def test_format_zarr_writes_ome_zarr_with_the_labels_of_the_tiff_output(tmp_path, capsys):
    """``--format zarr``: every image as NGFF 0.4 multiscale OME-Zarr that zarr opens
    lazily, the same labels and maps as the TIFFs; a rerun in either format into the
    same folder removes the other's images."""
    _segment(tmp_path / "tiff")
    _segment(tmp_path / "zarr", "--format", "zarr")
    tiffs, zarrs = tmp_path / "tiff", tmp_path / "zarr"
    labels = tifffile.imread(tiffs / "labels.tif")
    root = zarr.open_group(zarrs / "labels.zarr", mode="r")
    scale = root.attrs["multiscales"][0]
    assert scale["version"] == "0.4" and [a["name"] for a in scale["axes"]] == ["y", "x"]
    assert root.attrs["image-label"]["version"] == "0.4"
    assert root.attrs["polarseg"]["quantity"] == "segment labels"
    lazy = da.from_zarr(zarrs / "labels.zarr", component=scale["datasets"][0]["path"])
    np.testing.assert_array_equal(lazy.compute(), labels)
    phase = zarr.open_group(zarrs / "phase.zarr", mode="r")["0"][:]
    np.testing.assert_array_equal(phase, tifffile.imread(tiffs / "phase.tif"))
    stokes = zarr.open_group(zarrs / "stokes.zarr", mode="r")
    assert [a["name"] for a in stokes.attrs["multiscales"][0]["axes"]] == ["c", "y", "x"]
    assert not list(zarrs.glob("*.tif")) and not list(tiffs.glob("*.zarr"))
    written = json.loads((zarrs / "summary.json").read_text())
    assert "removed_from_earlier_run" not in written
    _segment(zarrs)  # back to TIFF: the OME-Zarr images go
    assert not list(zarrs.glob("*.zarr")) and (zarrs / "labels.tif").is_file()
    removed = json.loads((zarrs / "summary.json").read_text())["removed_from_earlier_run"]
    assert "labels.zarr" in removed
    _segment(zarrs, "--format", "zarr")
    assert not list(zarrs.glob("*.tif")) and (zarrs / "labels.zarr").is_dir()
    capsys.readouterr()
