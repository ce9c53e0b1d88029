"""Reading angle stacks and writing results (no napari, no Qt).

Angles are **degrees** in files and on the command line (the engine takes radians:
:attr:`StackData.angles_rad`). Every problem with an input file is raised as
:class:`~napari_polarseg.engine.PolarsegError` with one line that names the file.

The package's modules:

- :mod:`~napari_polarseg.io.readers`: :func:`read_stack` (the formats it reads, the
  file-name rule, bit depth, saturation, black level and the checks are its module's
  docstring); :mod:`~napari_polarseg.io.read_options`, :class:`ReadOptions` (how an input
  is read, each option described once, the command line's reading flags made from it);
  :mod:`~napari_polarseg.io.stack_formats`, one reader per kind of stack and
  :data:`STACK_FORMATS`, the suffix -> reader table (also the napari reader's);
  :mod:`~napari_polarseg.io.stack_data`, :class:`StackData`;
- :mod:`~napari_polarseg.io.frames`: single image files (:func:`read_frame`,
  :func:`to_grey`, :func:`natural_key`); :mod:`~napari_polarseg.io.tiff`, the first series
  of a TIFF; :mod:`~napari_polarseg.io.arrays`, arrays out of ``.npy``/``.npz`` files
  (:func:`read_arrays`);
- :mod:`~napari_polarseg.io.masks`: :func:`read_mask` and :func:`read_labels`;
- :mod:`~napari_polarseg.io.angles`: :func:`parse_angles`, :func:`angle_from_name`,
  :func:`sensor_from_name`;
- :mod:`~napari_polarseg.io.params_files`: :func:`read_params_dict`,
  :func:`read_params_file`;
- :mod:`~napari_polarseg.io.lazy_stack`: stacks left on disk and read block by block
  (:data:`LAZY_BYTES`, :func:`is_lazy`, :func:`in_memory`); the lazy TIFF reader
  :mod:`~napari_polarseg.io.lazy_tiff` and the Zarr / OME-Zarr reader
  :mod:`~napari_polarseg.io.zarr_stack` (the angles in the attribute :data:`ANGLES_ATTR`);
- :mod:`~napari_polarseg.io.writers`: :func:`atomic_output`, :func:`atomic_folder` and the
  atomic writers :func:`write_tiff` (a tiled BigTIFF when large:
  :mod:`~napari_polarseg.io.tiff_tiles`), :func:`write_zarr` (OME-Zarr:
  :mod:`~napari_polarseg.io.ome_zarr`), :func:`write_stack_tiff`, :func:`write_json`,
  :func:`write_png`;
- :mod:`~napari_polarseg.io.common`: the one-line errors and size checks they share.

Every name below is importable from ``napari_polarseg.io`` itself
(``from napari_polarseg import io as pio; pio.read_stack(...)``).
"""

from .angles import (
    DEFAULT_MOSAIC,
    SENSOR_NAMES,
    SensorDefaults,
    angle_from_name,
    parse_angles,
    sensor_from_name,
)
from .arrays import read_arrays
from .common import PathLike
from .frames import (
    FRAME_SUFFIXES,
    LUMA_BT601,
    natural_key,
    read_frame,
    single_frame_file,
    to_grey,
)
from .lazy_stack import LAZY_BYTES, in_memory, is_lazy
from .masks import MASK_SUFFIXES, read_labels, read_mask
from .params_files import read_params_dict, read_params_file
from .read_options import ReadOptions, ReadSpec, options_from_values, read_specs
from .readers import STACK_SUFFIXES, read_stack
from .stack_data import StackData
from .stack_formats import STACK_FORMATS, StackFormat
from .writers import (
    atomic_folder,
    atomic_output,
    write_json,
    write_png,
    write_stack_tiff,
    write_tiff,
    write_zarr,
)
from .zarr_stack import ANGLES_ATTR

__all__ = [
    "ANGLES_ATTR",
    "DEFAULT_MOSAIC",
    "FRAME_SUFFIXES",
    "LAZY_BYTES",
    "LUMA_BT601",
    "MASK_SUFFIXES",
    "SENSOR_NAMES",
    "STACK_FORMATS",
    "STACK_SUFFIXES",
    "PathLike",
    "ReadOptions",
    "ReadSpec",
    "SensorDefaults",
    "StackData",
    "StackFormat",
    "angle_from_name",
    "atomic_folder",
    "atomic_output",
    "in_memory",
    "is_lazy",
    "natural_key",
    "options_from_values",
    "parse_angles",
    "read_arrays",
    "read_frame",
    "read_labels",
    "read_mask",
    "read_params_dict",
    "read_params_file",
    "read_specs",
    "read_stack",
    "sensor_from_name",
    "single_frame_file",
    "to_grey",
    "write_json",
    "write_png",
    "write_stack_tiff",
    "write_tiff",
    "write_zarr",
]
