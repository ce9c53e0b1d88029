"""The tile map of this process on threads (engine/tile_map.ThreadTileMap): results in
the payloads' order, at most one tile a thread in flight, the caller's context in every
task, a task's error raised to the caller, and tiles that share the memory limit."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from napari_polarseg.engine import disk_arrays
from napari_polarseg.engine.classifier.tiled_prediction import scribble_tiles
from napari_polarseg.engine.features.pixel_features import PixelFeatureParams
from napari_polarseg.engine.limits import scribble_bytes_per_pixel
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.tile_map import (
    ThreadTileMap,
    in_process,
    in_this_process,
    tiles_on,
)
from napari_polarseg.engine.unsupervised.tiled_regions import TILE_BYTES_PER_PIXEL, region_tiles


def _slow_square(i: int, delay: float) -> tuple[int, int, str]:
    time.sleep(delay)
    return i, i * i, threading.current_thread().name


def test_results_in_order_from_several_threads():
    tile_map = ThreadTileMap(2)
    # the first tile is the slowest: its result still comes first
    payloads = [(i, 0.05 if i == 0 else 0.001) for i in range(8)]
    results = list(tile_map(_slow_square, payloads))
    assert [r[:2] for r in results] == [(i, i * i) for i in range(8)]
    assert {r[2] for r in results} <= {f"polarseg-tile_{j}" for j in range(2)}
    assert len({r[2] for r in results}) == 2  # both threads worked


def test_at_most_one_tile_a_thread_in_flight():
    made: list[int] = []

    def payloads():
        for i in range(6):
            made.append(i)
            yield i, 0.0

    results = ThreadTileMap(3)(_slow_square, payloads())
    first = next(results)
    assert first[:2] == (0, 0)
    assert made == [0, 1, 2, 3]  # three in flight, then one more as the first is taken
    assert [r[0] for r in results] == [1, 2, 3, 4, 5]


def _limit_in_task() -> bool:
    return disk_arrays.pixels_on_disk(10**6)


def test_tasks_see_the_callers_memory_limit():
    with disk_arrays.full_size_limit(1):  # every full-size array on disk
        seen = list(ThreadTileMap(2)(_limit_in_task, [()] * 4))
    assert seen == [True] * 4
    assert list(ThreadTileMap(2)(_limit_in_task, [()] * 2)) == [False, False]


def _fails(i: int) -> int:
    if i == 2:
        raise ValueError("tile 2")
    return i


def test_a_tasks_error_reaches_the_caller():
    got: list[int] = []
    with pytest.raises(ValueError, match="tile 2"):
        for value in ThreadTileMap(2)(_fails, [(i,) for i in range(6)]):
            got.append(value)
    assert got == [0, 1]


def test_the_tiles_do_not_depend_on_the_threads():
    """The tile choices give the same tiles whatever map runs them (the labels do not
    depend on the machine's cores); how many run at once follows from the limit."""
    from napari_polarseg.engine.tile_map import tile_map_for

    shape, params = (8000, 8000), SurfaceSuperpixels().params
    with tiles_on(in_process):
        alone = region_tiles(shape, params, 5 * 2**30)
    with tiles_on(ThreadTileMap(2)):
        shared = region_tiles(shape, params, 5 * 2**30)
        assert shared == alone and in_this_process(tile_map_for(shared))
    assert alone is not None and alone.at_once >= 1
    # 64 MP: the full-size arrays go to temporary files and count as none beside the boxes
    box = (alone.core + 2 * alone.halo) ** 2 * TILE_BYTES_PER_PIXEL
    assert alone.at_once == int(5 * 2**30 // box)

    feature_params, shape = PixelFeatureParams(), (6000, 8000)
    with tiles_on(in_process):
        one = scribble_tiles(shape, feature_params, 136, 8, limit=8 * 2**30)
    with tiles_on(ThreadTileMap(2)):
        two = scribble_tiles(shape, feature_params, 136, 8, limit=8 * 2**30)
    assert one is not None and one == two and one.at_once >= 1


def test_threads_give_the_same_sums_as_one_after_the_other():
    rng = np.random.default_rng(0)
    arrays = [rng.random((300, 300)) for _ in range(7)]
    payloads = [(a, i) for i, a in enumerate(arrays)]

    def total(a: np.ndarray, i: int) -> float:
        return float((a * (i + 1)).sum())

    here = list(in_process(total, payloads))
    threads = list(ThreadTileMap(2)(total, payloads))
    assert here == threads


def test_scribble_tiles_at_once_follow_what_stays_in_memory():
    """The scribbles method's tiles where its full-size arrays alone exceed the limit:
    cores of a few halos; those arrays go to temporary files, so as many boxes run at
    once as the limit holds beside the bytes a pixel that stay in memory (48 MP at
    2 GiB: several; 100 MP: one, the threads narrowed to it). Where the limit holds the
    arrays, boxes as large as the budget, so one at a time; a grid that holds two runs
    on two of three threads."""
    from napari_polarseg.engine.classifier.tiled_prediction import RESIDENT_BYTES_PER_PIXEL
    from napari_polarseg.engine.tile_map import tile_map_for

    params, limit = PixelFeatureParams(), 2 * 2**30
    with tiles_on(ThreadTileMap(2)):
        tight = scribble_tiles((6000, 8000), params, 136, 8, limit=limit)
        huge = scribble_tiles((8192, 12240), params, 136, 8, limit=limit)
        roomy = scribble_tiles((6000, 8000), params, 136, 8, limit=8 * 2**30)
        assert tight is not None and huge is not None and roomy is not None
        assert tight.core == huge.core  # a few halos, whatever the size
        box = (tight.core + 2 * tight.halo) ** 2 * scribble_bytes_per_pixel(params)[0]
        assert tight.at_once == int((limit - 48e6 * RESIDENT_BYTES_PER_PIXEL) // box) >= 2
        assert tile_map_for(tight).threads == 2
        assert huge.at_once == 1 and tile_map_for(huge) is in_process
        assert roomy.core > tight.core and roomy.at_once == 1
    with tiles_on(ThreadTileMap(3)):
        assert tile_map_for(roomy.__class__(roomy.shape, roomy.core, roomy.halo, 8, 2)).threads == 2
