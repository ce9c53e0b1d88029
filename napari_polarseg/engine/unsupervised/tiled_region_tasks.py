"""The work on one tile of the default method's tiled superpixels (:mod:`.tiled_regions`).

Each task reads only its tile's arrays — the outer box of Î, ρ, φ (float32, as
:func:`~.tile_maps.filled_box` checks them), of the clustered pixels, and a few small
values — and returns only what the whole image's step needs of the tile: histograms
(:func:`edge_histograms`) or the core's superpixels with their sums and border pairs
(:func:`region_core`). So a task runs the same in this process or on a Dask worker
(:mod:`..tile_map`), in memory bounded by the tile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from skimage.util import regular_grid

from ..features.pixel_features import check_maps
from ..features.superpixels import (
    border_channels,
    edge_gradients,
    edge_terms,
    watershed_on_grid,
)
from ..tiles import Box, Tile
from .region_features import pixel_terms
from .tile_maps import filled_box

#: Bins of :func:`log_histogram` and the range of log₂ of the values they cover.
LOG_BINS, LOG_RANGE = 1 << 16, (-40.0, 24.0)
#: The whole of a box, as a box.
ALL: Box = (slice(None), slice(None))

Maps = tuple[np.ndarray, np.ndarray, np.ndarray]
Pairs = tuple[np.ndarray, np.ndarray, np.ndarray]


def box_payload(
    maps: tuple[np.ndarray, ...], valid: np.ndarray | None, box: Box
) -> tuple[Maps, np.ndarray | None]:
    """(Î, ρ, φ of ``box`` as float32 copies with non-finite values 0, the box's part of
    ``valid`` or None): what a task reads of the image."""
    parts = check_maps(*(m[box] for m in maps))
    return parts, (None if valid is None else np.ascontiguousarray(valid[box]))


def log_histogram(values: np.ndarray) -> np.ndarray:
    """Counts of the non-negative ``values`` in :data:`LOG_BINS` bins of log₂ v from
    2^:data:`LOG_RANGE`[0] to 2^:data:`LOG_RANGE`[1] (smaller values, zero too, in the
    first bin, larger in the last): bins 0.1 % wide."""
    lo, hi = LOG_RANGE
    with np.errstate(divide="ignore"):
        x = (np.log2(values.ravel()) - lo) * (LOG_BINS / (hi - lo))
    index = np.clip(np.nan_to_num(x, nan=0.0, neginf=0.0), 0, LOG_BINS - 1).astype(np.intp)
    return np.bincount(index, minlength=LOG_BINS)


def edge_histograms(
    maps: Maps, valid: np.ndarray | None, inner: Box, polarisation: bool
) -> np.ndarray:
    """(3, :data:`LOG_BINS`) int64: the :func:`log_histogram` of Î, of the edge map's
    intensity gradient and of its polarisation gradient (zeros without
    ``polarisation``) over the part ``inner`` of one box (its maps and clustered pixels
    ``valid``)."""
    (i, d, ph), _, _ = filled_box(maps, valid, ALL)
    grad, pol = edge_gradients(i, d, ph, polarisation)
    counts = np.zeros((3, LOG_BINS), dtype=np.int64)
    counts[0] = log_histogram(i[inner])
    counts[1] = log_histogram(grad[inner])
    if pol is not None:
        counts[2] = log_histogram(pol[inner])
    return counts


@dataclass(frozen=True)
class Seeds:
    """The whole image's watershed seeds: scikit-image's ``regular_grid`` of ``n`` points
    on ``shape``, numbered 1 … in raster order (as ``watershed(image, markers=n)``
    numbers them)."""

    rows: np.ndarray
    cols: np.ndarray

    @classmethod
    def of(cls, shape: tuple[int, int], n: int) -> Seeds:
        grid = regular_grid(shape, n)
        return cls(np.arange(shape[0])[grid[0]], np.arange(shape[1])[grid[1]])

    @property
    def count(self) -> int:
        return self.rows.size * self.cols.size

    def markers(self, box: Box) -> np.ndarray:
        """(h, w) int32: the seeds inside ``box`` with their numbers, 0 elsewhere."""
        r0, r1, c0, c1 = box[0].start, box[0].stop, box[1].start, box[1].stop
        out = np.zeros((r1 - r0, c1 - c0), dtype=np.int32)
        ir = np.flatnonzero((self.rows >= r0) & (self.rows < r1))
        ic = np.flatnonzero((self.cols >= c0) & (self.cols < c1))
        ids = 1 + ir[:, None] * self.cols.size + ic[None, :]
        out[np.ix_(self.rows[ir] - r0, self.cols[ic] - c0)] = ids
        return out


def border_pairs(a: np.ndarray, b: np.ndarray, ea: np.ndarray, eb: np.ndarray, n: int) -> Pairs:
    """(keys lo·n + hi, pair counts L, summed edge strengths Σ max(e_a, e_b) (m, C)) of
    the pixel pairs (a, b) of two regions that differ, one row per region pair; ``ea``,
    ``eb`` hold C edge maps' values (C, *a.shape)."""
    differ = a != b
    a, b = a[differ].astype(np.int64), b[differ].astype(np.int64)
    e = np.maximum(ea[:, differ], eb[:, differ]).astype(np.float64)
    keys, inverse = np.unique(np.minimum(a, b) * n + np.maximum(a, b), return_inverse=True)
    sums = np.stack([np.bincount(inverse, weights=c, minlength=keys.size) for c in e], axis=1)
    return keys, np.bincount(inverse).astype(np.float64), sums


