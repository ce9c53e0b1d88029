"""Pixel labels of a region model made tile by tile (:mod:`.tiled_regions`), written tile
by tile.

:func:`~.segmenter.pixel_labels` on a whole image gives every pixel its superpixel's
label (outside the clustered pixels, the nearest clustered pixel's), moves the pixels on
a segment border to the neighbouring segment whose mean (log Î, ρ) they resemble most
(:func:`~.boundaries.refined_labels`, up to
:data:`~.boundaries.REFINE_PASSES` one-pixel passes) and numbers the segments in order
of first appearance. :class:`TiledLabels` does the same on every tile's outer box and
keeps its core:

- the segments' means and pooled spread, which the refinement compares with, come from
  the superpixels' sums of log Î, (log Î)², ρ and ρ² over their clustered pixels
  (:func:`~.boundaries.segment_stats`): the same for every tile; each tile then updates
  them with its own moves only;
- a border moves at most one pixel a pass, so a core's refined labels read no further
  than :data:`~.boundaries.REFINE_PASSES` pixels into the halo;
- the outside pixels take the nearest clustered pixel's label within the outer box;
- the first appearance of each segment is the smallest raster index of its pixels over
  every core.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .. import disk_arrays
from ..tile_map import tile_map_for
from ..tiles import Tile, TileGrid
from .boundaries import SegmentStats, refine_maps, refined_labels, segment_stats
from .tile_maps import filled_box
from .tiled_region_tasks import box_payload

if TYPE_CHECKING:
    from .segmenter import RegionModel

#: Rows of the labels renumbered at once (bounds the temporaries).
BAND_ROWS = 512


def in_order_of_appearance(
    labels: np.ndarray, node_labels: np.ndarray, first: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(labels, node labels) renumbered, ``labels`` in place, in order of ``first`` (the
    smallest raster index of each label's pixels; the largest int64 for a label with
    none, which takes 0 as in :func:`~.segmenter.first_appearance`)."""
    present = np.flatnonzero(first < np.iinfo(np.int64).max)
    values = present[np.argsort(first[present], kind="stable")]
    size = max(first.size, int(node_labels.max()) + 1 if node_labels.size else 0)
    order = np.zeros(size, dtype=np.int32)
    order[values] = np.arange(values.size, dtype=np.int32)
    for top in range(0, labels.shape[0], BAND_ROWS):
        band = labels[top : top + BAND_ROWS]
        band[...] = order[band]
    return labels, order[node_labels]


@dataclass(frozen=True)
class TiledLabels:
    """The ``labeller`` of a tiled :class:`~.segmenter.RegionModel` (module docstring).

    Attributes
    ----------
    grid : TileGrid
        The tiles the model was made on (their halos hold the refinement's reach).
    moments : ndarray (4, n)
        Σ log Î, Σ (log Î)², Σ ρ, Σ ρ² over the clustered pixels of each of the n
        superpixels (log Î in ln of the input's units, not centred).
    """

    grid: TileGrid
    moments: np.ndarray

    @classmethod
    def of(
        cls,
        grid: TileGrid,
        terms: dict[str, np.ndarray],
        count: np.ndarray,
        centre: float,
        n: int,
    ) -> TiledLabels:
        """From the superpixels' sums of the per-pixel terms (log Î centred on
        ``centre``: Σ (l + c) = Σ l + c N, Σ (l + c)² = Σ l² + 2c Σ l + c² N) and their
        pixel counts N; the first ``n`` are the clustered superpixels."""
        c, size = float(centre), np.asarray(count[:n], dtype=np.float64)
        log_sum, log_square = terms["l"][:n], terms["ll"][:n]
        return cls(
            grid,
            np.stack(
                [
                    log_sum + c * size,
                    log_square + 2.0 * c * log_sum + c * c * size,
                    terms["d"][:n],
                    terms["dd"][:n],
                ]
            ),
        )

    def stats(self, node_labels: np.ndarray, weight: np.ndarray, m: int) -> SegmentStats:
        """The m segments' :func:`~.boundaries.segment_stats` from the superpixels'."""

        def per_segment(values: np.ndarray) -> np.ndarray:
            return np.bincount(node_labels, weights=values, minlength=m)

        sums = np.stack([per_segment(self.moments[0]), per_segment(self.moments[2])])
        squares = np.stack([per_segment(self.moments[1]), per_segment(self.moments[3])])
        return segment_stats(per_segment(weight), sums, squares)

    def __call__(
        self, model: RegionModel, node_labels: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(labels (H, W) int32, node labels (n,)) of ``model`` whose superpixels are
        labelled ``node_labels``: :func:`~.segmenter.pixel_labels` tile by tile, each
        tile on the current tile map (:func:`~..tile_map.tile_map_for`)."""
        node_labels = np.asarray(node_labels, dtype=np.int32)
        m = int(node_labels.max()) + 1 if node_labels.size else 1
        lookup = node_labels if model.valid is None else np.append(node_labels, 0)
        lookup = lookup.astype(np.int32)
        refine = model.used_params.refine_boundaries and m > 1
        stats = self.stats(node_labels, model.weight, m) if refine else None
        shape = model.regions.shape
        plain = stats is None and model.valid is None  # no pixel maps needed

        def payloads() -> Iterator[tuple]:
            for tile in self.grid:
                maps, valid = (
                    (None, None) if plain else box_payload(model.maps, model.valid, tile.outer)
                )
                regions = model.regions[tile.outer]
                yield regions, lookup, maps, valid, tile, m, stats, shape[1]

        labels = disk_arrays.empty(shape, dtype=np.int32)  # on disk when it does not fit
        first = np.full(m, np.iinfo(np.int64).max)
        cores = tile_map_for(self.grid)(core_labels, payloads())
        for tile, (core, tile_first) in zip(self.grid, cores, strict=True):
            labels[tile.core] = core
            np.minimum(first, tile_first, out=first)
        return in_order_of_appearance(labels, node_labels, first)


def core_labels(
    regions: np.ndarray,
    lookup: np.ndarray,
    maps: tuple[np.ndarray, ...] | None,
    valid: np.ndarray | None,
    tile: Tile,
    m: int,
    stats: SegmentStats | None,
    width: int,
) -> tuple[np.ndarray, np.ndarray]:
    """One core's labels (h, w) int32 and the smallest raster index (image of ``width``
    columns) of each of the ``m`` labels' pixels in it (the largest int64 for none):
    its outer box's superpixels (``regions``) labelled by ``lookup``, the outside
    pixels (not ``valid``) the nearest clustered one's, refined with ``stats`` on the
    box's ``maps`` (Î, ρ, φ) when given (module docstring)."""
    labels = lookup[regions]
    if maps is not None:
        filled, _, nearest = filled_box(maps, valid, (slice(None), slice(None)))
        if nearest is not None:
            labels = labels.ravel()[nearest]
        if stats is not None:
            i, d = filled[0], filled[1]
            labels = refined_labels(labels, i, d, m, refine_maps(i, d), stats)
            if nearest is not None:
                labels = labels.ravel()[nearest]
    (r0, r1), (c0, c1) = (
        (tile.core[0].start, tile.core[0].stop),
        (tile.core[1].start, tile.core[1].stop),
    )
    core = np.ascontiguousarray(labels[tile.inner]).reshape(r1 - r0, c1 - c0)
    rows = np.arange(r0, r1, dtype=np.int64)
    cols = np.arange(c0, c1, dtype=np.int64)
    first = np.full(m, np.iinfo(np.int64).max)
    np.minimum.at(first, core.ravel(), (rows[:, None] * width + cols).ravel())
    return core, first
