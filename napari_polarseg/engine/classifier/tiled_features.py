"""The pixel features of a large image, made tile by tile when they are read.

A whole-image feature stack (:func:`~..features.pixel_features.pixel_features`) holds
about 200 bytes a pixel with its temporaries: 5 GB for a 24 MP frame. A
:class:`TiledFeatures` holds only the polarisation maps and the superpixels; the
features of a box are computed when a reader asks for them
(:meth:`TiledFeatures.box`), on the box grown by the halo of a
:class:`~..tiles.TileGrid`, so inside the box they equal the whole image's:

- every filter reads at most :func:`~..features.pixel_features.feature_reach` pixels
  (the largest σ × truncate of the filter chains, on its pyramid grid);
- log Î is centred on the whole image's centre
  (:func:`~..features.pixel_features.log_intensity_centre`), not the box's;
- the ``regions`` group averages the σ ≤ 4 features over each superpixel of the
  whole image's superpixels (drawn once over the image: the compact watershed floods
  from a grid of seeds over the whole edge map, which no tile reproduces). A
  superpixel may stretch over hundreds of pixels (598 px on the fruits frame), so no
  halo holds them: their means are statistics gathered over the tiles first
  (:meth:`TiledFeatures.region_values`: every core's sums of those features per
  superpixel, ``np.bincount``), then every box reads them as one
  :class:`~..features.feature_stack.RegionBlock` per channel.

Training reads the rows of the stroke pixels (:meth:`TiledFeatures.take`), gathered
tile by tile around the strokes of each tile; the prediction reads each tile's box
(:mod:`.tiled_prediction`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..features.banded_edges import band_counts
from ..features.feature_stack import FeatureStack, GridBlock, RegionBlock
from ..features.pixel_features import (
    REGION_MAX_SIGMA,
    PixelFeatureParams,
    feature_names,
    feature_reach,
    largest_factor,
    log_intensity_centre,
    pixel_features,
)
from ..tile_map import tile_map_for
from ..tiles import Box, TileGrid, round_up

Maps = tuple[np.ndarray, np.ndarray, np.ndarray]


def tile_halo(params: PixelFeatureParams, margin: int) -> int:
    """Pixels a tile reads beyond the pixels it answers for, so its features there and
    ``margin`` pixels further equal the whole image's: ``margin`` plus the features'
    reach (:func:`~..features.pixel_features.feature_reach`)."""
    return int(margin) + feature_reach(params)


def without_regions(params: PixelFeatureParams, largest: float | None = None) -> PixelFeatureParams:
    """``params`` without the ``regions`` group (and with ``largest``, only the scales
    σ ≤ it): the features a box computes itself."""
    scales = tuple(s for s in params.scales if largest is None or s <= largest)
    groups = tuple(g for g in params.groups if g != "regions")
    return replace(params, scales=scales or params.scales[:1], groups=groups)


def block_sums(plane: np.ndarray, block: int) -> np.ndarray:
    """Sums (h / b, w / b) of the b × b blocks of ``plane`` (h, w, both multiples of
    b = ``block``), added in its precision by strided slices: ``reshape(…).sum`` over
    two short axes runs numpy's reduction loop per block, 8 × slower."""
    b = int(block)
    columns = sum(plane[:, j::b] for j in range(1, b)) + plane[:, 0::b]
    return sum(columns[i::b] for i in range(1, b)) + columns[0::b]


def core_sums(
    features: FeatureStack, inner: Box, regions: np.ndarray, n: int, block: int = 1
) -> np.ndarray:
    """(F, n) float64 sums of every feature over the pixels of the box ``inner`` of
    ``features`` per region (``regions``: the flat region of each of those pixels,
    0 … n − 1; with ``block`` b > 1, of each b × b block of them, the regions being
    constant on those blocks and the box's sides multiples of b). Each plane's blocks
    are summed first (:func:`block_sums`), so ``np.bincount``, which converts its
    weights to float64, reads b² × fewer (3 × faster at b = 2)."""
    planes = (features.plane(j)[inner] for j in range(features.n_features))
    if block > 1:
        planes = (block_sums(p, block) for p in planes)
    return np.stack([np.bincount(regions, p.ravel(), n) for p in planes])


