"""Angle stacks left on disk: a chunked array (a Zarr array, or tifffile's Zarr store of a
tiled TIFF) as a lazy Dask stack that is read block by block.

When a stack is read lazily
---------------------------
:func:`~napari_polarseg.io.read_stack` reads a tiled or BigTIFF stack and a Zarr /
OME-Zarr array lazily when ``lazy="always"``, or with ``lazy="auto"`` (the default) when
the stack's decoded size exceeds :data:`LAZY_BYTES` (256 MiB: a 4 × 5 MP uint16 stack,
80 MiB, is read whole; a 4 × 24 MP uint16 stack, 192 MiB, too; a 4 × 40 MP one is not);
``lazy="never"`` reads every file whole.

:attr:`StackData.stack <napari_polarseg.io.stack_data.StackData.stack>` is then a
``dask.array.Array`` (N, H, W) whose blocks hold every frame of about
:data:`BLOCK_BYTES` of the file's data (whole tiles of the file); slicing it and calling
``.compute()`` (or ``numpy.asarray``) reads only the tiles under the slice. The colour to
grey conversion, the saturation flags (:attr:`StackData.saturated`, lazy too) and the dark
frame / offset subtraction are done block by block on the way. The reader's checks
(:mod:`napari_polarseg.io.readers`, *Checks*) need each frame's lowest and highest value:
they are computed block by block in one pass over the file (:func:`frame_extremes`), so
reading keeps a few blocks in memory at a time, never the file.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..engine import disk_arrays
from ..engine.errors import PolarsegError
from ..engine.limits import check_bytes
from .common import dims, first_line, input_error
from .frames import grey_frames
from .read_options import LAZY_CHOICES, ReadOptions
from .stack_data import BlackLevel, StackData

#: Decoded size (bytes) above which ``lazy="auto"`` reads a stack lazily.
LAZY_BYTES = 256 * 2**20
#: Target decoded size (bytes) of one block of a lazy stack (all its frames).
BLOCK_BYTES = 8 * 2**20


@dataclass(frozen=True)
class LazyReader:
    """How a stack format is read lazily (``StackFormat.lazy``).

    Attributes
    ----------
    nbytes : callable
        ``nbytes(path) -> int``: the stack's decoded size from the file's header alone
        (0 when the header cannot be read: the whole reader then says what is wrong).
    read : callable
        ``read(path, options, black_level) -> StackData`` with Dask arrays.
    """

    nbytes: Callable[[Path], int]
    read: Callable[[Path, ReadOptions, BlackLevel], StackData]


def is_lazy(array: Any) -> bool:
    """Whether ``array`` is a Dask array (without importing Dask when nothing did)."""
    dask_array = sys.modules.get("dask.array")
    return dask_array is not None and isinstance(array, dask_array.Array)


def wants_lazy(opts: ReadOptions, nbytes: int) -> bool:
    """Whether a stack of ``nbytes`` decoded bytes is read lazily (``opts.lazy``)."""
    assert opts.lazy in LAZY_CHOICES
    if opts.lazy == "always":
        return True
    return opts.lazy == "auto" and nbytes > LAZY_BYTES


def lazy_blocks(array: Any, whole: tuple[int, ...] = ()) -> Any:
    """A chunked array (Zarr, or anything sliceable with ``shape``, ``dtype`` and
    ``chunks``) as a Dask array of blocks of about :data:`BLOCK_BYTES`, each a whole
    number of the array's own chunks and whole along the axes ``whole`` (the frames, a
    colour axis: every block then holds all the frames)."""
    import dask.array as da

    shape = tuple(int(n) for n in array.shape)
    wanted = tuple(-1 if axis in whole else "auto" for axis in range(len(shape)))
    chunks = da.core.normalize_chunks(
        wanted,
        shape,
        limit=BLOCK_BYTES,
        dtype=array.dtype,
        previous_chunks=getattr(array, "chunks", None),
    )
    return da.from_array(array, chunks=chunks, lock=False, asarray=True, fancy=False)


def _grey_block(
    block: np.ndarray,
    path: Path,
    colour: bool,
    channel: int | None,
    level: float | None,
    part: int,
) -> Any:
    """One block through :func:`~napari_polarseg.io.frames.grey_frames`: its grey data
    (``part`` 0) or its saturated samples (``part`` 1)."""
    return grey_frames(path, block, colour, channel, True, level)[part]


def lazy_grey_frames(
    path: Path, data: Any, colour: bool, channel: int | None, level: float | None
) -> tuple[Any, Any]:
    """:func:`~napari_polarseg.io.frames.grey_frames` of a lazy (N, H, W[, C]) array,
    block by block: the grey stack (N, H, W) and the saturated samples (None without a
    level). The dimensions, the dtype and the channel are checked on a one-pixel corner
    first, so a bad file is refused before anything is read."""
    corner = np.asarray(data[(slice(None), slice(0, 1), slice(0, 1))])
    grey, flags = grey_frames(path, corner, colour, channel, True, level)
    drop = (3,) if colour else ()
    args = (path, colour, channel, level)
    stack = data.map_blocks(_grey_block, *args, 0, dtype=grey.dtype, drop_axis=drop)
    saturated = None
    if flags is not None:
        saturated = data.map_blocks(_grey_block, *args, 1, dtype=np.bool_, drop_axis=drop)
    return stack, saturated


def _subtract_block(
    block: np.ndarray, dark: np.ndarray | None, black: BlackLevel, path: Path
) -> Any:
    """One block less its part of the dark frame (1, h, w) and the offset."""
    part = BlackLevel(None if dark is None else dark[0], black.dark_name, black.offset)
    return part.subtract(path, block)


def lazy_subtract(path: Path, stack: Any, black: BlackLevel) -> Any:
    """:meth:`BlackLevel.subtract` of a lazy stack (N, H, W), block by block (float64)."""
    if not black.subtracts:
        return stack
    import dask.array as da

    if black.dark is None:
        return stack.map_blocks(_subtract_block, None, black, path, dtype=np.float64)
    dark = np.asarray(black.dark, dtype=np.float64)
    if dark.shape != tuple(stack.shape[1:]):
        raise input_error(
            black.dark_name or path,
            f"the dark frame is {dims(dark.shape)} pixels but the frames are "
            f"{dims(stack.shape[1:])}",
        )
    if not np.all(np.isfinite(dark)):
        raise input_error(black.dark_name or path, "the dark frame has NaN or infinite values")
    dark = da.from_array(dark[None], chunks=((1,), *stack.chunks[1:]))
    return da.map_blocks(_subtract_block, stack, dark, black, path, dtype=np.float64)


def frame_extremes(stack: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Each frame's lowest and highest value and, for float data, whether it holds any
    finite value (the extremes are then those of its finite values, NaN without any).

    ``stack`` (N, H, W) is a NumPy or a lazy Dask array; a lazy one is read once, block by
    block (one pass computes all three).
    """
    axes = (1, 2)
    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN frame: said by caller
        if stack.dtype.kind != "f":
            parts: tuple[Any, ...] = (stack.min(axis=axes), stack.max(axis=axes))
        else:
            finite = np.isfinite(stack)
            values = np.where(finite, stack, np.nan)
            parts = (np.nanmin(values, axis=axes), np.nanmax(values, axis=axes))
            parts += (finite.any(axis=axes),)
        if is_lazy(stack):
            import dask

            parts = dask.compute(*parts)
    lo, hi, *finite_any = (np.asarray(p) for p in parts)
    return lo, hi, (finite_any[0] if finite_any else None)


