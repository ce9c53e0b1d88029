"""Edge-aware diffusion over the region graph (engine/unsupervised/region_diffusion.py)."""

from __future__ import annotations

import numpy as np
import pytest

from napari_polarseg.engine.unsupervised.region_diffusion import (
    MAX_STEPS,
    border_strength,
    diffuse,
    diffusion_steps,
    edge_aware_adjacency,
)


def strip_regions(n: int = 6, width: int = 4, height: int = 5) -> np.ndarray:
    """n vertical strips of ``width`` columns: region j borders j − 1 and j + 1."""
    return np.repeat(np.arange(n), width)[None, :].repeat(height, axis=0).astype(np.int32)


def test_border_lengths_and_strengths():
    regions = strip_regions(3)
    edges = np.zeros(regions.shape)
    edges[:, 4] = 2.0  # the first column of region 1: on the 0|1 border
    rows, cols, length, strength = border_strength(regions, edges)
    assert rows.tolist() == [0, 1] and cols.tolist() == [1, 2]
    np.testing.assert_array_equal(length, [5, 5])  # five rows of pixel pairs each
    np.testing.assert_allclose(strength, [2.0, 0.0])


def test_several_edge_maps_are_read_along_the_same_borders():
    """A (C, H, W) stack gives one strength column per map, each that map's own."""
    regions = strip_regions(3)
    first, second = np.zeros(regions.shape), np.zeros(regions.shape)
    first[:, 4], second[:, 8] = 2.0, 3.0  # on the 0|1 border, on the 1|2 border
    rows, cols, length, both = border_strength(regions, np.stack([first, second]))
    assert both.shape == (2, 2)
    for column, edges in enumerate((first, second)):
        r, c, n, alone = border_strength(regions, edges)
        np.testing.assert_array_equal(both[:, column], alone)
        assert r.tolist() == rows.tolist() and c.tolist() == cols.tolist()
        np.testing.assert_array_equal(n, length)
    np.testing.assert_allclose(both, [[2.0, 0.0], [0.0, 3.0]])


def test_diffusion_mixes_across_weak_borders_only():
    """Strips 0-2 and 3-5 are two surfaces split by a strong edge: after diffusion each
    strip holds its surface's mean feature, and the surfaces keep theirs."""
    regions = strip_regions(6)
    edges = np.ones(regions.shape)
    edges[:, 11:13] = 50.0  # the 2|3 border (columns 11 | 12)
    x = np.array([[1.0], [2.0], [3.0], [10.0], [11.0], [12.0]])
    graph = edge_aware_adjacency(regions, edges, tau=1.0)
    assert graph[2, 3] < 1e-12 * graph[0, 1]
    y = diffuse(x, graph, 0.5, 200)
    np.testing.assert_allclose(y[:3, 0], 2.0, atol=1e-6)
    np.testing.assert_allclose(y[3:, 0], 11.0, atol=1e-6)


def test_diffusion_keeps_constants_and_isolated_nodes():
    regions = strip_regions(4)
    graph = edge_aware_adjacency(regions, np.ones(regions.shape))
    np.testing.assert_allclose(diffuse(np.full((4, 2), 3.5), graph, 0.5, 10), 3.5)
    lone = np.zeros((5, 5), dtype=np.int32)  # one region, no neighbour
    g1 = edge_aware_adjacency(lone, np.ones((5, 5)))
    np.testing.assert_array_equal(diffuse(np.array([[7.0]]), g1, 0.5, 10), [[7.0]])


def test_no_strength_or_no_steps_is_the_identity():
    regions = strip_regions(3)
    graph = edge_aware_adjacency(regions, np.ones(regions.shape))
    x = np.array([[1.0], [5.0], [9.0]])
    assert diffuse(x, graph, 0.0, 10) is x
    assert diffuse(x, graph, 0.5, 0) is x


@pytest.mark.parametrize(
    ("reach", "n", "strength", "steps"),
    [(0.07, 3000, 0.5, 30), (0.07, 500, 0.5, 5), (0.0, 3000, 0.5, 0), (0.5, 10**6, 0.5, MAX_STEPS)],
)
def test_steps_spread_over_a_share_of_the_image(reach, n, strength, steps):
    """t = ⌈reach² n / λ⌉: the same share of the frame at any resolution, bounded."""
    assert diffusion_steps(reach, n, strength) == steps
