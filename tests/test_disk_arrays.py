"""Full-size arrays in temporary files when they do not fit the run's memory limit
(issue 39): the same labels and maps as in memory, and no file left behind."""

from __future__ import annotations

import errno
import gc
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from napari_polarseg._sample_data import SAMPLE_DIR
from napari_polarseg.engine import PRESETS, Scene, disk_arrays
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.limits import KEPT_MAPS, RUNTIME_BYTES
from napari_polarseg.engine.physics.pixel_mask import usable_extremes
from napari_polarseg.engine.result import Normals

AUTO = PRESETS["auto"]
LINUX = sys.platform.startswith("linux")


def _leaves(copies: int) -> tuple[np.ndarray, np.ndarray]:
    data = np.load(SAMPLE_DIR / "leaves.npz")
    return np.tile(data["stack"], (1, copies, copies)), np.deg2rad(data["angles"])


def _mapped_files(directory: Path) -> list[str]:
    """The lines of this process's memory map naming a file in ``directory``."""
    with open("/proc/self/maps") as f:
        return [line for line in f if str(directory) in line]


def test_a_disk_array_is_an_array_whose_values_survive_their_release(tmp_path):
    a = disk_arrays.disk_empty((300, 400), np.float32, directory=str(tmp_path))
    assert a.shape == (300, 400) and a.dtype == np.float32 and a.flags.writeable
    assert not a.any()  # a new file reads as zeros
    assert disk_arrays.is_on_disk(a) and disk_arrays.is_on_disk(a.reshape(-1)[7:])
    assert not disk_arrays.is_on_disk(np.zeros(3))
    a[...] = np.arange(a.size, dtype=np.float32).reshape(a.shape)
    disk_arrays.release(a, None, np.ones(2))
    assert np.array_equal(a, np.arange(a.size, dtype=np.float32).reshape(a.shape))
    assert list(tmp_path.iterdir()) == []  # the file has no name
    copy = disk_arrays.copy_of(a, np.float64)
    assert copy.dtype == np.float64 and np.array_equal(copy, a)


@pytest.mark.skipif(not LINUX, reason="reads /proc/self/maps")
def test_the_file_is_gone_with_the_last_view(tmp_path):
    a = disk_arrays.disk_empty((64, 1024), directory=str(tmp_path))
    view = a[10:20]
    del a
    gc.collect()
    assert len(_mapped_files(tmp_path)) == 1  # the view keeps it
    del view
    gc.collect()
    assert _mapped_files(tmp_path) == [] and list(tmp_path.iterdir()) == []


def test_the_limit_places_the_arrays():
    assert disk_arrays.FULL_SIZE_BYTES_PER_PIXEL == 8 * KEPT_MAPS + 24
    shape = (1000, 1000)
    assert not disk_arrays.pixels_on_disk(10**9)  # no limit set: in memory, as before
    assert not disk_arrays.is_on_disk(disk_arrays.empty(shape))
    small = int(shape[0] * shape[1] * disk_arrays.FULL_SIZE_BYTES_PER_PIXEL)
    with disk_arrays.full_size_limit(small):
        assert disk_arrays.is_on_disk(disk_arrays.empty(shape, np.int32))
        assert disk_arrays.is_on_disk(disk_arrays.zeros((4, *shape), np.uint8))
        assert not disk_arrays.is_on_disk(disk_arrays.empty((100, 100)))
    with disk_arrays.full_size_limit(100 * small):
        assert not disk_arrays.is_on_disk(disk_arrays.empty(shape))


def test_kept_moves_the_full_size_arrays_of_a_stage_value():
    shape = (200, 300)
    phase = disk_arrays.disk_empty(shape)
    value = Normals(np.full(shape, 0.5), phase.view(), np.ones(shape, dtype=bool))
    assert disk_arrays.kept(value, shape) is value  # no limit: as it is
    with disk_arrays.full_size_limit(1):
        moved = disk_arrays.kept(value, shape)
    assert all(disk_arrays.is_on_disk(a) for a in (moved.zenith, moved.clamped))
    assert moved.azimuth is value.azimuth  # already on disk
    assert np.array_equal(moved.zenith, value.zenith)
    assert np.array_equal(moved.clamped, value.clamped)


def test_a_full_disk_is_an_error_not_a_crash(monkeypatch, tmp_path):
    def full(fd, offset, size):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "posix_fallocate", full, raising=False)
    with pytest.raises(PolarsegError, match="no room"):
        disk_arrays.disk_empty((10, 10), directory=str(tmp_path))


def test_usable_extremes_equal_the_boolean_index():
    rng = np.random.default_rng(0)
    valid = rng.random((30, 40)) > 0.4
    for dtype in (np.uint8, np.uint16, np.int16, np.float32, np.float64):
        stack = (rng.random((4, 30, 40)) * 200 - 50).astype(dtype)
        used = stack[:, valid]
        assert usable_extremes(stack, valid) == (float(used.min()), float(used.max()))
    assert usable_extremes(stack, np.ones((30, 40), bool)) == (stack.min(), stack.max())


def _run(stack, angles, limit):
    scene = Scene(stack, angles, max_bytes=limit)
    result = scene.segment(AUTO, maps=False, reconstruction=False)
    return scene, result


@pytest.mark.skipif(not LINUX, reason="reads /proc/self/maps")
def test_a_scene_beyond_its_limit_works_on_disk_and_gives_the_same_labels(monkeypatch, tmp_path):
    stack, angles = _leaves(3)  # 7 x 360 x 390
    held = stack.nbytes + stack.size + RUNTIME_BYTES
    limit = held + 12 * 2**20  # tiled, and the full-size arrays beyond its half
    monkeypatch.setenv(disk_arrays.SCRATCH_ENV, str(tmp_path))
    scene, result = _run(stack, angles, limit)
    pol = scene.polarisation(AUTO)
    on_disk = (pol.intensity, pol.dop, pol.phase, pol.residual, pol.invalid, scene.mask.flags)
    assert all(disk_arrays.is_on_disk(a) for a in on_disk)
    assert disk_arrays.is_on_disk(result.labels) and disk_arrays.is_on_disk(result.zenith)
    assert result.method_record["k"] >= 2
    out = scene.method_output(AUTO)  # kept by the scene: its labels on disk, once
    assert disk_arrays.is_on_disk(out.labels)
    assert out.extra["unsupervised"].labels is out.labels
    maps = ("labels", "intensity", "dop", "phase", "residual", "zenith", "clamped", "valid")
    disk = {name: np.array(getattr(result, name)) for name in maps}
    assert _mapped_files(tmp_path)  # while the scene and its result live
    del scene, result, pol, on_disk, out
    gc.collect()
    assert _mapped_files(tmp_path) == [] and list(tmp_path.iterdir()) == []
    # the same limit (the same tiles), every array in memory
    monkeypatch.setattr(disk_arrays, "DISK_SHARE", float("inf"))
    scene, result = _run(stack, angles, limit)
    assert not disk_arrays.is_on_disk(result.labels)
    assert not disk_arrays.is_on_disk(scene.polarisation(AUTO).intensity)
    for name in maps:
        np.testing.assert_array_equal(disk[name], getattr(result, name), err_msg=name)
    assert result.labels.dtype == np.int64
