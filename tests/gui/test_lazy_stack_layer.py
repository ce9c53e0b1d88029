"""Big stacks shown from disk (issue 39, point 4, the plugin's part).

The plugin's reader opens a stack over ``LAZY_BYTES`` as a Dask-backed layer (lowered
here so that a small file takes the lazy path, exactly as napari's File ▸ Open calls
it); the Segment dock reads it whole in its worker for a run, saying so in the status
line, and refuses it beyond the memory limit. A result written as OME-Zarr opens as lazy
multiscale layers.
"""

from __future__ import annotations

import time
from pathlib import Path

import dask.array as da
import numpy as np
import pytest
from _gui_helpers import click, error_messages, run_and_wait, wait_idle
from napari.layers import Image, Labels

import napari_polarseg
import napari_polarseg.io.lazy_stack as lazy_stack
import napari_polarseg.widgets.session.store as store_module
from napari_polarseg import _reader
from napari_polarseg.engine import Scene
from napari_polarseg.engine.params import AUTO
from napari_polarseg.io import write_stack_tiff, write_zarr

SAMPLE = Path(napari_polarseg.__file__).parent / "sample_data" / "leaves.npz"


@pytest.fixture
def leaves_tiff(tmp_path: Path) -> tuple[Path, np.ndarray, np.ndarray]:
    with np.load(SAMPLE) as data:
        stack, angles = data["stack"], data["angles"]
    path = tmp_path / "big_leaves.tif"
    write_stack_tiff(path, stack, angles)
    return path, stack, angles


@pytest.fixture
def lazy_open(viewer, monkeypatch):
    """Open a file with the plugin as napari does, with every stack "big"."""
    monkeypatch.setattr(lazy_stack, "LAZY_BYTES", 1024)

    def _open(path: Path):
        layers = viewer.open(str(path), plugin="napari-polarseg")
        assert len(layers) == 1
        return layers[0]

    return _open


def test_big_stack_opens_as_a_dask_layer_and_runs(
    viewer, add_widget, qtbot, monkeypatch, leaves_tiff, lazy_open
):
    path, stack, angles = leaves_tiff
    layer = lazy_open(path)
    assert isinstance(layer, Image) and isinstance(layer.data, da.Array)
    assert layer.data.shape == stack.shape and layer.metadata["reader"]["lazy"] is True
    assert layer.metadata["angles_deg"] == [float(a) for a in angles]

    real_read = store_module.read_whole

    def slow_read(data):  # a big file takes a while: the status line says what happens
        time.sleep(1.0)
        return real_read(data)

    monkeypatch.setattr(store_module, "read_whole", slow_read)
    widget = add_widget("Segment by material", preset=None)
    assert widget.stack_layer.value is layer
    time.sleep(0.3)
    assert widget.store.get(str(layer.unique_id)) is None  # choosing it read nothing
    click(qtbot, widget.run_button)
    qtbot.waitUntil(lambda: "reading the stack" in widget.status.value, timeout=5000)
    assert widget.status.value.startswith(
        "running: reading the stack (7 x 120 x 130 uint16, 213.3 KiB) from disk into memory"
    )
    wait_idle(qtbot, widget)
    assert error_messages() == []
    ref = Scene(stack, np.deg2rad(angles)).segment(AUTO)
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)
    assert isinstance(layer.data, da.Array)  # the layer still shows the file lazily
    held = widget.store.stack_of(str(layer.unique_id))
    assert isinstance(held, np.ndarray)
    np.testing.assert_array_equal(held, stack)

    # a rerun with other values does not read the file again
    monkeypatch.setattr(store_module, "read_whole", None)  # would fail if called
    widget.n_segments.value = 3
    run_and_wait(qtbot, widget)
    assert error_messages() == [] and "segments" in widget.status.value
    assert widget.store.stack_of(str(layer.unique_id)) is held


def test_big_stack_over_the_memory_limit_is_refused(
    viewer, add_widget, qtbot, monkeypatch, leaves_tiff, lazy_open
):
    layer = lazy_open(leaves_tiff[0])
    monkeypatch.setenv("POLARSEG_MAX_BYTES", "100K")
    widget = add_widget("Segment by material", preset=None)
    run_and_wait(qtbot, widget)
    status = widget.status.value
    assert status.startswith("error: the stack (7 x 120 x 130 uint16, 213.3 KiB)"), status
    assert "more than the limit of 100.0 KiB" in status and "POLARSEG_MAX_BYTES" in status
    assert widget.output("segments") is None
    assert error_messages() and "more than the limit" in error_messages()[-1]
    assert widget.store.get(str(layer.unique_id)) is None
    # with the limit raised it runs
    monkeypatch.setenv("POLARSEG_MAX_BYTES", "1G")
    run_and_wait(qtbot, widget)
    assert widget.output("segments") is not None


def test_zarr_stack_opens_lazily(viewer, tmp_path, leaves_tiff, add_widget, qtbot):
    import zarr

    _, stack, angles = leaves_tiff
    path = tmp_path / "leaves.zarr"
    z = zarr.open_array(path, mode="w", shape=stack.shape, chunks=(7, 64, 64), dtype=stack.dtype)
    z[:] = stack
    z.attrs["angles_deg"] = [float(a) for a in angles]
    reader = _reader.get_reader(str(path))
    assert reader is _reader.read_angle_stack
    data, kwargs, kind = reader(str(path), lazy="always")[0]
    assert kind == "image" and isinstance(data, da.Array)
    np.testing.assert_array_equal(np.asarray(data), stack)
    layer = viewer.add_image(data, **kwargs)
    widget = add_widget("Segment by material", preset=None)
    assert widget.stack_layer.value is layer
    wait_idle(qtbot, widget)
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    ref = Scene(stack, np.deg2rad(angles)).segment(AUTO)
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)


def test_result_ome_zarr_opens_as_multiscale_layers(viewer, tmp_path):
    rng = np.random.default_rng(0)
    labels = rng.integers(0, 5, (1100, 1300)).astype(np.uint16)
    write_zarr(tmp_path / "labels.zarr", labels, {"quantity": "segment labels"}, labels=True)
    stokes = rng.random((3, 600, 700)).astype(np.float32)
    write_zarr(tmp_path / "stokes.zarr", stokes, {"components": ["S0", "S1", "S2"]})
    write_zarr(tmp_path / "dop.zarr", stokes[1, :100, :100], {"quantity": "dop"})
    (tmp_path / "other.zarr").mkdir()  # not a Zarr store: left to other readers
    assert _reader.get_reader(str(tmp_path / "other.zarr")) is None

    layers = viewer.open(str(tmp_path / "labels.zarr"), plugin="napari-polarseg")
    (lab,) = layers
    assert isinstance(lab, Labels) and lab.multiscale and lab.name == "labels"
    assert all(isinstance(level, da.Array) for level in lab.data)
    assert [tuple(level.shape) for level in lab.data] == [(1100, 1300), (550, 650), (275, 325)]
    np.testing.assert_array_equal(np.asarray(lab.data[0]), labels)

    planes = viewer.open(str(tmp_path / "stokes.zarr"), plugin="napari-polarseg")
    assert [p.name for p in planes] == ["S0", "S1", "S2"]
    assert all(isinstance(p, Image) and p.multiscale and p.data[0].ndim == 2 for p in planes)
    np.testing.assert_allclose(np.asarray(planes[2].data[0]), stokes[2])

    (dop,) = viewer.open(str(tmp_path / "dop.zarr"), plugin="napari-polarseg")
    assert isinstance(dop, Image) and not dop.multiscale and isinstance(dop.data, da.Array)
    assert error_messages() == []
