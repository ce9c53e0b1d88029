"""Large images as tiled BigTIFF, written tile by tile.

:func:`~napari_polarseg.io.writers.write_tiff` writes an image as a tiled BigTIFF
(:func:`write_tiled_tiff`) when a plane holds at least :data:`TILED_PIXELS` pixels or the
image is a lazy Dask array: 256 × 256 tiles (:data:`TILE`), zlib-compressed for integer
images (labels, masks: they shrink many times), uncompressed for float maps (they hardly
shrink and would cost seconds a map). tifffile, napari and any TIFF reader open such a
file; ``tifffile.imread(path, aszarr=True)`` reads it tile by tile.

The image is read in bands of whole rows (a Dask array: one row of its blocks at a time,
each block computed once), so a lazy image is never held whole.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from .lazy_stack import is_lazy

#: Pixels per plane from which an image is written as a tiled BigTIFF (4096 × 4096).
TILED_PIXELS = 4096 * 4096
#: Tile shape (rows, columns) of a tiled BigTIFF.
TILE = (256, 256)


def wants_tiles(array: Any) -> bool:
    """Whether ``array`` (H, W) or (N, H, W) is written as a tiled BigTIFF."""
    shape = array.shape
    return is_lazy(array) or int(shape[-1]) * int(shape[-2]) >= TILED_PIXELS


def _row_bands(plane: Any) -> Iterator[np.ndarray]:
    """Bands of whole rows of one plane (H, W): a Dask plane's rows of blocks, each
    computed once; a NumPy plane's tile rows."""
    if is_lazy(plane):
        top = 0
        for height in plane.chunks[0]:
            yield np.asarray(plane[top : top + height].compute())
            top += height
        return
    for top in range(0, plane.shape[0], TILE[0]):
        yield plane[top : top + TILE[0]]


def iter_tiles(array: Any, dtype: np.dtype) -> Iterator[np.ndarray]:
    """The tiles of ``array`` (H, W) or (N, H, W) in a tiled TIFF's order: plane by plane,
    tile rows top to bottom, tiles left to right (edge tiles smaller: tifffile pads them)."""
    planes = array if array.ndim == 3 else array[None]
    rows, cols = TILE
    for k in range(planes.shape[0]):
        pending = np.empty((0, planes.shape[2]), dtype)
        for band in _row_bands(planes[k]):
            pending = np.concatenate([pending, np.asarray(band, dtype)])
            while pending.shape[0] >= rows:
                for left in range(0, pending.shape[1], cols):
                    yield pending[:rows, left : left + cols]
                pending = pending[rows:]
        if pending.shape[0]:
            for left in range(0, pending.shape[1], cols):
                yield pending[:, left : left + cols]


def write_tiled_tiff(path: Path, array: Any, metadata: dict[str, Any]) -> None:
    """Write ``array`` (H, W) or (N, H, W), NumPy or Dask, as a tiled BigTIFF at ``path``
    (not atomically: :func:`~napari_polarseg.io.writers.write_tiff` renames it into
    place), ``metadata`` in the ImageDescription (tifffile's shaped metadata)."""
    dtype = np.dtype(array.dtype)
    compression = "zlib" if dtype.kind in "biu" else None
    tifffile.imwrite(
        path,
        iter_tiles(array, dtype),
        shape=tuple(int(n) for n in array.shape),
        dtype=dtype,
        bigtiff=True,
        tile=TILE,
        photometric="minisblack",
        compression=compression,
        compressionargs={"level": 1} if compression else None,
        metadata=dict(metadata),
    )
