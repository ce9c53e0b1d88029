"""Memory limits: refuse work that would exhaust memory *before* allocating it.

A mistyped size, a huge TIFF or a tiny window on a large image can ask for more memory
than the machine has; numpy would then either raise a bare ``MemoryError`` or push the
machine into swap. Instead, readers check a file's header and the command line estimates
the pipeline's peak memory from the stack's shape and the parameters, and both refuse
with a :class:`PolarsegError` that says how much would be needed.

The limit is the number of bytes in the environment variable :data:`ENV_VAR`
(``POLARSEG_MAX_BYTES``, e.g. ``32e9`` or ``32GiB``), or the ``limit`` argument
(``polarseg segment --max-memory 20G``), else :func:`default_max_bytes`:
:data:`DEFAULT_MAX_BYTES` (16 GiB), or :data:`RAM_SHARE` of the machine's physical memory
when that is less. The methods that work tile by tile choose their tiles from the limit,
so their peak follows it; a run is refused only when its full-size arrays alone exceed
it. 16 GiB: at that limit no input under 100 MP is refused, by the default method or by
scribbles, whose full-size arrays at 100 MP (the stack, the pipeline's kept maps, the
labels, the class probabilities) come to about 15 GiB; beyond it a tile gains nothing
(the tiles of the default method stop growing at 2048 px) while a whole-image run of an
image that would fit only wastes memory the viewer and the system need.

Per method: :func:`~.run_memory.estimate_pipeline_bytes` counts the thesis blocks, or
the method's own peak with the tiles it would use (:mod:`.run_memory`);
:func:`estimate_scribble_bytes` the scribbles method on the whole image, from the
feature stack it builds (:func:`feature_bytes_per_pixel`) and the full-size arrays it
keeps (:func:`scribble_bytes_per_pixel`); the latter's split into tile-bound and
full-size bytes chooses its tile size
(:func:`~.classifier.tiled_prediction.scribble_tiles`).
"""

from __future__ import annotations

import os
import re
from typing import Any

from .errors import PolarsegError

#: Largest default memory limit (bytes) of a read or a run (:func:`default_max_bytes`).
DEFAULT_MAX_BYTES = 16 * 2**30
#: Share of the machine's physical memory the default limit never exceeds.
RAM_SHARE = 0.75
#: Environment variable overriding :data:`DEFAULT_MAX_BYTES`.
ENV_VAR = "POLARSEG_MAX_BYTES"

_UNITS = {"": 1, "B": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}


def parse_bytes(text: str) -> int:
    """Bytes from ``"8e9"``, ``"512MiB"``, ``"16G"`` or ``"2GB"`` (binary multiples).

    Raises
    ------
    PolarsegError
        If the text is not a positive size.
    """
    match = re.fullmatch(r"\s*([0-9.eE+]+)\s*([KMGT]?)(?:i?B)?\s*", str(text), re.IGNORECASE)
    try:
        value = float(match.group(1)) * _UNITS[match.group(2).upper()] if match else -1.0
    except ValueError:
        value = -1.0
    if not value > 0 or value == float("inf"):
        raise PolarsegError(f"a memory size must be a positive number of bytes, got {text!r}")
    return int(value)


def physical_memory() -> int | None:
    """Bytes of physical memory of the machine (None where the system does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):  # pragma: no cover - e.g. Windows
        return None


def default_max_bytes() -> int:
    """The default memory limit: :data:`DEFAULT_MAX_BYTES`, or :data:`RAM_SHARE` of the
    physical memory when that is less (module docstring)."""
    ram = physical_memory()
    if ram is None or ram <= 0:
        return DEFAULT_MAX_BYTES
    return min(DEFAULT_MAX_BYTES, int(RAM_SHARE * ram))


def memory_limit(limit: int | float | None = None) -> int:
    """The memory limit in bytes: ``limit``, else ``$POLARSEG_MAX_BYTES``, else
    :func:`default_max_bytes`."""
    if limit is not None:
        if not limit > 0:
            raise PolarsegError(f"the memory limit must be positive, got {limit!r}")
        return int(limit)
    env = os.environ.get(ENV_VAR)
    if env:
        try:
            return parse_bytes(env)
        except PolarsegError:
            raise PolarsegError(f"{ENV_VAR}={env!r} is not a memory size") from None
    return default_max_bytes()


def work_bytes(limit: int | float | None, held: int) -> int:
    """The memory left to a run's work, bytes: :func:`memory_limit` of ``limit`` less
    ``held`` bytes (its stack, flags, …) and the libraries (:data:`RUNTIME_BYTES`); at
    least 1."""
    return max(memory_limit(limit) - int(held) - RUNTIME_BYTES, 1)


def format_bytes(n: float) -> str:
    """Human-readable size: ``format_bytes(3 * 2**30) == '3.0 GiB'``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0
    return f"{n:.1f} PiB"  # pragma: no cover


