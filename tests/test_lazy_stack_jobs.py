"""A lazy (Dask) stack layer in the Segment dock's jobs, without Qt (issue 39, point 4):
the worker reads it whole once, first saying so as a stage, and refuses it beyond the
memory limit before reading anything."""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

import dask.array as da
import numpy as np
import pytest
from job_helpers import drive

from napari_polarseg.engine import PolarsegError, Scene
from napari_polarseg.engine.params import AUTO
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.widgets.session import PipelineStore, features_job, segment_request

ANGLES_DEG = [0, 45, 90, 135]


@pytest.fixture(scope="module")
def stack() -> np.ndarray:
    scene = make_scene("leaves", shape=(96, 104), angles_deg=ANGLES_DEG)
    return np.round(np.asarray(scene.stack) * 1000).astype(np.uint16)


def _job(store: PipelineStore, data: Any, **kw: Any) -> Generator[Any, None, Any]:
    request = segment_request(
        store, "k", data, np.deg2rad(ANGLES_DEG), AUTO, None, None, maps=False, **kw
    )
    return request.job(*request.args)


def test_a_lazy_stack_is_read_once_with_a_stage_of_its_own(stack):
    lazy = da.from_array(stack, chunks=(4, 48, 52))
    store = PipelineStore()
    assert store.needs_reading("k", lazy) and not store.needs_reading("k", stack)
    items, result = drive(_job(store, lazy))
    assert items[0][0] == "reading the stack (4 x 96 x 104 uint16, 78.0 KiB) from disk into memory"
    assert items[0][1] == 0
    ref = Scene(stack, np.deg2rad(ANGLES_DEG)).segment(AUTO, maps=False, reconstruction=False)
    np.testing.assert_array_equal(result.labels, ref.labels)
    held = store.stack_of("k")
    assert isinstance(held, np.ndarray) and held.dtype == np.uint16
    np.testing.assert_array_equal(held, stack)
    # the same layer again (and the features job): nothing read again
    assert not store.needs_reading("k", lazy)
    items, _ = drive(_job(store, lazy))
    assert not any("reading the stack" in str(item[0]) for item in items if isinstance(item, tuple))
    items, n = drive(features_job(store, "k", lazy, np.deg2rad(ANGLES_DEG), AUTO))
    assert [i[0] for i in items] == ["polarisation", "pixel features"] and n > 0
    # a new mask rebuilds the pipeline on the stack already read
    region = np.ones(stack.shape[1:], bool)
    region[:10] = False
    store.obtain("k", lazy, np.deg2rad(ANGLES_DEG), AUTO, region=region, mask_key="m")
    assert store.stack_of("k") is held


def test_a_lazy_stack_over_the_limit_is_refused_before_reading(stack, monkeypatch):
    def never(block: np.ndarray) -> np.ndarray:
        raise AssertionError("read despite the limit")

    lazy = da.from_array(stack, chunks=(4, 48, 52)).map_blocks(never, dtype=stack.dtype)
    monkeypatch.setenv("POLARSEG_MAX_BYTES", "200K")
    store = PipelineStore()
    for job in (
        _job(store, lazy),
        features_job(store, "k", lazy, np.deg2rad(ANGLES_DEG), AUTO),
    ):
        with pytest.raises(PolarsegError) as err:
            next(job)
        message = str(err.value)
        assert message.startswith("the stack (4 x 96 x 104 uint16, 78.0 KiB) is shown from disk")
        assert "would need 390.0 KiB, more than the limit of 200.0 KiB" in message
        assert "POLARSEG_MAX_BYTES" in message
    assert store.get("k") is None
