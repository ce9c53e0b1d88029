"""Peak memory of one run per method, counting the tiles the run would work in.

What every run holds from start to end (bytes, P = H·W pixels, N frames), beyond the
interpreter and its libraries (:data:`~.limits.RUNTIME_BYTES`):

- the angle stack, N·P × its item size (the engine keeps an integer stack as it is and
  a float one as float64), and the pixel mask's flags, N·P bytes (:func:`stack_bytes`);
- the polarisation image of eq. 3.14, :data:`~.physics.fit_maps.FIT_MAP_BYTES` a pixel
  (Î, ρ, φ, residual in float64 and the invalid mask), written chunk by chunk: while it
  is fitted, the masked samples' boolean weights (N bytes a pixel) and the chunks being
  fitted on the cores (:func:`fit_bytes`).

On top of the stack, each method's own peak (:func:`method_bytes`), which counts the
pipeline's kept maps (:data:`~.limits.KEPT_MAPS` float64 a pixel) and is taken from the
same tile decision the method makes with the same limit:

- the superpixel methods that tile (the default, ``valid_superpixels``):
  :func:`~.unsupervised.tiled_regions.region_tiles`; whole image H·W ×
  (``WHOLE_BYTES_PER_PIXEL`` + 8 ``KEPT_MAPS``), tiled H·W × (8 ``KEPT_MAPS`` +
  ``TILED_FIXED_BYTES``) plus the outer boxes that run at once at
  ``TILE_BYTES_PER_PIXEL``; the others (``superpixels``, the consensus of several
  sizes) the whole image once a size;
- the pixel classifier on scribbles:
  :func:`~.classifier.tiled_prediction.scribble_tiles` with the bytes of
  :func:`~.limits.scribble_bytes_per_pixel`, whole or tiled alike; tiled with its
  full-size arrays in temporary files (the kept maps, edge map, superpixels, nodes,
  probabilities and labels: :func:`~.disk_arrays.on_disk_at`), H·W ×
  ``SCRIBBLE_DISK_FULL_BYTES`` in memory, the files' resident pages and the outer boxes
  that run at once.

So a run that tiles to fit is estimated at its tiled peak, and exceeds the limit only
when its full-size arrays alone do. The thesis block graph is
:func:`estimate_pipeline_bytes`'s (``blocks``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .chunks import CHUNK_BYTES, MIN_PARALLEL_POINTS, N_THREADS
from .disk_arrays import TRIM_BYTES, on_disk_at
from .limits import (
    KEPT_MAPS,
    RUNTIME_BYTES,
    check_bytes,
    memory_limit,
    scribble_bytes_per_pixel,
    work_bytes,
)
from .params import SegmentParams
from .physics.fit_maps import FIT_MAP_BYTES
from .physics.polarimage import FIT_CHUNK_PIXELS
from .registered import computes_block_maps
from .tiles import TileGrid

#: float64 temporaries a sample of the weighted fit's chunk holds at once (the samples,
#: their weights, the state means, the misfit and its square, the usable flags).
FIT_CHUNK_TEMPORARIES = 6
#: Full-size bytes a pixel a tiled superpixel run keeps in memory when its full-size
#: arrays are in temporary files (:func:`~.disk_arrays.on_disk_at`): the clustered-pixel
#: mask and one boolean comparison of the labels' renumbering.
DISK_FULL_BYTES = 2
#: Full-size bytes a pixel a tiled scribbles run keeps in memory when its full-size
#: arrays are in temporary files: the boolean comparisons of the borders between
#: superpixels (one a direction at a time) and of the stroke pixels while training.
SCRIBBLE_DISK_FULL_BYTES = 2
#: Pages of the temporary files resident at once: what the release thread lets the
#: resident memory grow by (:data:`~.disk_arrays.TRIM_BYTES`) and the band a copy
#: touches, with room for both.
DISK_RESIDENT_BYTES = 8 * TRIM_BYTES


@dataclass(frozen=True)
class MethodMemory:
    """A method's peak bytes on an image (its kept maps included) and its tiles (None:
    the whole image at once)."""

    bytes: int
    tiles: TileGrid | None = None


def stack_bytes(shape: tuple[int, int, int], itemsize: int = 8) -> int:
    """Bytes of the stack (N, H, W) as the engine keeps it (``itemsize`` bytes a sample:
    1 or 2 for camera counts, 8 for a float stack) and of the mask's flags (1 a sample)."""
    n, h, w = (int(v) for v in shape)
    return n * h * w * (int(itemsize) + 1)


def fit_bytes(shape: tuple[int, int, int], on_disk: bool = False) -> int:
    """Peak bytes of the chunked fit beyond the stack: the maps (none ``on_disk``: in
    temporary files, :mod:`.disk_arrays`), the boolean sample weights and one chunk of
    the weighted fit a thread (:func:`~.chunks.run_chunks`)."""
    n, h, w = (int(v) for v in shape)
    pixels = h * w
    chunk = min(pixels, FIT_CHUNK_PIXELS) * n * 8 * FIT_CHUNK_TEMPORARIES
    threads = N_THREADS if pixels >= MIN_PARALLEL_POINTS else 1
    maps = pixels * FIT_MAP_BYTES
    if on_disk:  # no more of the files resident than they hold
        maps = min(maps, DISK_RESIDENT_BYTES)
    return maps + pixels * n + threads * chunk


