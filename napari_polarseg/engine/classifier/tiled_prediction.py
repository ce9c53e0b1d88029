"""The scribbles method's prediction tile by tile: bounded memory on a large image.

Whether an image is tiled follows from its size and the memory limit
(:func:`scribble_tiles`): when the whole-image estimate
(:func:`~..limits.estimate_scribble_bytes`) exceeds the limit, the image is cut into
the tiles of a :class:`~..tiles.TileGrid` whose outer boxes fit what is left of the
limit after the full-size arrays (:func:`~..limits.scribble_bytes_per_pixel`).

Every tile's features are computed on its outer box
(:class:`~.tiled_features.TiledFeatures`), the classifier predicts the core grown by a
margin coarse to fine (:func:`~.refined_prediction.window_probabilities`: two grid cells,
what the interpolation and the border test read, plus the guided filter's 2 r), and the
core is kept. So the probabilities equal the whole image's to float rounding. Each tile
is a task of the current tile map (:mod:`..tile_map`: this process, or a Dask cluster
with ``polarseg segment --dask``): :func:`tile_prior` reads only its payload (the box's
maps, superpixels and the superpixels' feature means, the forest), so the results are
the same wherever it runs.

The region walk (:mod:`.region_walk`) is global — one linear system over every node of
the image — but it reads the pixels only through sums: for every superpixel and class
the number of pixels the classifier gives that class and their summed probabilities
(the nodes and their means λ), and the borders between nodes. So each tile adds its
core's counts and sums (``np.bincount``) and keeps its labels (uint8); the nodes,
their graph (:meth:`~.region_walk.RegionGraph.adjacency`, from the whole image's
superpixels and edge map), the seeds and the walk are then made once, and every pixel
takes its node's answer: the same system as the whole image's.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np

from .. import disk_arrays
from ..errors import Cancelled
from ..limits import KEPT_MAPS, memory_limit, scribble_bytes_per_pixel
from ..tile_map import boxes_at_once, in_this_process, tile_map_for
from ..tiles import Box, Tile, TileGrid, row_bands
from .pixel_classifier import (
    PixelClassifier,
    PixelPrediction,
    margin_uncertainty,
    most_probable,
    smooth_probabilities,
)
from .refined_prediction import window_probabilities
from .region_walk import RegionGraph, confident_seeds, node_prediction, walk, with_scribbles
from .tiled_features import TiledFeatures, box_features

#: Rows of the full-size node image renumbered at once (bounds the int64 keys).
BAND_ROWS = 512


def prediction_margin(stride: int, smoothing: float) -> int:
    """Pixels beyond a core its prediction must be right on: two grid cells and the
    guided filter's two box means of radius r = round(``smoothing``)."""
    r = max(1, round(smoothing)) if smoothing > 0 else 0
    return 2 * max(1, int(stride)) + 2 * r


#: Core side, in halos, when no tile can meet the limit (the full-size arrays alone
#: exceed it): 128 px cores with 136 px halos read 10 × the pixels (24 MP: 147 s).
UNBOUNDED_CORE_HALOS = 4
#: Bytes a pixel a tiled run holds in memory beside its tiles when its full-size arrays
#: are in temporary files (:func:`~..disk_arrays.on_disk_at`): the caller's strokes,
#: the comparisons of the superpixels' borders, the files' pages not yet given back.
#: Measured: the process's peak with one tile at a time grew by 11.6 bytes a pixel
#: from 24 to 100 MP (0.87 and 1.68 GiB, ``benchmarks/bench_scale.py``), the stack and
#: its flags (8, already off the work limit) among them; with room for a tile's peak
#: above its estimate (0.34 GiB measured, 0.26 estimated), 16: under 2 GiB two tiles
#: at once at 24 MP, one at 100 MP (two there peaked at 2.02 GiB).
RESIDENT_BYTES_PER_PIXEL = 16


