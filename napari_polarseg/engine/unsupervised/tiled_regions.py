"""The default method's superpixels and node statistics tile by tile: bounded memory on a
large image.

Everything :func:`~.segmenter.prepare_regions` reads of the pixels is local: the edge
map (Gaussian derivatives of σ = 1.5 px, :func:`~..features.superpixels.superpixel_edges`),
the compact watershed that grows a superpixel from each seed of a regular grid, the
per-pixel terms of the node features (:func:`~.region_features.pixel_terms`) and the
borders between superpixels. What is global is small: two medians that scale the edge
map and a constant that centres log Î (from histograms of their values over every tile,
:func:`edge_scales`), and the node-level work on a few thousand to ~100 000
superpixels (standardising, diffusion over the region graph, PCA, clustering, merge,
choosing k), which runs as it does on a whole image.

So (:func:`tiled_prepare_regions`):

1. the image is cut into the cores of a :class:`~..tiles.TileGrid`; each core is worked
   on its outer box, grown by a halo of :data:`HALO_SEEDS` seed spacings;
2. the seeds are the whole image's (scikit-image's ``regular_grid`` of
   n = H·W / area points, numbered in raster order as its ``watershed`` numbers them),
   so a superpixel grown across a cut carries the same number in both tiles and is one
   node; only the core of each box is kept;
3. each core adds its superpixels' pixel counts, sums of the per-pixel terms
   (Σ Î, Σ S1, Σ S2, Σ log Î, Σ (log Î)², Σ ρ, Σ ρ², Σ ρ log Î, Σ cos 2φ, Σ sin 2φ) and
   centroid sums (one ``np.bincount`` each), and the pixel pairs across its borders
   (length L_ab and summed edge strength Σ e); the pairs across a cut between two cores
   are taken afterwards from the one-pixel lines on either side of it;
4. the node features, border weights L_ab · exp(−(e_ab / τ)²) and projection are then
   the whole image's functions of those sums (:func:`~.region_features.features_of_sums`,
   :func:`~.segmenter.project_features`).

The superpixels themselves are kept as one int32 image (4 bytes a pixel; in a temporary
file when the run's full-size arrays do not fit its limit, :mod:`..disk_arrays`, as the
maps they are read from may be); the labels are written tile by tile by node lookup and
border refinement (:mod:`.tiled_labels`).

Every tile's work (:mod:`.tiled_region_tasks`) reads only its outer box and returns only
its sums, border pairs and core; it runs on the current tile map
(:func:`~..tile_map.tile_map_for`): on this process's threads, or on a Dask
cluster (``polarseg segment --dask``), the results added in the tiles' order either way
(the same labels to the bit).

Whether an image is tiled follows from its size and the memory limit
(:func:`region_tiles`), never from the user; below it the whole-image code runs
unchanged. Tiled labels differ from the whole image's only where a watershed decision
near a cut, a median from a histogram, or a border refinement that updates its segment
means tile by tile, differ (``tests/test_tiled_default.py``: ARI ≥ 0.98).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np
import scipy.sparse as sps

from .. import disk_arrays
from ..errors import PolarsegError
from ..features.pixel_features import EPS_INTENSITY
from ..features.superpixels import seed_count
from ..limits import KEPT_MAPS, memory_limit
from ..tile_map import boxes_at_once, tile_map_for, worker_bytes
from ..tiles import MIN_CORE, Tile, TileGrid
from .params import UnsupervisedParams
from .pixel_maps import edge_weight, reweighs_borders
from .region_diffusion import gated_strength, symmetric, weighted_graph
from .region_features import features_of_sums
from .segmenter import RegionModel, project_features
from .shape_trend import surface_trend_share
from .texture import GRAIN_REACH, reads_grain
from .tiled_labels import TiledLabels
from .tiled_region_tasks import (
    LOG_BINS,
    LOG_RANGE,
    CoreSums,
    Seeds,
    border_pairs,
    box_payload,
    edge_histograms,
    region_core,
)

#: Bytes a pixel of the whole-image preparation and labelling beyond the pipeline's
#: kept maps, the edge map's two terms among them (measured on the 5 MP frame of
#: ``benchmarks/bench_scale.py``: a peak of 1.13 GiB, 0.09 of it the interpreter's).
WHOLE_BYTES_PER_PIXEL = 176
#: Bytes a pixel of one outer box while it is prepared: its filled maps, edge map and
#: gradients, the watershed's copies and the ten float64 per-pixel terms.
TILE_BYTES_PER_PIXEL = 200
#: Full-size bytes a pixel of a tiled run: the superpixels (int32), the labels (int32,
#: then the result's int64 and its block labels), the clustered-pixel mask.
TILED_FIXED_BYTES = 4 + 4 + 8 + 4 + 1
#: Halo of a tile in seed spacings of the watershed.
HALO_SEEDS = 3
#: Largest core side, pixels (larger boxes gain nothing and cost memory).
MAX_CORE = 2048
#: Smallest core side in halos, whatever the limit: smaller cores spend more on their
#: halos than on themselves (at 128 px and a 96 px halo, 6× the pixels; 24 MP took 73 s
#: in 1536 tiles against 66 s whole) while the memory they save is small beside the
#: pipeline's full-size maps. At 8 halos the outer boxes hold 1.56× the pixels.
MIN_CORE_HALOS = 8
#: Pixels the Gaussian derivatives of the edge map read each way (σ = 1.5, truncated at 4σ).
EDGE_REACH = 6


def tile_halo(shape: tuple[int, int], params: UnsupervisedParams) -> int:
    """Halo (pixels) of the tiles: :data:`HALO_SEEDS` spacings of the watershed's seeds
    (√ of the superpixel area, pixels), at least the edge map's reach, the border
    refinement's and the grain maps' (:data:`~.texture.GRAIN_REACH`)."""
    seeds = HALO_SEEDS * int(math.ceil(math.sqrt(params.area_of(shape))))
    return max(seeds, 4 * EDGE_REACH, GRAIN_REACH)


def region_tiles(
    shape: tuple[int, int], params: UnsupervisedParams, limit: int | float | None = None
) -> TileGrid | None:
    """The tiles of the default method's superpixels on an image of ``shape``, or None
    when the whole image fits the memory ``limit`` (default
    :func:`~..limits.memory_limit`): H·W × (:data:`WHOLE_BYTES_PER_PIXEL` + 8 ×
    :data:`~..limits.KEPT_MAPS`) bytes. Tiled, the limit less the full-size arrays is
    the budget of one outer box at :data:`TILE_BYTES_PER_PIXEL` (core side at most
    :data:`MAX_CORE`, and at least :data:`MIN_CORE_HALOS` halos where that box fits the
    budget or where no tile can: the limit first, then the speed; with the tiles on a Dask
    cluster, :func:`~..tile_map.tiles_on`, the outer box at most the workers' share,
    :func:`~..tile_map.worker_bytes`). Parameters with per-pixel
    feature scales or another boundary than the polarisation edges are never tiled."""
    cap = memory_limit(limit)
    pixels = int(shape[0]) * int(shape[1])
    kept = 8 * KEPT_MAPS * pixels
    if pixels * WHOLE_BYTES_PER_PIXEL + kept <= cap:
        return None
    if params.pixel_scales or params.boundary != "polarisation":
        return None
    budget = cap - kept - pixels * TILED_FIXED_BYTES
    align = params.watershed_grid_of(shape)  # boxes start on the watershed's blocks
    halo = tile_halo(shape, params)
    grid = TileGrid.for_budget(shape, budget, TILE_BYTES_PER_PIXEL, halo, align)
    # the speed floor where its box fits the budget, or where nothing can (the
    # full-size arrays alone exceed the limit: smaller tiles would only cost time)
    floor = MIN_CORE_HALOS * grid.halo
    fits = budget <= 0 or (floor + 2 * grid.halo) ** 2 * TILE_BYTES_PER_PIXEL <= budget
    core = min(max(grid.core, floor) if fits else grid.core, MAX_CORE)
    worker = worker_bytes()
    if worker is not None:  # the outer box within a Dask worker's share, whatever else
        side = int(math.sqrt(worker / TILE_BYTES_PER_PIXEL)) - 2 * grid.halo
        core = min(core, max(side, MIN_CORE))
    core = max(core // align * align, align)
    box = (core + 2 * grid.halo) ** 2 * TILE_BYTES_PER_PIXEL
    at_once = boxes_at_once(cap, pixels, kept + pixels * TILED_FIXED_BYTES, box)
    grid = TileGrid(grid.shape, core, grid.halo, align, at_once=at_once)
    return grid if len(grid) > 1 else None


def histogram_median(counts: np.ndarray) -> float:
    """The median of the values counted by
    :func:`~.tiled_region_tasks.log_histogram`: the geometric centre of the bin holding
    the middle value (to 0.05 %)."""
    lo, hi = LOG_RANGE
    middle = int(np.searchsorted(np.cumsum(counts), (int(counts.sum()) + 1) / 2.0))
    return float(2.0 ** (lo + (middle + 0.5) * (hi - lo) / LOG_BINS))


def edge_scales(
    maps: tuple[np.ndarray, np.ndarray, np.ndarray],
    valid: np.ndarray | None,
    grid: TileGrid,
    polarisation: bool,
) -> tuple[float, tuple[float, float]]:
    """(centre of log Î, (m_log, m_s)): log of the median Î and the medians of the two
    gradient magnitudes of the edge map (:func:`~..features.superpixels.edge_gradients`)
    over the whole image, from their
    :func:`~.tiled_region_tasks.log_histogram` over every core (each read
    with the edge map's reach around it): the whole image's medians to 0.05 %. (A
    sample of an eighth of the pixels missed the medians by up to 13 %, which moved
    the superpixels of 6 % of the pixels.)"""
    shape = maps[0].shape

    def payloads() -> Iterator[tuple]:
        for tile in grid:
            outer = tile.grown(EDGE_REACH, shape)
            yield (*box_payload(maps, valid, outer), Tile(tile.core, outer).inner, polarisation)

    counts = np.zeros((3, LOG_BINS), dtype=np.int64)
    for add in tile_map_for(grid)(edge_histograms, payloads()):
        counts += add
    centre = math.log(max(histogram_median(counts[0]), EPS_INTENSITY))
    m_pol = histogram_median(counts[2]) if polarisation else 1.0
    return centre, (histogram_median(counts[1]), m_pol)


class RegionSums:
    """The per-region sums tiles add to (module docstring, step 3), for region numbers
    0 … ``n`` − 1 (the seeds, then the pixels outside the clustered ones)."""

    def __init__(self, n: int, shape: tuple[int, int]) -> None:
        self.n, self.shape = n, shape
        self.count = np.zeros(n)
        self.terms: dict[str, np.ndarray] = {}
        self.position = np.zeros((2, n))  # Σ row, Σ column
        self.pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def add(self, core: CoreSums) -> None:
        """Add one core's sums and border pairs (:func:`~.tiled_region_tasks.region_core`),
        in the order of the tiles (the sums are then the same to the bit wherever the
        tiles ran)."""
        ids = core.ids
        self.count[ids] += core.count
        for name, add in core.terms.items():
            self.terms.setdefault(name, np.zeros(self.n))[ids] += add
        self.position[:, ids] += core.position
        self.pairs.extend(core.pairs)

    def add_borders(self, a: np.ndarray, b: np.ndarray, ea: np.ndarray, eb: np.ndarray):
        """Add the pixel pairs (a, b) with edge values (ea, eb)
        (:func:`~.tiled_region_tasks.border_pairs`)."""
        if a.size:
            self.pairs.append(border_pairs(a, b, ea, eb, self.n))

    def borders(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, length L_ab, strength e_ab = mean pair value, (m, C): one column
        per border map) of every border."""
        keys = np.concatenate([p[0] for p in self.pairs]) if self.pairs else np.zeros(0, int)
        merged, inverse = np.unique(keys, return_inverse=True)
        length = np.bincount(inverse, weights=np.concatenate([p[1] for p in self.pairs] or [[]]))
        sums = np.concatenate([p[2] for p in self.pairs]) if self.pairs else np.zeros((0, 1))
        strength = np.stack([np.bincount(inverse, weights=c) for c in sums.T], axis=1)
        strength /= np.maximum(length, 1e-300)[:, None]
        return merged // self.n, merged % self.n, length, strength


def _keep_cut_lines(tile: Tile, core: CoreSums, lines: dict, shape: tuple[int, int]) -> None:
    """Keep the edge values on both sides of the cuts right of and below ``tile``'s core
    (``core.right``, ``core.below``) in the full-length ``lines``."""
    (r0, r1), (c0, c1) = (
        (tile.core[0].start, tile.core[0].stop),
        (tile.core[1].start, tile.core[1].stop),
    )
    if core.right is not None:
        c = core.right.shape[1]
        lines.setdefault(("col", c1), np.zeros((2, c, shape[0])))[:, :, r0:r1] = core.right
    if core.below is not None:
        c = core.below.shape[1]
        lines.setdefault(("row", r1), np.zeros((2, c, shape[1])))[:, :, c0:c1] = core.below


def _cut_pairs(sums: RegionSums, regions: np.ndarray, lines: dict) -> None:
    """The pixel pairs across every cut between two cores, from the final regions on
    either side and the edge values kept by :func:`_keep_cut_lines`."""
    for (kind, at), (e_before, e_after) in lines.items():
        if kind == "col":
            sums.add_borders(regions[:, at - 1], regions[:, at], e_before, e_after)
        else:
            sums.add_borders(regions[at - 1], regions[at], e_before, e_after)


#: Rows of the superpixel image renumbered at once (bounds the temporaries).
BAND_ROWS = 512


def _tile_pass(
    maps: tuple[np.ndarray, np.ndarray, np.ndarray],
    valid: np.ndarray | None,
    p: UnsupervisedParams,
    grid: TileGrid,
    progress: Callable[[float], None],
) -> tuple[np.ndarray, RegionSums, float]:
    """(superpixels (H, W) int32 numbered by their seeds from 0, the pixels outside
    ``valid`` the last number; their :class:`RegionSums`; the log Î centre): steps 1–3
    of the module docstring. ``progress`` gets the share of tiles done."""
    shape = maps[0].shape
    weight = edge_weight(p)
    grain = reads_grain(p.features + p.texture)
    centre, scales = edge_scales(maps, valid, grid, weight > 0)
    seeds = Seeds.of(shape, seed_count(shape, p.area_of(shape)))
    block = p.watershed_grid_of(shape)
    border, apart = p.border_intensity_weight, reweighs_borders(p)
    if grid.align % block:
        raise PolarsegError(f"tiles aligned to {grid.align} px, the watershed's blocks {block}")
    outside = seeds.count
    sums = RegionSums(outside + 1, shape)
    regions = disk_arrays.empty(shape, dtype=np.int32)  # on disk when they do not fit
    lines: dict = {}

    def payloads() -> Iterator[tuple]:
        for tile in grid:
            box = box_payload(maps, valid, tile.outer)
            yield (*box, tile, seeds, weight, scales, centre, shape, grain, block, border, apart)

    cores = tile_map_for(grid)(region_core, payloads())
    for index, (tile, core) in enumerate(zip(grid, cores, strict=True)):
        regions[tile.core] = core.regions
        sums.add(core)
        _keep_cut_lines(tile, core, lines, shape)
        progress((index + 1) / len(grid))
    _cut_pairs(sums, regions, lines)
    return regions, sums, centre


def _renumber(regions: np.ndarray, sums: RegionSums, outside: bool) -> tuple[np.ndarray, int]:
    """Number the superpixels with a clustered pixel 0 … n − 1 in the order of their
    seeds, the outside pixels n (as :func:`~.segmenter.prepare_regions` does), in place;
    returns (the old number of every new one, n)."""
    old = np.flatnonzero(sums.count[:-1] > 0)
    n = old.size
    lut = np.full(sums.n, n, dtype=np.int32)
    lut[old] = np.arange(n, dtype=np.int32)
    for top in range(0, regions.shape[0], BAND_ROWS):
        band = regions[top : top + BAND_ROWS]
        band[...] = lut[band]
    return (np.append(old, sums.n - 1) if outside else old), n


def _graph(
    sums: RegionSums, old: np.ndarray, n: int, tau: float, z: np.ndarray, gate: float
) -> tuple[sps.csr_matrix, sps.csr_matrix | None]:
    """(shared-border lengths L_ab, edge-aware weights L_ab · exp(−(e_ab / τ)²) with
    τ = ``tau`` × the median e_ab over every border, outside pixels' too), both (n, n)
    over the clustered superpixels (None below two). With two border maps, e_ab is their
    :func:`~.region_diffusion.gated_strength` (``gate``, 0: their sum; ``z`` the regions'
    complex polarisation in the new numbering)."""
    rows, cols, length, strength = sums.borders()
    lut = np.zeros(sums.n, dtype=np.int64)
    lut[old] = np.arange(old.size)
    rows, cols, size = lut[rows], lut[cols], old.size
    adjacency = symmetric(rows, cols, length, size)[:n][:, :n].tocsr()
    if n < 2:
        return adjacency, None
    if strength.shape[1] == 2:
        strength = gated_strength(strength, np.abs(z[rows] - z[cols]), gate)
    else:
        strength = strength[:, 0]
    return adjacency, weighted_graph(rows, cols, length, strength, size, tau)[:n][:, :n].tocsr()


def tiled_prepare_regions(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    params: UnsupervisedParams,
    valid: np.ndarray | None,
    grid: TileGrid,
    progress: Callable[[float], None] | None = None,
) -> RegionModel:
    """:func:`~.segmenter.prepare_regions` tile by tile on ``grid`` (module docstring):
    the same :class:`~.segmenter.RegionModel` but for its maps (the unfilled Î, ρ, φ),
    no ``refine_maps`` nor ``nearest``, and a ``labeller`` that writes the labels tile
    by tile (:class:`~.tiled_labels.TiledLabels`)."""
    step = progress or (lambda share: None)
    p = params
    shape = tuple(np.shape(intensity))
    maps = (intensity, dop, phase)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        valid = None if valid.all() else valid
    regions, sums, centre = _tile_pass(maps, valid, p, grid, lambda s: step(0.8 * s))
    old, n = _renumber(regions, sums, valid is not None)
    keep = slice(0, n)
    raw = sums.count[old]
    count = np.maximum(raw, 1.0)
    terms = {k: v[old] for k, v in sums.terms.items()}
    centroid = (sums.position[:, old] / count).T
    z_region = (terms["s1"] + 1j * terms["s2"]) / np.maximum(terms["s0"], EPS_INTENSITY)
    share = surface_trend_share(z_region[keep], count[keep], centroid[keep], shape)
    close_up = share > p.close_up_share
    q = p.close_up_params() if close_up else p
    trend = (q.trend_degree, q.trend_reach, q.trend_iterations)
    x = features_of_sums(terms, count, q.features + q.texture, trend, centroid, shape)
    x = np.where(np.isfinite(x), x, 0.0)
    weight = raw[keep].astype(float)
    adjacency, borders = _graph(sums, old, n, q.diffusion_tau, z_region, q.border_gate)
    if borders is None:
        z = np.zeros((n, 0))
    else:
        z = project_features(x[keep], weight, borders, adjacency, q)
    step(0.9)
    labeller = TiledLabels.of(grid, terms, raw, centre, n)
    return RegionModel(
        maps,
        valid,
        regions,
        n,
        weight,
        adjacency,
        z,
        tuple(q.features),
        share,
        close_up,
        p,
        None,
        None,
        borders,
        labeller,
    )