def box_pixels(grid: TileGrid) -> int:
    """Pixels of the outer boxes of ``grid`` in memory at once: the largest box (a core
    grown by its halo, clipped) times the tiles that run at once, ``grid.at_once`` on
    this process's threads (:data:`~.chunks.N_THREADS`; :func:`~.tile_map.tile_map_for`)."""
    side = grid.core + 2 * grid.halo
    in_flight = max(1, min(grid.at_once or 1, N_THREADS))
    return min(side, grid.shape[0]) * min(side, grid.shape[1]) * in_flight


def superpixel_bytes(
    shape: tuple[int, int], params: SegmentParams, limit: int | None
) -> MethodMemory:
    """The superpixel methods (module docstring)."""
    from .methods.registry import get_method
    from .methods.valid_superpixels import ValidSuperpixels
    from .unsupervised.tiled_regions import (
        TILE_BYTES_PER_PIXEL,
        TILED_FIXED_BYTES,
        WHOLE_BYTES_PER_PIXEL,
        region_tiles,
    )

    pixels = int(shape[0]) * int(shape[1])
    kept = 8 * KEPT_MAPS * pixels
    whole = pixels * WHOLE_BYTES_PER_PIXEL
    method = get_method(params.method)
    if not isinstance(method, ValidSuperpixels):
        return MethodMemory(kept + whole)
    if type(method).region_models is not ValidSuperpixels.region_models:
        sizes = len(getattr(method, "area_factors", (1,)))  # drawn together, not tiled
        return MethodMemory(kept + sizes * whole)
    unsupervised = method.params
    if params.object_size > 0:
        unsupervised = method.scaled_params(float(params.object_size), shape)
    grid = region_tiles(shape, unsupervised, limit)
    if grid is None:
        return MethodMemory(kept + whole)
    box = box_pixels(grid) * TILE_BYTES_PER_PIXEL
    full = kept + pixels * TILED_FIXED_BYTES
    if on_disk_at(pixels, limit):  # the kept maps, superpixels and labels in files
        resident = min(full, DISK_RESIDENT_BYTES)  # no more than the files hold
        return MethodMemory(pixels * DISK_FULL_BYTES + resident + box, grid)
    return MethodMemory(full + box, grid)


def scribble_method_bytes(
    shape: tuple[int, int], limit: int | None, channels: int = 1, n_classes: int = 4
) -> MethodMemory:
    """The pixel classifier on scribbles with the default features and prediction
    stride (module docstring)."""
    from .classifier.classifier_settings import ClassifierSettings
    from .classifier.pixel_classifier import PREDICTION_STRIDE
    from .classifier.pixel_segmentation import TILED_SMOOTHING
    from .classifier.tiled_features import tile_align, tile_halo
    from .classifier.tiled_prediction import prediction_margin, scribble_tiles

    features = ClassifierSettings().features
    halo = tile_halo(features, prediction_margin(PREDICTION_STRIDE, TILED_SMOOTHING))
    align = tile_align(features, PREDICTION_STRIDE)
    grid = scribble_tiles(shape, features, halo, align, channels, n_classes, limit=limit)
    pixels = int(shape[0]) * int(shape[1])
    kept = 8 * KEPT_MAPS * pixels
    work, fixed = scribble_bytes_per_pixel(features, channels, n_classes, tiled=grid is not None)
    if grid is None:
        return MethodMemory(int(kept + pixels * (work + fixed)))
    box = box_pixels(grid) * work
    full = kept + pixels * fixed
    if on_disk_at(pixels, limit):  # the kept maps and the method's planes in files
        resident = min(full, DISK_RESIDENT_BYTES)  # no more than the files hold
        return MethodMemory(int(pixels * SCRIBBLE_DISK_FULL_BYTES + resident + box), grid)
    return MethodMemory(int(full + box), grid)


def method_bytes(
    shape: tuple[int, int],
    params: SegmentParams,
    limit: int | None = None,
    *,
    scribbles: bool = False,
    channels: int = 1,
    n_classes: int = 4,
) -> MethodMemory:
    """The peak of the method of a run on an image of ``shape`` (H, W) under the memory
    ``limit`` (default :func:`~.limits.memory_limit`): the pixel classifier with
    ``scribbles`` (``channels`` feature channels, ``n_classes`` materials), else
    ``params.method`` (module docstring)."""
    cap = memory_limit(limit)
    if scribbles:
        return scribble_method_bytes(shape, cap, channels, n_classes)
    return superpixel_bytes(shape, params, cap)


