"""A TIFF angle stack read lazily through tifffile's Zarr store (tiled TIFF, BigTIFF).

``tifffile.imread(path, aszarr=True)`` gives a Zarr store over the first series' tiles or
strips (its full-resolution level, for a pyramid); :func:`read_lazy_tiff_stack` wraps it
in a Dask array (:func:`~napari_polarseg.io.lazy_stack.lazy_blocks`), so only the tiles a
slice covers are decoded. The axes, the bits per sample and the angles come from the
header as for a whole read (:mod:`napari_polarseg.io.tiff`,
:mod:`napari_polarseg.tiff_angles`; angles in degrees). A TIFF written in strips is read
the same way, one strip (or page) at a time.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from ..engine.errors import PolarsegError
from ..tiff_angles import FROM_JSON, tiff_angles
from .common import first_line, input_error, metadata_angles, saturation_level
from .lazy_stack import LazyReader, lazy_blocks, lazy_grey_frames, lazy_subtract
from .read_options import ReadOptions
from .stack_data import BlackLevel, StackData
from .tiff import SINGLE_IMAGE, colour_last, frame_axes, tifffile_messages


def tiff_stack_bytes(path: Path) -> int:
    """The decoded size in bytes of a TIFF's first series, from its header (0 when the
    file cannot be opened)."""
    try:
        with tifffile_messages(), tifffile.TiffFile(path) as tif:
            return int(tif.series[0].nbytes) if tif.series else 0
    except Exception:
        return 0


def _header(path: Path) -> tuple[tuple[int, ...], str, int | None, dict[str, Any]]:
    """Shape, axes, bits per sample (when fewer than the dtype holds) and angle metadata
    (``angles``, ``angles_from``) of the first series."""
    with tifffile.TiffFile(path) as tif:
        if not tif.series:
            raise input_error(path, "the TIFF file holds no image")
        series = tif.series[0]
        shape, axes = tuple(series.shape), series.axes
        bits = None
        with contextlib.suppress(Exception):
            bits = int(series.keyframe.bitspersample)
            if series.dtype.kind not in "ui" or bits >= series.dtype.itemsize * 8:
                bits = None
        frames = [n for n, ax in zip(shape, frame_axes(axes), strict=False) if ax not in "YXS"]
        found = tiff_angles(tif, int(np.prod(frames)) if frames else 1)
    angles = {} if found is None else {"angles": found[0], "angles_from": found[1]}
    return shape, axes, bits, angles


def _open(path: Path) -> tuple[Any, tuple[int, ...], str, int | None, dict[str, Any]]:
    """The series as a Dask array of blocks, and :func:`_header`'s items."""
    import zarr

    with tifffile_messages():
        try:
            shape, axes, bits, angles = _header(path)
            store = tifffile.imread(path, aszarr=True, series=0, level=0)
            array = zarr.open_array(store, mode="r")
        except PolarsegError:
            raise
        except Exception as exc:
            raise input_error(path, f"cannot read the TIFF file ({first_line(exc)})") from exc
    if tuple(array.shape) != shape:
        raise input_error(path, f"the TIFF's tiles hold {array.shape}, its series {shape}")
    # every block holds all the frames where they are the first axis (QYX, QYXS)
    colour_frames = len(shape) == 4 and axes.endswith("S")
    whole = (0,) if len(shape) == 3 else (0, 3) if colour_frames else ()
    data = lazy_blocks(array, whole)
    return data, shape, axes, bits, angles


def read_lazy_tiff_stack(path: Path, opts: ReadOptions, black: BlackLevel) -> StackData:
    """A TIFF stack left on disk: :attr:`StackData.stack` is a Dask array (N, H, W) whose
    blocks hold all frames; the colour conversion, saturation flags and black level are
    applied block by block."""
    data, shape, axes, bits, angles = _open(path)
    data, colour = colour_last(data, frame_axes(axes))
    if data.ndim == (3 if colour else 2):
        raise input_error(path, SINGLE_IMAGE)
    level = saturation_level(opts.saturation, data.dtype, bits)
    stack, saturated = lazy_grey_frames(path, data, colour, opts.channel, level)
    stack = lazy_subtract(path, stack, black)
    info: dict[str, Any] = {"format": "tiff", "lazy": True, "saturation_level": level}
    info["block_shape"] = [int(c[0]) for c in stack.chunks]
    if bits is not None:
        info["bits_per_sample"] = bits
    if angles.get("angles_from") not in (None, FROM_JSON):
        info["angles_from"] = angles["angles_from"]
    values = metadata_angles(path, angles.get("angles"))
    return StackData(stack, values, os.fspath(path), info, saturated=saturated)


#: The lazy reading of a TIFF stack (``STACK_FORMATS[".tif"].lazy``).
LAZY_TIFF = LazyReader(tiff_stack_bytes, read_lazy_tiff_stack)
