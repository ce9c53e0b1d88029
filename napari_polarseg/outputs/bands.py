"""A large result's output images, made band by band of rows when they are written
(issue 39).

A result folder's images of a large image (a plane of at least
:data:`~napari_polarseg.io.tiff_tiles.TILED_PIXELS` pixels: :func:`is_large`) are not made
whole before they are written: :func:`as_dtype` (the float32 maps, ``labels.tif``,
``mask.tif``) and :func:`stokes_image` (``stokes.tif``) give lazy Dask arrays whose
blocks are :data:`BAND_ROWS` rows of the image, computed from the result's maps when the
tiled BigTIFF writer (:func:`~napari_polarseg.io.writers.write_tiff`) reads them, one
band at a time; :func:`composite_image` draws ``aolp_dolp.png`` band by band into a
Pillow image (its RGB bytes whole, as the PNG encoder needs them, but no float copy of
it). The values are those of the whole-image functions to the bit (the same per-pixel
arithmetic; the percentiles from the same values), so the files are the same.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from .. import io as pio
from ..engine import disk_arrays
from ..engine.analysis.views import CompositeParams, auto_dolp_max, hsv_to_rgb
from ..engine.physics.stokes import stokes_components
from ..engine.tiles import row_bands as tile_bands
from ..io.tiff_tiles import TILED_PIXELS

#: Rows of a band: the images of a large result are computed this many rows at a time
#: (a 12 240-pixel-wide float64 band is 25 MB); the composite, with more temporaries a
#: pixel, a quarter of it.
BAND_ROWS = 256


def is_large(shape: tuple[int, ...]) -> bool:
    """Whether images of ``shape`` ((H, W) or (C, H, W)) are made band by band: a plane
    of at least :data:`~napari_polarseg.io.tiff_tiles.TILED_PIXELS` pixels (the images
    written as tiled BigTIFF)."""
    return int(shape[-1]) * int(shape[-2]) >= TILED_PIXELS


def row_bands(height: int, rows: int | None = None) -> Iterator[slice]:
    """The row ranges of the bands of ``rows`` rows (default :data:`BAND_ROWS`) of an
    image ``height`` rows high, top to bottom (:func:`~napari_polarseg.engine.tiles.row_bands`)."""
    return tile_bands(height, BAND_ROWS if rows is None else rows)


def banded(
    shape: tuple[int, ...], dtype: np.typing.DTypeLike, band: Callable[[slice], np.ndarray]
) -> Any:
    """A lazy Dask array of ``shape`` ((H, W) or (C, H, W)) and ``dtype`` whose blocks are
    the bands :func:`row_bands`: ``band(rows)`` gives the block of those rows ((h, W) or
    (C, h, W)), computed when the block is read."""
    import dask
    import dask.array as da

    dtype = np.dtype(dtype)
    blocks = []
    for rows in row_bands(shape[-2]):
        block_shape = (*shape[:-2], rows.stop - rows.start, shape[-1])
        task = dask.delayed(band, pure=False)(rows)  # pure: would hash the image
        blocks.append(da.from_delayed(task, shape=block_shape, dtype=dtype))
    return da.concatenate(blocks, axis=len(shape) - 2)


def as_dtype(array: np.ndarray, dtype: np.typing.DTypeLike) -> Any:
    """``np.asarray(array, dtype)`` of an (H, W) image: whole for a small one, else
    lazily band by band (:func:`banded`; no full-size copy)."""
    if not is_large(array.shape):
        return np.asarray(array, dtype)
    return banded(array.shape, dtype, lambda rows: read_band(rows, dtype, array)[0])


def read_band(
    rows: slice, dtype: np.typing.DTypeLike | None, *arrays: np.ndarray
) -> list[np.ndarray]:
    """The rows ``rows`` of each of ``arrays`` as ``dtype`` (None: their own), after which
    the pages of those in temporary files are given back at once
    (:func:`~napari_polarseg.engine.disk_arrays.release`; a band is read faster than the
    background release)."""
    bands = [np.asarray(a[rows], dtype) for a in arrays]
    disk_arrays.release(*arrays)
    return bands


def stokes_image(intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray) -> Any:
    """``stokes.tif``'s (3, H, W) float32 S0, S1, S2
    (:func:`~napari_polarseg.engine.physics.stokes.stokes_components`, input units):
    whole for a small image, else lazily band by band (:func:`banded`)."""
    if not is_large(intensity.shape):
        return np.asarray(stokes_components(intensity, dop, phase), np.float32)

    def band(rows: slice) -> np.ndarray:
        maps = read_band(rows, None, intensity, dop, phase)
        return np.asarray(stokes_components(*maps), np.float32)

    return banded((3, *intensity.shape), np.float32, band)


def finite_percentile(
    array: np.ndarray, q: float, keep: Callable[[np.ndarray], np.ndarray] | None = None
) -> float | None:
    """``np.percentile`` (linear) of the finite float64 values of ``array`` (H, W) that
    ``keep`` (a band -> bool mask; default all finite ones) keeps, or None when there is
    none: they are gathered band by band into one float64 buffer (a temporary file when
    ``array`` is in one, :mod:`~napari_polarseg.engine.disk_arrays`) and partitioned in
    place, so there is no second copy. The same value as on the whole array."""
    size = int(array.shape[0]) * int(array.shape[1])
    if disk_arrays.is_on_disk(array):
        buffer = disk_arrays.disk_empty((size,), np.float64)
    else:
        buffer = np.empty(size, np.float64)
    n = 0
    for rows in row_bands(array.shape[0]):
        values = read_band(rows, np.float64, array)[0]
        kept = values[np.isfinite(values) if keep is None else keep(values)]
        buffer[n : n + kept.size] = kept
        n += kept.size
    if n == 0:
        return None
    return float(np.percentile(buffer[:n], q, overwrite_input=True))


def _value_band(intensity: np.ndarray, top: float | None) -> np.ndarray:
    """:func:`~napari_polarseg.engine.analysis.views.intensity_value` of a band, with the
    image's percentile ``top`` (None: no positive Î in the image, all zeros)."""
    i = np.asarray(intensity, dtype=np.float64)
    if top is None:
        return np.zeros(i.shape)
    good = np.isfinite(i) & (i > 0)
    return np.where(good, np.clip(i / top, 0.0, 1.0), 0.0)