def check_bytes(needed: float, what: str, limit: int | float | None = None) -> None:
    """Raise if ``needed`` bytes exceed the memory limit.

    Parameters
    ----------
    needed : float
        Estimated bytes.
    what : str
        What needs them, for the message (e.g. ``"reading a 40000 x 40000 x 19 stack"``).
    limit : float, optional
        Limit in bytes (default: :func:`memory_limit`).

    Raises
    ------
    PolarsegError
        ``"<what> would need 37.2 GiB of memory, more than the limit of 8.0 GiB (set
        POLARSEG_MAX_BYTES or --max-memory to allow more)"``.
    """
    cap = memory_limit(limit)
    if needed > cap:
        raise PolarsegError(
            f"{what} would need {format_bytes(needed)} of memory, more than the limit of "
            f"{format_bytes(cap)} (set {ENV_VAR} or --max-memory to allow more)"
        )


#: Bytes of the running interpreter and the libraries a run loads (numpy, SciPy,
#: scikit-image, scikit-learn) before any array: 85 MB measured after a default run on a
#: small image. Counted in every run's estimate and kept out of the methods' work
#: (:meth:`~.pipeline.Pipeline.work_limit`).
RUNTIME_BYTES = 128 * 2**20
#: float64 maps of H × W the pipeline keeps after its chunked fit, beyond the stack and
#: its flags (:meth:`~.pipeline.Pipeline.work_limit`): Î, ρ, φ, residual, θ and the
#: invalid and clamped masks (42 bytes a pixel; the diffuse azimuth is φ itself, the
#: specular one 8 more): what a method's work sits on top of.
KEPT_MAPS = 6
#: Bytes a pixel of the scribbles method's full-size arrays beyond the pipeline's maps
#: and its K class planes: the superpixels' edge map (float64) and its temporaries
#: (4 float64 maps while it is made), the superpixels (int32), the walk's nodes
#: (int32, int64 while renumbered), the labels (int32 and the result's int64), the
#: uncertainty (float32).
SCRIBBLE_FIXED_BYTES = 8 + 32 + 4 + 12 + 12 + 4
#: Float32 per-pixel products whose local means the features take (:data:`MOMENTS`).
FEATURE_MOMENTS = 10
#: Float32 temporaries of one scale while its features are made, beyond its features:
#: the smoothed moments, DoLP, the two variances.
SCALE_TEMPORARIES = 14
#: Bytes a pixel of the region means' averaging matrix (float32 weight, int32 row and
#: column) and of one expanded plane.
REGION_MEAN_BYTES = 16


def feature_bytes_per_pixel(
    params: Any = None, channels: int = 1, threads: int | None = None
) -> float:
    """Peak bytes a pixel of :func:`~.features.pixel_features.pixel_features` on one
    image: per channel its Î, ρ, φ (float32), the moments of every pyramid level
    (:data:`FEATURE_MOMENTS` float32 / f²), the features kept (11 a scale for the
    default groups, / f² on a coarser grid: 113 bytes), the temporaries of the scales
    computed at once (``threads``, :data:`SCALE_TEMPORARIES` + features, / f²) and the
    region means' matrix. Measured: 320 bytes a pixel at 1 MP and 348 at 4 MP, on
    2 threads, for the 390 counted."""
    from .features.pixel_features import (
        PixelFeatureParams,
        feature_names,
        feature_threads,
        pyramid_factor,
    )

    params = params or PixelFeatureParams()
    threads = feature_threads() if threads is None else int(threads)
    names = feature_names(params)
    per_scale = {
        s: sum(n.endswith(f"@{s:g}") and ":" not in n for n in names) for s in params.scales
    }
    area = {s: 1.0 / pyramid_factor(s) ** 2 for s in params.scales}
    kept = sum(4 * per_scale[s] * area[s] for s in params.scales)
    moments = sum(4 * FEATURE_MOMENTS / f**2 for f in {pyramid_factor(s) for s in params.scales})
    work = sorted(4 * (SCALE_TEMPORARIES + per_scale[s]) * area[s] for s in params.scales)
    busy = sum(work[-max(threads, 1) :])
    regions = REGION_MEAN_BYTES if "regions" in params.groups else 0
    return channels * (12 + moments + kept * 1.0) + busy + regions


def scribble_bytes_per_pixel(
    params: Any = None, channels: int = 1, n_classes: int = 4, tiled: bool = False
) -> tuple[float, float]:
    """(bytes a pixel of the work that tiles bound, bytes a pixel of the full-size
    arrays) of the scribbles method beyond the pipeline's kept maps.

    The first: :func:`feature_bytes_per_pixel` and the prediction's K float32 planes
    twice (the prior and the interpolated grid). The second: the K float32 planes of
    the output probabilities and :data:`SCRIBBLE_FIXED_BYTES`; whole-image (not
    ``tiled``) also the prior of the walk (K float32 planes) and a full-size float32
    copy of Î while its median is taken.
    """
    work = feature_bytes_per_pixel(params, channels) + 8 * n_classes
    fixed = 4 * n_classes + SCRIBBLE_FIXED_BYTES + (0 if tiled else 4 * n_classes + 4)
    return work, fixed


def estimate_scribble_bytes(
    shape: tuple[int, int], params: Any = None, channels: int = 1, n_classes: int = 4
) -> int:
    """Peak bytes of the scribbles method (features, training, prediction, walk) on
    the whole image of ``shape`` (H, W), with the pipeline's :data:`KEPT_MAPS`."""
    pixels = int(shape[0]) * int(shape[1])
    work, fixed = scribble_bytes_per_pixel(params, channels, n_classes)
    return int(pixels * (work + fixed + 8 * KEPT_MAPS))
