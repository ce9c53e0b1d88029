"""Images as OME-Zarr (NGFF 0.4): a multiscale pyramid in a Zarr (format 2) directory.

:func:`write_ome_zarr` writes an image (H, W) or planes (C, H, W) as the group
``NAME.zarr``: datasets ``0`` (full resolution), ``1``, ``2``, … each half the height and
width of the one before, until one fits in a chunk (:data:`CHUNK` = 512 × 512 pixels a
plane); the ``multiscales`` attribute names the axes (``c``, ``y``, ``x``) and each
level's scale. Integer images (labels, masks) are downsampled by taking every second
pixel (no new label values), float maps by the mean of 2 × 2 pixels (NaN ignored). A
labels image also carries ``image-label`` (NGFF labels), so OME-Zarr readers show it as
labels. The writer's own metadata (quantity, unit, …) goes under ``"polarseg"``.

Every level is written chunk by chunk from a NumPy or a lazy Dask array (the lower
levels from the level above, read back from disk), so a lazy image is never held whole.

Open one with zarr (``zarr.open_group("labels.zarr")["0"]``, lazily:
``dask.array.from_zarr("labels.zarr", component="0")``), or in napari with the
napari-ome-zarr plugin (``napari labels.zarr``) as a multiscale layer.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .lazy_stack import is_lazy

#: NGFF version of the metadata written.
NGFF_VERSION = "0.4"
#: Chunk shape (rows, columns) of every plane of every level.
CHUNK = (512, 512)


def _chunks(shape: tuple[int, ...]) -> tuple[int, ...]:
    """The Zarr chunks of a level: one plane, :data:`CHUNK` pixels."""
    plane = tuple(min(c, max(int(n), 1)) for c, n in zip(CHUNK, shape[-2:], strict=True))
    return (1, *plane) if len(shape) == 3 else plane


def _half(level: Any, integer: bool) -> Any:
    """The next level: every second pixel (``integer``) or the 2 × 2 mean (NaN ignored)."""
    import dask.array as da

    if integer:
        return level[..., ::2, ::2]
    axes = {level.ndim - 2: 2, level.ndim - 1: 2}
    even = level[..., : level.shape[-2] // 2 * 2, : level.shape[-1] // 2 * 2]
    return da.coarsen(_nanmean, even, axes, trim_excess=True).astype(level.dtype)


def _nanmean(block: np.ndarray, axis: Any = None) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # 2 x 2 pixels all NaN: NaN
        return np.nanmean(block, axis=axis)


def _axes(ndim: int) -> list[dict[str, str]]:
    planes = [{"name": "c", "type": "channel"}] if ndim == 3 else []
    return planes + [{"name": "y", "type": "space"}, {"name": "x", "type": "space"}]


def write_ome_zarr(
    path: Path,
    array: Any,
    metadata: dict[str, Any] | None = None,
    *,
    labels: bool = False,
    name: str | None = None,
) -> None:
    """Write ``array`` (H, W) or (C, H, W), NumPy or Dask, as an OME-Zarr image at
    ``path`` (a new directory; not atomic: :func:`~napari_polarseg.io.writers.write_zarr`
    renames it into place).

    Parameters
    ----------
    path : Path
        The directory to create (``NAME.zarr``).
    array : array (H, W) or (C, H, W)
        Any real dtype.
    metadata : dict, optional
        JSON-serialisable items stored under the group's ``"polarseg"`` attribute.
    labels : bool
        A labels image: ``image-label`` metadata, and downsampled by taking every second
        pixel whatever its dtype.
    name : str, optional
        The multiscale's name (default: the directory's name without ``.zarr``).
    """
    import dask.array as da
    import zarr

    data = da.asarray(array) if is_lazy(array) else da.from_array(np.asarray(array))
    if data.ndim not in (2, 3):
        raise ValueError(f"an OME-Zarr image here is (H, W) or (C, H, W), got {data.shape}")
    integer = labels or data.dtype.kind in "biu"
    root = zarr.open_group(path, mode="w", zarr_format=2)
    datasets = []
    level = data
    while True:
        index = len(datasets)
        target = root.create_array(
            str(index),
            shape=level.shape,
            dtype=level.dtype,
            chunks=_chunks(level.shape),
            chunk_key_encoding={"name": "v2", "separator": "/"},
            fill_value=0,
        )
        da.store(level.rechunk(_chunks(level.shape)), target, lock=False)
        scale = [1.0] * (data.ndim - 2) + [float(2**index)] * 2
        datasets.append(
            {"path": str(index), "coordinateTransformations": [{"type": "scale", "scale": scale}]}
        )
        if max(level.shape[-2:]) <= max(CHUNK):
            break
        level = _half(da.from_zarr(target), integer)
    attrs: dict[str, Any] = {
        "multiscales": [
            {
                "version": NGFF_VERSION,
                "name": name or path.name.removesuffix(".zarr"),
                "axes": _axes(data.ndim),
                "datasets": datasets,
                "type": "nearest" if integer else "mean",
            }
        ],
        "polarseg": dict(metadata or {}),
    }
    if labels:
        attrs["image-label"] = {"version": NGFF_VERSION}
    root.attrs.update(attrs)