def composite_band(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    params: CompositeParams,
    top: float | None,
) -> np.ndarray:
    """The (h, W, 3) uint8 RGB of :func:`~napari_polarseg.engine.analysis.views.aolp_dolp_composite`
    on a band of rows, ``top`` the image's Î percentile (:func:`composite_image`): the same
    per-pixel arithmetic as :func:`~napari_polarseg.engine.analysis.views.hsv_planes`."""
    rho = np.asarray(dop, dtype=np.float64)
    phi = np.asarray(phase, dtype=np.float64)
    finite = np.isfinite(rho) & np.isfinite(phi) & np.isfinite(intensity)
    hue = np.where(finite, np.mod(phi, np.pi) / np.pi, 0.0)
    hue = np.where(hue >= 1.0, 0.0, hue)  # mod can round up to π itself
    dolp = np.where(finite, np.clip(rho / params.dolp_max, 0.0, 1.0), 0.0)
    if params.mode == "intensity":
        saturation, value = dolp, _value_band(intensity, top)
    elif params.mode == "light":
        saturation, value = dolp, np.ones_like(dolp)
    else:  # dark
        saturation, value = np.ones_like(dolp), dolp
    value = np.where(finite, value, 0.0)
    hsv = np.stack([hue, saturation, value], axis=-1).astype(np.float32)
    rgb = hsv_to_rgb(hsv)
    return np.round(np.clip(rgb, 0.0, 1.0) * np.float32(255.0)).astype(np.uint8)


def auto_dolp_max_banded(dop: np.ndarray, percentile: float = 99.0) -> float:
    """:func:`~napari_polarseg.engine.analysis.views.auto_dolp_max` of ρ (H, W), its
    percentile found by :func:`finite_percentile` (no full-size copy)."""
    top = finite_percentile(dop, percentile)
    return auto_dolp_max(np.array([] if top is None else [top]), percentile)


def composite_image(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, params: CompositeParams
) -> Any:
    """The AoLP/DoLP composite of an (H, W) image as a Pillow RGB image, drawn band by
    band (:func:`composite_band`); the same pixels as
    :func:`~napari_polarseg.engine.analysis.views.aolp_dolp_composite`."""
    from PIL import Image

    top = None
    if params.mode == "intensity":

        def positive(i: np.ndarray) -> np.ndarray:
            return np.isfinite(i) & (i > 0)

        top = finite_percentile(intensity, params.intensity_percentile, positive)
    height, width = intensity.shape
    picture = Image.new("RGB", (int(width), int(height)))
    for rows in row_bands(height, BAND_ROWS // 4):
        band = composite_band(*read_band(rows, None, intensity, dop, phase), params, top)
        picture.paste(Image.fromarray(band), (0, rows.start))
    return picture


def labels_image_banded(labels: np.ndarray, materials: Any = None) -> Any:
    """:func:`~napari_polarseg.outputs.contract.labels_image` of a large (H, W) labelling
    (``materials``: a scribble classifier's
    :class:`~napari_polarseg.engine.materials.Materials`, or None), lazily band by band:
    the same type (uint16, else uint32) and values."""

    def values(rows: slice) -> np.ndarray:
        band = read_band(rows, None, labels)[0]
        return band if materials is None else np.asarray(materials.label_values(band))

    top = max(int(values(rows).max(initial=0)) for rows in row_bands(labels.shape[0]))
    dtype = np.uint16 if top < 2**16 else np.uint32
    return banded(labels.shape, dtype, lambda rows: values(rows).astype(dtype))


def used_pixels_banded(valid: np.ndarray | None, shape: tuple[int, int]) -> Any:
    """:func:`~napari_polarseg.outputs.contract.used_pixels` (uint8, 1 = used) of a large
    image of ``shape`` from ``valid`` (None: every pixel used), lazily band by band."""
    if valid is None:
        return banded(
            shape, np.uint8, lambda rows: np.ones((rows.stop - rows.start, shape[1]), np.uint8)
        )
    return as_dtype(valid, np.uint8)


def write_picture(path: str | os.PathLike[str], picture: Any) -> None:
    """Write a Pillow image (:func:`composite_image`) as PNG, atomically, as
    :func:`~napari_polarseg.io.writers.write_png` writes an array (zlib level 1): the
    same file as of the array of its pixels."""
    with pio.atomic_output(path) as tmp:
        picture.save(tmp, format="PNG", compress_level=1)