def region_sums(
    maps: list[Maps],
    inner: Box,
    core: np.ndarray,
    params: PixelFeatureParams,
    log_centres: list[float],
    block: int = 1,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """A tile's share of :meth:`TiledFeatures.region_values` (a task of the current tile
    map, :mod:`..tile_map`): the superpixels of its ``core`` (their ids, ascending) and
    every channel's (F_r, m) float64 sums of its features of ``params`` over each of
    them, the features computed on the channel's ``maps`` of the tile's outer box
    (``inner``: the core within it). ``block``: the superpixels are constant on the
    ``block`` × ``block`` blocks of the core (it starts on a multiple of ``block`` in
    the image), summed block by block (:func:`core_sums`) when its sides are multiples
    of ``block``."""
    b = int(block) if block > 1 and not (core.shape[0] % block or core.shape[1] % block) else 1
    flat = core.ravel()
    present = np.bincount(flat) > 0
    ids = np.flatnonzero(present)
    local = (np.cumsum(present) - 1)[core[::b, ::b].ravel()]
    sums = []
    for (i, d, p), centre in zip(maps, log_centres, strict=True):
        f = pixel_features(i, d, p, params, log_centre=centre)
        sums.append(core_sums(f, inner, local, ids.size, b))
    return ids, sums


def region_names(params: PixelFeatureParams) -> tuple[str, ...]:
    """The names of the ``regions`` group's features of ``params`` (no prefix)."""
    return tuple(n for n in feature_names(params) if n.startswith("region:"))


def tile_align(params: PixelFeatureParams, stride: int) -> int:
    """Multiple of pixels tiles start on: the coarsest feature grid and the prediction
    grid both divide it."""
    return math.lcm(largest_factor(params), max(1, int(stride)))


@dataclass
class TiledFeatures:
    """Pixel features of an image computed on boxes of it (module docstring).

    Attributes
    ----------
    images : list of (Î, ρ, φ)
        Every channel's polarisation image (H, W each): the luminance first.
    channels : list of str
        The channels' name prefixes (``""`` for the luminance).
    params : PixelFeatureParams
    grid : TileGrid
        The tiles the prediction runs on; its halo and alignment hold for any box.
    regions : ndarray (H, W) int or None
        The whole image's superpixels (with the ``regions`` group).
    region_block : int
        The superpixels are constant on the ``region_block`` × ``region_block`` blocks
        from the image's origin (drawn on the watershed's coarser grid,
        :func:`~..features.superpixels.watershed_grid`); 1: no such blocks.
    """

    images: list[Maps]
    channels: list[str]
    params: PixelFeatureParams
    grid: TileGrid
    regions: np.ndarray | None = None
    log_centres: list[float] = field(default_factory=list)
    region_block: int = 1
    _region_values: list[np.ndarray] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.log_centres:
            self.log_centres = log_centres_of(self.images)

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid.shape

    @property
    def names(self) -> tuple[str, ...]:
        """The features' names, as the whole image's stack names them."""
        plain = feature_names(self.params)
        return tuple(f"{c}:{n}" if c else n for c in self.channels for n in plain)

    @property
    def n_features(self) -> int:
        return len(self.names)

    def box(self, outer: Box) -> FeatureStack:
        """The features of the pixels of ``outer`` (a box starting on the grid's
        alignment); they equal the whole image's at least a halo inside its cut edges
        (the region means: everywhere)."""
        return box_features(*self.box_inputs(outer))

    def box_inputs(self, outer: Box, inner: Box | None = None) -> tuple:
        """What :func:`box_features` reads for the box ``outer``: every channel's maps of
        the box (views), the box's superpixels and the whole image's region means (None
        without the ``regions`` group), the channels, parameters, log Î centres and
        ``inner`` (rows, columns of ``outer``: the box the features are made for, e.g.
        :meth:`fine_box`; None: all of ``outer``). A tile task's payload: its arrays are
        all the box needs of the image."""
        maps = self.box_maps(outer)
        regions = self.regions[outer] if self.regions is not None else None
        means = self.region_values() if self.regions is not None else None
        return maps, regions, means, self.channels, self.params, self.log_centres, inner

    def fine_box(self, needed: Box, outer: Box) -> Box:
        """The box (rows, columns of ``outer``) on which a reader of the pixels
        ``needed`` (image coordinates, inside ``outer``) has the scales
        σ ≤ :data:`~..features.pixel_features.REGION_MAX_SIGMA` computed
        (:func:`own_features`): ``needed`` grown by their reach (24 MP's default: 32 px
        against the 112 px of σ = 16), its start rounded down and its end up to the
        grid's alignment, within ``outer``."""
        a = self.grid.align
        reach = feature_reach(self.params, REGION_MAX_SIGMA)
        out = []
        for want, box in zip(needed, outer, strict=True):
            start = max(box.start, (want.start - reach) // a * a)
            stop = min(box.stop, round_up(want.stop + reach, a))
            out.append(slice(start - box.start, stop - box.start))
        return out[0], out[1]

    def box_maps(self, outer: Box) -> list[Maps]:
        """Every channel's Î, ρ, φ of the box ``outer`` (views)."""
        return [tuple(m[outer] for m in image) for image in self.images]

    def region_values(self) -> list[np.ndarray]:
        """Every channel's (F_r, n) float32 means of its σ ≤ 4 features over each
        superpixel, gathered over the tiles' cores on the current tile map
        (:func:`region_sums`, added in the grid's order, then divided by each
        superpixel's pixels); made once."""
        if self._region_values is None:
            assert self.regions is not None
            small = without_regions(self.params, REGION_MAX_SIGMA)
            halo = round_up(feature_reach(small), self.grid.align)
            grid = replace(self.grid, halo=halo)
            n = int(self.regions.max()) + 1
            sums: list[np.ndarray] = []
            payloads = (
                (
                    self.box_maps(tile.outer),
                    tile.inner,
                    self.regions[tile.core],
                    small,
                    self.log_centres,
                    self.block_of(tile.core),
                )
                for tile in grid
            )
            for ids, adds in tile_map_for(grid)(region_sums, payloads):
                sums = sums or [np.zeros((a.shape[0], n)) for a in adds]
                for total, add in zip(sums, adds, strict=True):
                    total[:, ids] += add
            counts = np.maximum(band_counts(self.regions, n), 1)
            self._region_values = [(v / counts).astype(np.float32) for v in sums]
        return self._region_values

    def block_of(self, core: Box) -> int:
        """:attr:`region_block` when the box ``core`` starts on a multiple of it, else 1:
        the block :func:`region_sums` may sum ``core`` by."""
        b = self.region_block
        return b if core[0].start % b == 0 and core[1].start % b == 0 else 1

    def around(self, rows: tuple[int, int], cols: tuple[int, int]) -> Box:
        """The box read for the pixels rows[0]:rows[1] × cols[0]:cols[1]: grown by the
        halo, its start rounded down and its end up to the alignment, clipped."""
        a, h = self.grid.align, self.grid.halo
        return (
            slice(max(0, (rows[0] - h) // a * a), min(self.shape[0], round_up(rows[1] + h, a))),
            slice(max(0, (cols[0] - h) // a * a), min(self.shape[1], round_up(cols[1] + h, a))),
        )

    def take(self, index: np.ndarray) -> np.ndarray:
        """(n, F) float32 rows of the pixels at flat ``index``: for every tile's share of
        them, the features of the box around those pixels only (:func:`box_rows`, on
        the current tile map)."""
        index = np.asarray(index, dtype=np.int64).ravel()
        out = np.empty((index.size, self.n_features), dtype=np.float32)
        r, c = np.divmod(index, self.shape[1])
        tile = (r // self.grid.core) * self.grid.counts[1] + c // self.grid.core
        shares = [np.flatnonzero(tile == t) for t in np.unique(tile)]

        def payloads():
            for mine in shares:
                rr, cc = r[mine], c[mine]
                rows, cols = (int(rr.min()), int(rr.max()) + 1), (int(cc.min()), int(cc.max()) + 1)
                outer = self.around(rows, cols)
                inner = self.fine_box((slice(*rows), slice(*cols)), outer)
                top, left = outer[0].start + inner[0].start, outer[1].start + inner[1].start
                local = (rr - top) * (inner[1].stop - inner[1].start) + (cc - left)
                yield self.box_inputs(outer, inner), local

        rows_of = tile_map_for(self.grid)(box_rows, payloads())
        for mine, rows in zip(shares, rows_of, strict=True):
            out[mine] = rows
        return out


def log_centres_of(images: Sequence[Maps]) -> list[float]:
    """Every channel's log Î centre, in the order of ``images`` ((Î, ρ, φ) each): the
    whole image's :func:`~..features.pixel_features.log_intensity_centre`."""
    return [float(log_intensity_centre(im[0])) for im in images]


def box_rows(inputs: tuple, local: np.ndarray) -> np.ndarray:
    """(n, F) float32 rows of the pixels at the flat indices ``local`` of a box (a task
    of the current tile map): :func:`box_features` of ``inputs``
    (:meth:`TiledFeatures.box_inputs`), those rows taken."""
    return box_features(*inputs).take(local)


def cut_block(block: GridBlock, box: Box) -> GridBlock:
    """The block of the pixels of ``box`` (rows, columns of the block's image, starting
    on multiples of its factor f) of a :class:`~..features.feature_stack.GridBlock`:
    the coarse cells over them. Interpolated, it equals ``block`` at least f pixels
    inside the box's cut edges (there the edge cell is held instead of read on)."""
    f = block.factor
    top, left = box[0].start, box[1].start
    if top % f or left % f:
        raise ValueError(f"a box cut from a block of factor {f} starts at ({top}, {left})")
    h, w = box[0].stop - top, box[1].stop - left
    cells = block.values[:, top // f : top // f + -(-h // f), left // f : left // f + -(-w // f)]
    return GridBlock(np.ascontiguousarray(cells), f, (h, w))


def own_features(
    maps: Maps,
    params: PixelFeatureParams,
    channel: str,
    log_centre: float,
    inner: Box | None = None,
) -> FeatureStack:
    """One channel's features of ``params`` but the ``regions`` group on its ``maps`` of a
    box, for the pixels of ``inner`` (rows, columns of the box, starting on multiples
    of the coarsest grid factor; None: the whole box): the scales
    σ ≤ :data:`~..features.pixel_features.REGION_MAX_SIGMA`, which filter every pixel at
    full or half resolution, computed on ``inner`` alone, the coarser ones on the box
    and cut to ``inner`` (:func:`cut_block`). So at least the σ ≤ 4 scales' reach
    (:func:`~..features.pixel_features.feature_reach`) inside ``inner``'s cut edges and
    the whole reach inside the box's, they equal the features of the whole box."""
    own = without_regions(params)
    i, d, p = maps
    if inner is None:
        return pixel_features(i, d, p, own, channel=channel, log_centre=log_centre)
    parts: dict[float, tuple[GridBlock, tuple[str, ...]]] = {}
    for fine in (True, False):
        scales = tuple(s for s in own.scales if (s <= REGION_MAX_SIGMA) == fine)
        if not scales:
            continue
        box = inner if fine else (slice(None), slice(None))
        stack = pixel_features(
            i[box], d[box], p[box], replace(own, scales=scales), channel=channel,
            log_centre=log_centre,
        )  # fmt: skip
        start = 0
        for sigma, block in zip(scales, stack.blocks, strict=True):
            names = stack.names[start : start + block.n_features]
            parts[sigma] = (block if fine else cut_block(block, inner), names)
            start += block.n_features
    blocks = tuple(parts[s][0] for s in own.scales)
    return FeatureStack(blocks, tuple(n for s in own.scales for n in parts[s][1]), own)


def box_features(
    maps: list[Maps],
    regions: np.ndarray | None,
    means: list[np.ndarray] | None,
    channels: list[str],
    params: PixelFeatureParams,
    log_centres: list[float],
    inner: Box | None = None,
) -> FeatureStack:
    """The features of a box (:meth:`TiledFeatures.box`) from what it reads
    (:meth:`TiledFeatures.box_inputs`), for the pixels of ``inner`` (rows, columns of
    the box; None: all of it): every channel's own features of its ``maps``
    (:func:`own_features`), then, with ``regions``, that channel's region ``means`` on
    the superpixels there."""
    stacks = []
    if regions is not None and inner is not None:
        regions = regions[inner]
    for n, (c, m) in enumerate(zip(channels, maps, strict=True)):
        f = own_features(m, params, c, log_centres[n], inner)
        if means is not None and regions is not None:
            block = RegionBlock(means[n], regions)
            names = [f"{c}:{x}" if c else x for x in region_names(params)]
            f = FeatureStack((*f.blocks, block), (*f.names, *names), params)
        stacks.append(f)
    return stacks[0] if len(stacks) == 1 else FeatureStack.joined(stacks)


def tiled_features(
    images: Sequence[Maps],
    channels: Sequence[str],
    params: PixelFeatureParams,
    grid: TileGrid,
    regions: np.ndarray | None,
    log_centres: Sequence[float] = (),
    region_block: int = 1,
) -> TiledFeatures:
    """A :class:`TiledFeatures` (``regions`` dropped without the ``regions`` group;
    ``log_centres``: every channel's, when already known; ``region_block``: the side of
    the blocks the ``regions`` are constant on)."""
    keep = regions if "regions" in params.groups else None
    return TiledFeatures(
        list(images), list(channels), params, grid, keep, list(log_centres), region_block
    )
