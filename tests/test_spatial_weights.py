"""Moran's I of node features over the superpixels' border graph, and the per-scene
weights it gives (engine/unsupervised/spatial_weights.py)."""

import numpy as np
import pytest

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.unsupervised.params import UnsupervisedParams
from napari_polarseg.engine.unsupervised.region_graph import region_adjacency
from napari_polarseg.engine.unsupervised.spatial_weights import coherence_weights, morans_i


def grid_graph(side: int):
    """The border graph of a side × side grid of square superpixels (4 px each), and
    each superpixel's row and column."""
    cells = np.arange(side * side).reshape(side, side)
    regions = np.kron(cells, np.ones((2, 2), dtype=int))
    rows, cols = np.divmod(np.arange(side * side), side)
    return region_adjacency(regions), rows, cols


def test_morans_i_known_answers():
    graph, rows, cols = grid_graph(16)
    halves = np.where(cols < 8, 1.0, -1.0)  # two patches: one border column of 16 pairs
    checker = np.where((rows + cols) % 2 == 0, 1.0, -1.0)  # every neighbour unlike
    noise = np.random.default_rng(0).standard_normal(rows.size)
    i = morans_i(np.stack([halves, checker, noise, np.ones(rows.size)], axis=1), graph)
    # halves: of the 2 × 480 directed neighbour pairs, 32 cross the middle (x_a x_b = −1)
    # and 928 do not (+1), every border the same length: I = (928 − 32) / 960
    assert i[0] == pytest.approx(896 / 960, abs=1e-9)
    assert i[1] == pytest.approx(-1.0, abs=1e-9)
    assert abs(i[2]) < 0.1
    assert i[3] == 0.0  # a constant column


def test_coherence_weights_rank_and_off():
    graph, rows, cols = grid_graph(16)
    rng = np.random.default_rng(1)
    smooth = np.where(cols < 8, 1.0, -1.0) + 0.1 * rng.standard_normal(rows.size)
    noisy = rng.standard_normal(rows.size)
    xs = np.stack([smooth, noisy], axis=1)
    w = coherence_weights(xs, graph, 1.0)
    assert w[0] == pytest.approx(1.0) and w[1] < 0.15
    assert coherence_weights(xs, graph, 2.0)[1] == pytest.approx(w[1] ** 2)
    assert np.array_equal(coherence_weights(xs, graph, 0.0), np.ones(2))


def test_coherence_power_checked():
    with pytest.raises(PolarsegError, match="coherence_power"):
        UnsupervisedParams(coherence_power=-1.0)