def lazy_read_error(path: Path, exc: BaseException) -> Exception:
    """The one-line error of a failure while a lazy stack's blocks are read."""
    return input_error(path, f"cannot read the file's data ({first_line(exc)})")


def in_memory(data: StackData, limit: int) -> StackData:
    """``data`` with its lazy arrays read into memory (NumPy), after checking that the
    stack fits in ``limit`` bytes, with its float64 copy when it is not of integers (the
    engine keeps camera counts as they are: :func:`~..engine.run_memory.stack_bytes`);
    ``data`` itself if nothing is lazy."""
    lazy = [name for name in ("stack", "saturated") if is_lazy(getattr(data, name))]
    if not lazy:
        return data
    import dask.array

    shape, dtype = data.stack.shape, data.stack.dtype
    copy = 0 if np.issubdtype(dtype, np.integer) else 8
    check_bytes(
        float(np.prod(shape)) * (dtype.itemsize + copy),
        f"{data.source}: reading {dims(shape)} values of {data.stack.dtype.name}",
        limit,
    )
    sources = [getattr(data, name) for name in lazy]
    # written block by block into arrays placed by the run's memory limit (in temporary
    # files for an image whose full-size arrays do not fit it: disk_arrays), the file
    # read once for all of them
    targets = [disk_arrays.empty(a.shape, a.dtype) for a in sources]
    try:
        dask.array.store(sources, targets, lock=False)
    except PolarsegError:
        raise
    except Exception as exc:
        raise lazy_read_error(Path(data.source), exc) from exc
    for name, value in zip(lazy, targets, strict=True):
        setattr(data, name, value)
    data.metadata["lazy"] = False
    return data
