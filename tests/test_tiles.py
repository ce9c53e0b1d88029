"""The tile grid with halos (``engine/tiles.py``): cores cover the image exactly once,
halos and alignment hold, and the tile size follows the memory budget."""

import numpy as np
import pytest

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.tiles import MIN_CORE, TileGrid


@pytest.mark.parametrize("shape", [(100, 100), (257, 1000), (1024, 1224)])
def test_cores_cover_the_image_exactly_once(shape):
    grid = TileGrid(shape, core=128, halo=36, align=4)
    count = np.zeros(shape, dtype=int)
    for tile in grid:
        count[tile.core] += 1
        r, c = tile.outer
        assert r.start % 4 == 0 and c.start % 4 == 0  # aligned
        # the outer box holds the core and the halo, clipped at the image's edges
        assert r.start == max(tile.core[0].start - 36, 0)
        assert c.stop == min(tile.core[1].stop + 36, shape[1])
        inner = tile.inner
        assert inner[0].stop - inner[0].start == tile.core[0].stop - tile.core[0].start
    assert np.all(count == 1)
    assert len(grid) == len(list(grid))


def test_tile_size_follows_the_budget():
    shape = (6000, 8000)
    small = TileGrid.for_budget(shape, 200e6, 400, reach=130, align=4)
    large = TileGrid.for_budget(shape, 2e9, 400, reach=130, align=4)
    assert small.core < large.core
    for grid, budget in ((small, 200e6), (large, 2e9)):
        assert grid.core % 4 == 0 and grid.halo == 132
        assert grid.largest_outer * 400 <= budget
    # never below the smallest core, never beyond the image
    assert TileGrid.for_budget(shape, 1.0, 400, 130, 4).core == MIN_CORE
    assert TileGrid.for_budget((300, 200), 1e12, 400, 130, 4).core == 300


def test_bad_grids_are_refused():
    with pytest.raises(PolarsegError):
        TileGrid((10, 10), core=6, halo=4, align=4)


def test_borders_mark_both_sides_of_every_cut():
    grid = TileGrid((10, 12), core=4, halo=0)
    b = grid.borders()
    assert b[3].all() and b[4].all() and b[7].all() and b[8].all()
    assert b[:, 3].all() and not b[1, 1]