def estimate_run_bytes(
    shape: tuple[int, int, int],
    params: SegmentParams,
    limit: int | None = None,
    *,
    itemsize: int = 8,
    scribbles: bool = False,
    channels: int = 1,
    n_classes: int = 4,
) -> int:
    """Peak bytes of a run without the thesis blocks on a stack of ``shape`` (N, H, W):
    the libraries (:data:`~.limits.RUNTIME_BYTES`), the stack and its flags plus the
    larger of the fit's peak and the method's (:func:`method_bytes`, with the normals
    the result adds), the method's tiles chosen under ``limit`` less the stack, as the
    run chooses them (:meth:`~.pipeline.Pipeline.work_limit`)."""
    n, h, w = (int(v) for v in shape)
    held = stack_bytes(shape, itemsize)
    work = work_bytes(limit, held)  # the methods' limit (Pipeline.work_limit)
    method = method_bytes(
        (h, w), params, work, scribbles=scribbles, channels=channels, n_classes=n_classes
    )
    on_disk = on_disk_at(h * w, work)
    return held + RUNTIME_BYTES + max(fit_bytes(shape, on_disk), method.bytes)


def _graph_kind(blocks: int, params: SegmentParams) -> str:
    """How the pipeline will store the block graph ("dense", "knn" or "spatial")."""
    from .stages import affinity_graph_kind

    return affinity_graph_kind(blocks, params)


def estimate_pipeline_bytes(
    shape: tuple[int, int, int],
    params: SegmentParams,
    blocks: bool | None = None,
    *,
    limit: int | float | None = None,
    itemsize: int = 8,
    scribbles: bool = False,
    channels: int = 1,
    n_classes: int = 4,
) -> int:
    """Rough peak memory (bytes) of one run on a stack of ``shape`` (N, H, W).

    Without ``blocks``: the stack (``itemsize`` bytes a sample as the engine keeps it)
    and the larger of the chunked fit's peak and the method's own, the pixel classifier's
    with ``scribbles`` (``channels``, ``n_classes``), counted with the tiles the method
    would choose under ``limit`` (default :func:`memory_limit`):
    :func:`~.run_memory.estimate_run_bytes`. A run that tiles to fit is estimated at its
    tiled peak.

    With ``blocks`` (default: when the method declares ``block_maps``, the thesis
    method; a run that asks for the thesis maps too) the thesis block graph on the whole
    image: the float64 stack and the temporaries of the fit (about 6 N × H × W values),
    about 24 float64 maps (with the reconstruction, its error and their temporaries), the
    block coefficients and features ((L + 1)² per block, a few copies), one chunk of
    harmonic evaluations, and the block graph: for a dense affinity its distance matrix
    and eigen-solver workspace (about 5 n_blocks² values); for a sparse one (k nearest
    neighbours or the spatial neighbourhood) a few copies of its non-zeros and the
    Lanczos vectors.
    """
    n, h, w = (int(v) for v in shape)
    pixels = h * w
    if not (computes_block_maps(params.method) if blocks is None else blocks):
        kinds = {"scribbles": scribbles, "channels": channels, "n_classes": n_classes}
        cap = memory_limit(limit)
        return estimate_run_bytes((n, h, w), params, cap, itemsize=itemsize, **kinds)
    win = max(int(params.window), 1)
    blocks_n = (h // win) * (w // win)
    k = (int(params.degree) + 1) ** 2
    kind = _graph_kind(blocks_n, params)
    if kind == "dense":
        graph = 5 * blocks_n * blocks_n
    else:
        radius = float(params.spatial_radius)
        neighbours = 30 if kind == "knn" else int(3.2 * (radius + 1) ** 2)
        graph = 6 * blocks_n * neighbours + 40 * blocks_n
    total = 8 * (6 * n * pixels + 24 * pixels + 4 * blocks_n * k + graph)
    return int(total + 2 * CHUNK_BYTES)


def check_pipeline_memory(
    shape: tuple[int, int, int],
    params: SegmentParams,
    limit: int | float | None = None,
    blocks: bool | None = None,
    **kinds: Any,
) -> int:
    """Refuse a run whose :func:`estimate_pipeline_bytes` exceeds the limit.

    ``blocks``: whether the run computes the block maps (default: when the method
    declares ``block_maps``); ``kinds``: the keywords of :func:`estimate_pipeline_bytes`
    that say what the run is (``itemsize``, ``scribbles``, ``channels``, ``n_classes``).
    The estimate counts the tiles the method chooses under the same limit, so a run
    that tiles to fit is not refused. Returns the estimate (bytes). Raises
    :class:`PolarsegError` naming the stack size (and, for a run on blocks, the window,
    the number of blocks and the degree) and the memory it would need.
    """
    blocks = computes_block_maps(params.method) if blocks is None else blocks
    needed = estimate_pipeline_bytes(shape, params, blocks, limit=limit, **kinds)
    n, h, w = shape
    what = f"segmenting {n} frames of {h} x {w} pixels"
    if blocks:
        n_blocks = (h // params.window) * (w // params.window)
        what += f" with window {params.window} ({n_blocks} blocks) and degree {params.degree}"
    check_bytes(needed, what, limit)
    return needed