def scribble_tiles(
    shape: tuple[int, int],
    feature_params: Any,
    halo: int,
    align: int,
    channels: int = 1,
    n_classes: int = 4,
    limit: int | float | None = None,
) -> TileGrid | None:
    """The tiles of the scribbles method on an image of ``shape``, or None when the
    whole image fits the memory ``limit`` (default :func:`~..limits.memory_limit`).

    Whole image: the work and full-size bytes a pixel of
    :func:`~..limits.scribble_bytes_per_pixel` plus the pipeline's
    :data:`~..limits.KEPT_MAPS` float64 maps. Tiled: the limit less the full-size
    arrays is the budget of one outer box of (c + 2h)² pixels at the work's bytes a
    pixel (:meth:`TileGrid.for_budget`; at least its smallest core); when the
    full-size arrays alone exceed the limit, cores of :data:`UNBOUNDED_CORE_HALOS`
    halos. As many tiles at once as :func:`~..tile_map.boxes_at_once` says, the
    full-size arrays on disk counted at :data:`RESIDENT_BYTES_PER_PIXEL`.
    """
    cap = memory_limit(limit)
    pixels = int(shape[0]) * int(shape[1])
    work, fixed = scribble_bytes_per_pixel(feature_params, channels, n_classes)
    if pixels * (work + fixed + 8 * KEPT_MAPS) <= cap:
        return None
    _, fixed = scribble_bytes_per_pixel(feature_params, channels, n_classes, tiled=True)
    full_size = pixels * (fixed + 8 * KEPT_MAPS)
    budget = cap - full_size
    if budget <= 0:
        # the full-size arrays alone exceed the limit: no tile can meet it, and cores
        # under a few halos would only multiply the halos' work
        budget = (UNBOUNDED_CORE_HALOS + 2) ** 2 * halo * halo * work
    grid = TileGrid.for_budget(shape, budget, work, halo, align)
    box = (grid.core + 2 * grid.halo) ** 2 * work
    at_once = boxes_at_once(cap, pixels, full_size, box, RESIDENT_BYTES_PER_PIXEL)
    return replace(grid, at_once=at_once)


def _local(box: Box, outer: Box) -> Box:
    """``box`` in the coordinates of ``outer``."""
    r0, c0 = outer[0].start, outer[1].start
    return slice(box[0].start - r0, box[0].stop - r0), slice(box[1].start - c0, box[1].stop - c0)


def prior_payloads(
    classifier: PixelClassifier,
    features: TiledFeatures,
    stride: int,
    guide: tuple[np.ndarray, tuple[float, float]] | None,
    cancel: Any = None,
) -> Iterator[tuple]:
    """Every tile's payload of :func:`tile_prior`, in the grid's order: the classifier's
    model, what the tile's outer box reads (:meth:`~.tiled_features.TiledFeatures.box_inputs`),
    the window (the core grown by :func:`prediction_margin`) within the box its features
    are made for and the core within the window, the stride and, with the ``guide``
    (the whole image's guide and its (mean, std)), the guide's window, its statistics
    and the smoothing radius. The features are made for the window grown by the fine
    scales' reach (:meth:`~.tiled_features.TiledFeatures.fine_box`): the scales σ ≤ 4
    are not filtered over the whole halo, which only σ = 8 and 16 read.
    ``cancel()`` is asked before every tile, and within a tile when the tiles run in
    this process."""
    smoothing = classifier.params.smoothing if guide is not None else 0.0
    inside = cancel if in_this_process(tile_map_for(features.grid)) else None
    for tile in features.grid:
        if cancel is not None and cancel():
            raise Cancelled("prediction cancelled")
        window = tile.grown(prediction_margin(stride, smoothing), features.shape)
        smooth = None
        if guide is not None and smoothing > 0:
            smooth = (guide[0][window], guide[1], smoothing)
        inner = features.fine_box(window, tile.outer)
        inputs = features.box_inputs(tile.outer, inner)
        local = _local(_local(window, tile.outer), inner)
        yield classifier.model, inputs, local, _local(tile.core, window), stride, smooth, inside


def tile_prior(
    model: Any,
    inputs: tuple,
    window: Box,
    core: Box,
    stride: int,
    smooth: tuple[np.ndarray, tuple[float, float], float] | None = None,
    cancel: Any = None,
) -> tuple[np.ndarray, int]:
    """p_k (K, h, w) of a tile's core and the pixels predicted on their own features
    (a task of the current tile map, :mod:`..tile_map`): the box's features
    (:func:`~.tiled_features.box_features` of ``inputs``), the ``window`` (rows, columns
    of the box) coarse to fine, smoothed by the guide's window when ``smooth`` =
    (guide, (mean, std), radius) is given; the ``core`` of the window kept."""
    out = window_probabilities(model, box_features(*inputs), window, stride, cancel)
    proba = out.probabilities
    if smooth is not None:
        proba = smooth_probabilities(proba, smooth[0], smooth[2], smooth[1])
    return np.ascontiguousarray(proba[:, core[0], core[1]]), out.n_predicted


