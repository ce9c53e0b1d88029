"""Writing results atomically: TIFF, OME-Zarr, angle-stack TIFF, JSON and PNG (no napari,
no Qt).

:func:`write_tiff`, :func:`write_stack_tiff`, :func:`write_json` and :func:`write_png`
write to a temporary file in the destination's directory and :func:`os.replace` it into
place (:func:`atomic_output`), so a failure never leaves a truncated file where a good one
was; :func:`write_zarr` does the same with a directory (:func:`atomic_folder`). A large or
lazy image goes to a tiled BigTIFF (:mod:`napari_polarseg.io.tiff_tiles`).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from ..engine.errors import PolarsegError
from .common import PathLike
from .ome_zarr import write_ome_zarr
from .tiff_tiles import wants_tiles, write_tiled_tiff


@contextlib.contextmanager
def atomic_output(path: PathLike) -> Iterator[Path]:
    """Context manager giving a temporary path that replaces ``path`` on success.

    The temporary file lives in the destination's directory (so :func:`os.replace` is
    atomic) and keeps its extension (so writers that look at it pick the right format).
    On any exception it is deleted and ``path`` is left as it was.

    Examples
    --------
    >>> with atomic_output("figure.png") as tmp:        # doctest: +SKIP
    ...     fig.savefig(tmp)
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp{path.suffix}")
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_folder(path: PathLike) -> Iterator[Path]:
    """Context manager giving a temporary directory name that replaces the directory (or
    file) ``path`` on success; on any exception the temporary directory is removed and
    ``path`` is left as it was."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    old = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.old")
    try:
        yield tmp
        if path.exists():
            os.replace(path, old)
        try:
            os.replace(tmp, path)
        except BaseException:
            if old.exists():
                os.replace(old, path)
            raise
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if old.is_dir():
        shutil.rmtree(old, ignore_errors=True)
    elif old.exists():
        old.unlink()


def write_tiff(path: PathLike, array: Any, metadata: dict[str, Any] | None = None) -> None:
    """Write an array as a grey (multi-page if 3-D) TIFF, atomically: a tiled BigTIFF
    written tile by tile for a large or lazy image
    (:func:`~napari_polarseg.io.tiff_tiles.wants_tiles`).

    Parameters
    ----------
    path : str or path
        Destination ``.tif``.
    array : array
        (H, W) or (N, H, W), any dtype tifffile writes; NumPy or Dask.
    metadata : dict, optional
        JSON-serialisable items stored in the ImageDescription (tifffile's shaped
        metadata, read back by ``TiffFile.shaped_metadata``).
    """
    with atomic_output(path) as tmp:
        if wants_tiles(array):
            write_tiled_tiff(tmp, array, dict(metadata or {}))
        else:
            data = np.asarray(array)
            tifffile.imwrite(tmp, data, photometric="minisblack", metadata=dict(metadata or {}))


def write_zarr(
    path: PathLike, array: Any, metadata: dict[str, Any] | None = None, *, labels: bool = False
) -> None:
    """Write an image (H, W) or planes (C, H, W), NumPy or Dask, as an OME-Zarr directory
    (:func:`~napari_polarseg.io.ome_zarr.write_ome_zarr`), atomically.

    ``metadata`` goes under the group's ``"polarseg"`` attribute; ``labels``: a labels
    image (NGFF ``image-label``, downsampled without new values).
    """
    path = Path(path)
    with atomic_folder(path) as tmp:
        write_ome_zarr(tmp, array, _jsonable(metadata or {}), labels=labels, name=path.stem)


def write_stack_tiff(path: PathLike, stack: np.ndarray, angles_deg: Sequence[float]) -> None:
    """Write an angle stack as a multi-page TIFF with its angles in the metadata.

    Parameters
    ----------
    path : str or path
        Destination ``.tif``.
    stack : array (N, H, W)
        The frames.
    angles_deg : sequence of N floats
        Polariser angles in degrees; :func:`napari_polarseg.io.readers.read_stack` reads
        them back.
    """
    stack = np.asarray(stack)
    angles = np.asarray(angles_deg, dtype=np.float64).ravel()
    if stack.ndim != 3:
        raise PolarsegError(f"an angle stack must be (frames, rows, columns), got {stack.shape}")
    if angles.size != stack.shape[0]:
        raise PolarsegError(f"{stack.shape[0]} frames but {angles.size} angles")
    write_tiff(path, stack, {"angles": angles.tolist(), "angle_unit": "degrees"})


def _jsonable(obj: Any) -> Any:
    """Plain JSON types from numpy scalars/arrays, paths and tuples; NaN/inf become null."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: PathLike, obj: Any) -> None:
    """Write an object as indented JSON, atomically.

    numpy scalars and arrays become numbers and lists, paths strings, NaN and infinities
    ``null``. Serialisation happens before the file is touched: an object that cannot be
    serialised raises :class:`TypeError` and leaves ``path`` as it was.
    """
    text = json.dumps(_jsonable(obj), indent=2, allow_nan=False) + "\n"
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_png(path: PathLike, image: np.ndarray) -> None:
    """Write a uint8/uint16 image (H, W), (H, W, 3) or (H, W, 4) as PNG, atomically.

    Boolean images are written as 0/255. Other dtypes raise :class:`PolarsegError`
    (scale them to an integer type first).
    """
    from PIL import Image

    image = np.asarray(image)
    if image.dtype == np.bool_:
        image = image.astype(np.uint8) * 255
    if image.dtype not in (np.uint8, np.uint16):
        raise PolarsegError(f"PNG images must be uint8 or uint16, got {image.dtype}")
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[-1] in (3, 4))):
        raise PolarsegError(
            f"a PNG image must be (H, W), (H, W, 3) or (H, W, 4), got {image.shape}"
        )
    with atomic_output(path) as tmp:
        # zlib level 1: a camera frame's composite in a fifth of the time of the default
        # level, for files about a third larger
        Image.fromarray(image).save(tmp, format="PNG", compress_level=1)