@dataclass(frozen=True)
class CoreSums:
    """What one core adds to the whole image's superpixels (:func:`region_core`).

    Attributes
    ----------
    regions : ndarray (h, w) int32
        The core's superpixels, numbered by their seeds from 0 (outside pixels: the
        last number).
    ids : ndarray (r,)
        The region numbers present in the core, ascending.
    count, terms, position :
        Their pixel counts (r,), sums of the per-pixel terms (name → (r,)) and sums of
        the rows and columns (2, r).
    pairs : list of (keys, L, Σ e)
        The pixel pairs across borders inside the core (:func:`border_pairs`: left-right,
        then up-down).
    right, below : ndarray (2, C, h) / (2, C, w) or None
        The border maps' values on both sides of the cut right of / below the core (None
        at the image's edge).
    """

    regions: np.ndarray
    ids: np.ndarray
    count: np.ndarray
    terms: dict[str, np.ndarray]
    position: np.ndarray
    pairs: list[Pairs]
    right: np.ndarray | None
    below: np.ndarray | None


def _sums(core: np.ndarray, box: Box, px: dict[str, np.ndarray], n: int) -> tuple:
    """(ids, count, terms, position) of the regions of ``core`` at ``box`` (image
    coordinates) with the per-pixel terms ``px`` of its pixels: ``np.bincount`` over n
    regions, kept for the regions present."""
    flat = core.ravel()
    full = np.bincount(flat, minlength=n).astype(np.float64)
    ids = np.flatnonzero(full)
    terms = {
        name: np.bincount(flat, weights=term.ravel(), minlength=n)[ids] for name, term in px.items()
    }
    h, w = core.shape
    rows = np.repeat(np.arange(box[0].start, box[0].stop, dtype=np.float64), w)
    cols = np.tile(np.arange(box[1].start, box[1].stop, dtype=np.float64), h)
    position = np.stack([np.bincount(flat, weights=v, minlength=n)[ids] for v in (rows, cols)])
    return ids, full[ids], terms, position


def _cut_edges(tile: Tile, edges: np.ndarray, shape: tuple[int, int]) -> tuple:
    """(right, below) of :class:`CoreSums`: copies of the values of the C border maps
    ``edges`` (C, h, w) on both sides of the cuts right of and below the core (its box
    reads them: they are the whole image's)."""
    (r0, r1), (c0, c1) = (
        (tile.core[0].start, tile.core[0].stop),
        (tile.core[1].start, tile.core[1].stop),
    )
    o_r, o_c = tile.outer[0].start, tile.outer[1].start
    right = below = None
    if c1 < shape[1]:
        cut = edges[:, r0 - o_r : r1 - o_r, c1 - 1 - o_c : c1 + 1 - o_c]
        right = np.ascontiguousarray(np.moveaxis(cut, 2, 0))
    if r1 < shape[0]:
        cut = edges[:, r1 - 1 - o_r : r1 + 1 - o_r, c0 - o_c : c1 - o_c]
        below = np.ascontiguousarray(np.moveaxis(cut, 1, 0))
    return right, below


def region_core(
    maps: Maps,
    valid: np.ndarray | None,
    tile: Tile,
    seeds: Seeds,
    weight: float,
    scales: tuple[float, float],
    centre: float,
    shape: tuple[int, int],
    grain: bool = False,
    grid: int = 1,
    border: float = 1.0,
    apart: bool = False,
) -> CoreSums:
    """One tile's superpixels and sums (:mod:`.tiled_regions`, steps 1–3): the compact
    watershed from the whole image's ``seeds`` on the edge map of its outer box
    (``maps`` and clustered pixels ``valid`` of ``tile.outer``; edge ``weight`` and
    ``scales``; on its ``grid`` × ``grid`` blocks, the box starting on a multiple of
    ``grid``), kept on the core; the outside pixels numbered ``seeds.count``; the
    sums of the per-pixel terms (log Î centred on ``centre``; with ``grain`` the grain
    maps too) over the regions. The border pairs carry the watershed's edge map or, with
    ``apart``, its two terms apart, the log Î one weighed ``border``
    (``UnsupervisedParams.border_intensity_weight``;
    :func:`~..features.superpixels.border_channels`)."""
    filled, v, _ = filled_box(maps, valid, ALL)
    parts = edge_terms(filled, weight, scales)
    edges = parts.sum(axis=0)
    labels = watershed_on_grid(edges, seeds.markers(tile.outer), grid)
    inner = tile.inner
    core = labels[inner] - 1
    del labels
    outside = seeds.count
    if v is not None:
        core[~v[inner]] = outside
    n = outside + 1
    # the terms of the outer box, cut to the core: the grain maps read a few pixels
    # around each one (.texture.GRAIN_REACH), which the halo holds
    terms = pixel_terms(*filled, centre=centre, texture=grain)
    px = {name: term[inner] for name, term in terms.items()}
    ids, count, terms, position = _sums(core, tile.core, px, n)
    edges = border_channels(parts, border) if apart else edges[None]
    del parts
    e = edges[:, inner[0], inner[1]]
    pairs = [
        border_pairs(a, b, ea, eb, n)
        for a, b, ea, eb in (
            (core[:, :-1], core[:, 1:], e[:, :, :-1], e[:, :, 1:]),
            (core[:-1], core[1:], e[:, :-1], e[:, 1:]),
        )
        if a.size
    ]
    right, below = _cut_edges(tile, edges, shape)
    return CoreSums(core, ids, count, terms, position, pairs, right, below)