def tile_priors(
    classifier: PixelClassifier,
    features: TiledFeatures,
    stride: int,
    guide: tuple[np.ndarray, tuple[float, float]] | None,
    cancel: Any = None,
) -> Iterator[tuple[Tile, np.ndarray, int]]:
    """(tile, its core's p_k, pixels predicted on their own features) of every tile in
    the grid's order, the tiles on the current tile map (this process, or a Dask
    cluster: ``polarseg segment --dask``)."""
    payloads = prior_payloads(classifier, features, stride, guide, cancel)
    results = tile_map_for(features.grid)(tile_prior, payloads)
    for tile, (proba, n) in zip(features.grid, results, strict=True):
        yield tile, proba, n


def tiled_pixels(
    classifier: PixelClassifier,
    features: TiledFeatures,
    stride: int,
    guide: tuple[np.ndarray, tuple[float, float]] | None = None,
    cancel: Any = None,
) -> PixelPrediction:
    """:func:`~.pixel_classifier.predict_pixels` tile by tile (no walk): every core's
    probabilities (:func:`tile_priors`), label and uncertainty stitched into
    arrays placed by :func:`~..disk_arrays.empty` (in temporary files when the image's
    full-size arrays do not fit the run's limit)."""
    k = classifier.classes.size
    h, w = features.shape
    proba = disk_arrays.empty((k, h, w), dtype=np.float32)
    labels = disk_arrays.empty((h, w), dtype=np.int32)
    uncertainty = disk_arrays.empty((h, w), dtype=np.float32)
    predicted = 0
    for tile, p, n in tile_priors(classifier, features, stride, guide, cancel):
        proba[:, tile.core[0], tile.core[1]] = p
        labels[tile.core] = most_probable(p)
        uncertainty[tile.core] = margin_uncertainty(p)
        predicted += n
        disk_arrays.release(proba, labels, uncertainty)
    return PixelPrediction(labels, proba, uncertainty, classifier.classes, predicted)


def tiled_walk(
    classifier: PixelClassifier,
    features: TiledFeatures,
    graph: RegionGraph,
    stride: int,
    scribbles: np.ndarray | None = None,
    cancel: Any = None,
) -> PixelPrediction:
    """:func:`~.region_walk.walked_prediction` with the prior made tile by tile (module
    docstring): the node counts and probability sums gathered over the cores, then the
    walk over the nodes of the whole image. The classifier's labels and the nodes
    (H, W) are placed by :func:`~..disk_arrays.empty`."""
    k = classifier.classes.size
    keys = (int(graph.regions.max()) + 1) * k
    counts = np.zeros(keys)
    sums = np.zeros((keys, k))
    labels = disk_arrays.empty(features.shape, dtype=np.uint8 if k < 256 else np.int32)
    predicted = 0
    for tile, prior, n in tile_priors(classifier, features, stride, None, cancel):
        lab = most_probable(prior)
        key = (graph.regions[tile.core].astype(np.int64) * k + lab).ravel()
        # the core's keys are a short range of all of them: counted on that range
        low = int(key.min())
        key -= low
        span = slice(low, low + int(key.max()) + 1)
        counts[span] += np.bincount(key)
        for j in range(k):
            sums[span, j] += np.bincount(key, weights=prior[j].ravel())
        labels[tile.core] = lab
        predicted += n
    present = counts > 0
    node_of = (np.cumsum(present) - 1).astype(np.int32)
    nodes = disk_arrays.empty(features.shape, dtype=np.int32)
    for band in row_bands(nodes.shape[0], BAND_ROWS):
        nodes[band] = node_of[graph.regions[band].astype(np.int64) * k + labels[band]]
        disk_arrays.release(nodes)
    del labels
    means = sums[present] / counts[present][:, None]
    seeds = with_scribbles(confident_seeds(means), nodes, scribbles, classifier.classes)
    x = walk(graph.adjacency(nodes), means, seeds, classifier.params.region_walk)
    return node_prediction(x, nodes, classifier.classes, predicted)


def tiles_needed(core: int, halo: int) -> float:
    """Outer pixels read per core pixel for a square core of side ``core`` with a halo
    of ``halo``: ((c + 2h) / c)² (the tiling's extra work, ≥ 1)."""
    return math.pow((core + 2 * halo) / max(core, 1), 2)
