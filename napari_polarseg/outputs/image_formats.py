"""The formats a result folder's images are written in: :data:`IMAGE_FORMATS`.

``tiff`` (the default): ``labels.tif`` and the other images of
:data:`~napari_polarseg.outputs.contract.IMAGE_FILES` as TIFF, a tiled BigTIFF for a
large or lazy image (:mod:`napari_polarseg.io.tiff_tiles`). ``zarr``
(``polarseg segment --format zarr``): each as an OME-Zarr directory of the same stem,
``labels.zarr``, ``intensity.zarr``, … (:mod:`napari_polarseg.io.ome_zarr`; the TIFF
metadata under the group's ``"polarseg"`` attribute). The PNG, CSV and JSON files are the
same in both.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import io as pio
from .contract import ZARR_SUFFIX, image_name


@dataclass(frozen=True)
class ImageFormat:
    """How a result folder's images are written.

    Attributes
    ----------
    suffix : str
        The images' suffix (``.tif``, ``.zarr``), in place of ``.tif``.
    write : callable
        ``write(path, array, metadata, labels=False)``: write one image (H, W) or planes
        (C, H, W), NumPy or Dask, atomically; ``labels`` for a labels image.
    """

    suffix: str
    write: Callable[..., None]

    def name(self, tiff_name: str) -> str:
        """The file name of the image called ``tiff_name`` in the TIFF format."""
        return image_name(tiff_name, self.suffix)


def _write_tiff(path: Path, array: Any, metadata: dict[str, Any], labels: bool = False) -> None:
    pio.write_tiff(path, array, metadata)


#: ``--format`` word -> how the images are written.
IMAGE_FORMATS: dict[str, ImageFormat] = {
    "tiff": ImageFormat(".tif", _write_tiff),
    "zarr": ImageFormat(ZARR_SUFFIX, pio.write_zarr),
}
