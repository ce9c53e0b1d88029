"""Zarr and OME-Zarr angle stacks: a directory store ``NAME.zarr``, read lazily or whole.

What is read
------------
- **A Zarr array** at the store's root: (N, H, W) frames, or (N, H, W, C) colour frames
  (C = 2, 3 or 4; grey by the BT.601 luma unless a channel is chosen).
- **An OME-Zarr image** (a group with ``multiscales`` metadata, NGFF 0.4 in the group's
  attributes or 0.5 under ``"ome"``): the first, full-resolution dataset of its first
  multiscale. Axes of length 1 other than the last two are dropped, so a
  (t, c, z, y, x) image with t = z = 1 is read as (c, y, x): one frame per channel.

The polariser angles are the attribute :data:`ANGLES_ATTR` (``"angles_deg"``): a list of
numbers in **degrees**, one per frame, in the array's attributes or else the group's::

    import zarr
    z = zarr.open_array("scene.zarr", mode="w", shape=(4, 4096, 4096), chunks=(4, 512, 512),
                        dtype="uint16")
    z.attrs["angles_deg"] = [0, 45, 90, 135]

Data are only ever read as numbers (Zarr's codecs); nothing in a store is run as code.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..engine.limits import memory_limit
from .angles import enough_angles
from .common import (
    check_read_size,
    first_line,
    input_error,
    metadata_angles,
    saturation_level,
)
from .lazy_stack import LazyReader, in_memory, lazy_blocks, lazy_grey_frames, lazy_subtract
from .read_options import ReadOptions
from .stack_data import BlackLevel, StackData

#: The attribute (of the array, else of its group) that holds the angles in degrees.
ANGLES_ATTR = "angles_deg"


def _multiscale(attrs: dict[str, Any]) -> dict[str, Any] | None:
    """The first ``multiscales`` entry of an OME-Zarr group's attributes (NGFF 0.4 or
    0.5), or None."""
    scales = attrs.get("multiscales", attrs.get("ome", {}).get("multiscales"))
    return scales[0] if isinstance(scales, list) and scales else None


def open_zarr_array(path: Path) -> tuple[Any, dict[str, Any], list[str] | None]:
    """The stack's Zarr array, the group's attributes (``{}`` for a root array) and the
    OME-Zarr axis names (None without them).

    Raises
    ------
    PolarsegError
        If the store cannot be opened or holds no array to read.
    """
    import zarr

    if not path.is_dir():
        raise input_error(path, "no such Zarr store (a .zarr is a folder)")
    try:
        node = zarr.open(path, mode="r")
    except Exception as exc:
        raise input_error(path, f"cannot open the Zarr store ({first_line(exc)})") from exc
    if isinstance(node, zarr.Array):
        return node, {}, None
    attrs = dict(node.attrs)
    scale = _multiscale(attrs)
    if scale is None:
        arrays = sorted(name for name, _ in node.arrays())
        raise input_error(
            path,
            "the Zarr group is not an OME-Zarr image (no 'multiscales' metadata) "
            f"and not an array; its arrays: {', '.join(arrays) or 'none'}",
        )
    try:
        array = node[scale["datasets"][0]["path"]]
    except (KeyError, IndexError, TypeError) as exc:
        raise input_error(path, f"bad OME-Zarr multiscales metadata ({first_line(exc)})") from exc
    axes = [a["name"] if isinstance(a, dict) else str(a) for a in scale.get("axes", [])]
    return array, attrs, (axes or None)


def _frame_index(path: Path, shape: tuple[int, ...], axes: list[str] | None) -> tuple[Any, ...]:
    """The index that drops the OME-Zarr axes of length 1 other than the last two."""
    if axes is not None and len(axes) != len(shape):
        raise input_error(path, f"the OME-Zarr axes {axes} do not fit the array's {shape}")
    index: list[Any] = [slice(None)] * len(shape)
    extra = len(shape) - 3
    for axis in range(len(shape) - 2):
        if extra > 0 and shape[axis] == 1 and axes is not None:
            index[axis] = 0
            extra -= 1
    return tuple(index)


def zarr_stack_bytes(path: Path) -> int:
    """The stack's decoded size in bytes (0 when the store cannot be opened)."""
    try:
        array = open_zarr_array(path)[0]
    except Exception:
        return 0
    return int(np.prod(array.shape)) * array.dtype.itemsize


def zarr_angles(array: Any, attrs: dict[str, Any]) -> Any:
    """The :data:`ANGLES_ATTR` of the array, else of the group (degrees), or None."""
    found = dict(array.attrs).get(ANGLES_ATTR)
    return found if found is not None else attrs.get(ANGLES_ATTR)


def zarr_carries_angles(path: Path) -> bool:
    """Whether the store names its angles (:data:`ANGLES_ATTR`; never raises)."""
    try:
        return enough_angles(zarr_angles(*open_zarr_array(path)[:2]))
    except Exception:
        return False


def read_lazy_zarr_stack(path: Path, opts: ReadOptions, black: BlackLevel) -> StackData:
    """A Zarr / OME-Zarr stack left on disk: :attr:`StackData.stack` is a Dask array
    (N, H, W) whose blocks hold all frames (whole Zarr chunks)."""
    array, attrs, axes = open_zarr_array(path)
    if array.dtype.kind not in "biuf":
        raise input_error(path, f"image data must be real numbers, got dtype {array.dtype}")
    index = _frame_index(path, tuple(array.shape), axes)
    kept = [n for n, i in zip(array.shape, index, strict=True) if i != 0]
    colour = axes is None and len(kept) == 4 and kept[-1] in (2, 3, 4)
    kept_axes = [axis for axis, i in enumerate(index) if i != 0]
    whole = (kept_axes[0], *((kept_axes[3],) if colour else ())) if len(kept) >= 3 else ()
    data = lazy_blocks(array, whole)[index]  # the index drops OME-Zarr axes of length 1
    level = saturation_level(opts.saturation, data.dtype)
    stack, saturated = lazy_grey_frames(path, data, colour, opts.channel, level)
    stack = lazy_subtract(path, stack, black)
    info: dict[str, Any] = {"format": "zarr", "lazy": True, "saturation_level": level}
    info["block_shape"] = [int(c[0]) for c in stack.chunks]
    if axes is not None:
        info["ome_axes"] = axes
    angles = metadata_angles(path, zarr_angles(array, attrs), f"the '{ANGLES_ATTR}' attribute")
    return StackData(stack, angles, os.fspath(path), info, saturated=saturated)


def read_zarr_stack(path: Path, opts: ReadOptions, black: BlackLevel) -> StackData:
    """A Zarr / OME-Zarr stack read whole (NumPy arrays), after the memory check."""
    array = open_zarr_array(path)[0]
    limit = opts.max_bytes() or memory_limit()
    check_read_size(path, array.shape, array.dtype, limit)
    return in_memory(read_lazy_zarr_stack(path, opts, black), limit)


#: The lazy reading of a Zarr stack (``STACK_FORMATS[".zarr"].lazy``).
LAZY_ZARR = LazyReader(zarr_stack_bytes, read_lazy_zarr_stack)
