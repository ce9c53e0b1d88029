"""npe2 reader: polarisation angle stacks as one napari image layer.

Handles (the reading itself is :func:`napari_polarseg.io.read_stack`):

- a multi-page TIFF whose metadata holds the polariser angles (``"angles"`` in tifffile's
  shaped JSON metadata or in a JSON ImageDescription, as
  :func:`napari_polarseg.io.write_stack_tiff` writes it);
- an ``.npz`` with arrays ``stack`` (N, H, W) and ``angles`` (degrees);
- a folder of at least three frames whose file names carry the angle (the last number in
  the name: ``leaf_030.png`` is 30 degrees);
- a Zarr or OME-Zarr store (``NAME.zarr``, a folder) whose ``angles_deg`` attribute holds
  the angles (:mod:`napari_polarseg.io.zarr_stack`); a big TIFF or Zarr stack (over
  :data:`napari_polarseg.io.LAZY_BYTES`) becomes a lazy layer, its data a Dask array
  (:func:`read_angle_stack`);
- an OME-Zarr image of a result folder (``polarseg segment --format zarr``: ``labels.zarr``,
  ``dop.zarr``, …) as lazy multiscale layers (:mod:`napari_polarseg.zarr_layers`);
- a raw polarisation-camera frame (one 2-D grey PNG or TIFF) whose file name names a Sony
  polarisation sensor (:func:`napari_polarseg.io.sensor_from_name`): mono ``IMX250MZR``,
  ``IMX253MZR``, ``IMX264MZR`` (as in ``fruits_IMX250MZR.png``), decoded as a 2 × 2
  mosaic with the sensors' layout 90/45 over 135/0 at half resolution; colour
  ``IMX250MYR``, ``IMX253MYR``, decoded as a colour-polarisation mosaic (the same layout
  under an RGGB Bayer filter, 4 × 4 period) at a quarter of the resolution: the layer is
  the luminance stack, and ``metadata["colour_stack"]`` holds the (R, G, B) × angle
  stacks (:mod:`napari_polarseg.engine.physics.colour_mosaic`). Other single images are left to
  napari's own readers, since an ordinary photo cannot be told from a raw mosaic by its
  pixels.

The layer's ``metadata["angles_deg"]`` holds the angles in degrees, one per frame, which
the plugin's widgets read; ``metadata["reader"]`` what the reading found (format, mosaic
layout, ``bayer``, ``colours``, ``sensor``). Anything else (single images, TIFFs without
angles, ``.npz`` without ``angles``, folders of other files) gets ``None`` from
:func:`get_reader`, so napari can try its other readers. This module imports neither napari nor Qt.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .io import SENSOR_NAMES, STACK_FORMATS, angle_from_name, read_stack, single_frame_file
from .io.frames import frame_files
from .io.stack_formats import enough_angles
from .io.zarr_stack import zarr_carries_angles
from .zarr_layers import is_result_image, result_layer_data

#: Sony polarisation sensors named in raw files (mono ``…MZR``, colour ``…MYR``).
MOSAIC_SENSOR_NAMES = SENSOR_NAMES

LayerData = tuple[Any, dict[str, Any], str]

#: Axis labels of a stack layer: napari's slider of the first axis reads "angle" (the
#: plugin's docks add the polariser angle of the frame shown, ``widgets.angle_axis``);
#: rows and columns keep napari's own labels.
STACK_AXIS_LABELS = ("angle", "-2", "-1")
ReaderFunction = Callable[[str | list[str]], list[LayerData]]


def _single_path(path: str | list[str]) -> Path | None:
    if isinstance(path, (list, tuple)):
        if len(path) != 1:
            return None
        path = path[0]
    return Path(os.fspath(path))


def _folder_angles(path: Path) -> list[float] | None:
    frames = frame_files(path)
    angles = [angle_from_name(f.name) for f in frames]
    if len(frames) < 3 or any(a is None for a in angles) or not enough_angles(angles):
        return None
    return angles


def get_reader(path: str | list[str]) -> ReaderFunction | None:
    """Return :func:`read_angle_stack` if ``path`` is an angle stack this plugin reads.

    Only cheap checks are made here (the file type, then the stack format's
    ``carries_angles`` of :data:`napari_polarseg.io.STACK_FORMATS`: the names of the arrays
    in an ``.npz``, the TIFF's metadata; the names of a folder's files); the data is read
    by the returned function.

    Parameters
    ----------
    path : str or list of str
        What napari was asked to open (a list must hold exactly one path).

    Returns
    -------
    callable or None
        The reader function, or None for paths this plugin does not handle.
    """
    p = _single_path(path)
    if p is None or not p.exists():
        return None
    if p.suffix.lower() == ".zarr":
        if zarr_carries_angles(p):
            return read_angle_stack
        return read_result_image if is_result_image(p) else None
    if p.is_dir():
        return read_angle_stack if _folder_angles(p) is not None else None
    if MOSAIC_SENSOR_NAMES.search(p.stem) and single_frame_file(p):
        return read_mosaic_frame
    stack_format = STACK_FORMATS.get(p.suffix.lower())
    if stack_format is not None and stack_format.carries_angles(p):
        return read_angle_stack
    return None


def mosaic_placement(info: dict[str, Any]) -> dict[str, tuple[float, float]]:
    """Scale and translate that put a stack decoded from a raw mosaic frame on that frame.

    A super-pixel decoding makes one stack pixel of each period × period cell of the raw
    frame (period 2 for a polariser mosaic, 4 for a colour-polarisation one): the stack
    gets scale ``period`` and the translate that centres each of its pixels on its cell.
    Convention: napari's pixel centres, pixel (i, j) of a layer at scale 1 and no
    translate is centred on world (i, j) and covers i − ½ … i + ½; cell k of the raw frame
    covers raw pixels ``period·k … period·k + period − 1``, centred on ``period·k + (period
    − 1)/2``, hence translate ``(period − 1)/2`` (0.5 for a 2 × 2 super-pixel) and stack
    pixel k covers exactly raw ``period·k − ½ … period·k + period − ½``. An interpolated
    decoding (full resolution) and every other format need nothing (empty dict).
    """
    if info.get("format") != "mosaic" or info.get("demosaic") != "superpixel":
        return {}
    period = 4.0 if info.get("bayer") else 2.0
    offset = (period - 1.0) / 2.0
    return {"scale": (period, period), "translate": (offset, offset)}


def stack_layer_data(data: Any, name: str | None = None) -> LayerData:
    """napari layer data tuple of a :class:`napari_polarseg.io.StackData`; a stack decoded
    by super-pixel from a raw mosaic frame overlays that frame (:func:`mosaic_placement`,
    the angle axis keeps scale 1)."""
    angles = [float(a) for a in np.asarray(data.angles_deg, dtype=float).ravel()]
    source = str(data.source)
    info = {k: v for k, v in data.metadata.items() if k != "warnings"}
    metadata = {"angles_deg": angles, "source": source, "reader": _plain(info)}
    if data.colour_stack is not None:
        metadata["colour_stack"] = data.colour_stack
    layer_name = name or Path(source).stem or Path(source).name
    kwargs: dict[str, Any] = {
        "name": layer_name,
        "metadata": metadata,
        "colormap": "gray",
        "axis_labels": STACK_AXIS_LABELS,
    }
    placement = mosaic_placement(info)
    if placement:
        kwargs["scale"] = (1.0, *placement["scale"])
        kwargs["translate"] = (0.0, *placement["translate"])
    return (data.stack, kwargs, "image")


def read_angle_stack(path: str | list[str], lazy: str = "auto") -> list[LayerData]:
    """Read an angle stack into one image layer with ``metadata["angles_deg"]``.

    A multi-page TIFF or a Zarr store whose stack decodes to more than
    :data:`napari_polarseg.io.LAZY_BYTES` (``lazy="auto"``, what napari calls), or any
    with ``lazy="always"``, is read lazily: the layer's data is the Dask array of
    :func:`napari_polarseg.io.read_stack`, which napari draws tile by tile without
    loading the file (the Segment dock reads it whole for a run, within the memory
    limit).

    Raises :class:`napari_polarseg.engine.PolarsegError` with a one-line message naming
    the file for input that cannot be used (napari shows it as an error notification).
    """
    p = _single_path(path)
    if p is None:
        raise ValueError("napari-polarseg reads one angle stack (file or folder) at a time")
    return [stack_layer_data(read_stack(p, lazy=lazy))]


def read_result_image(path: str | list[str]) -> list[LayerData]:
    """Read an OME-Zarr image of a result folder (``polarseg segment --format zarr``) as
    lazy multiscale layers (:func:`napari_polarseg.zarr_layers.result_layer_data`)."""
    p = _single_path(path)
    if p is None:
        raise ValueError("napari-polarseg reads one result image at a time")
    return result_layer_data(p)


def read_mosaic_frame(path: str | list[str]) -> list[LayerData]:
    """Read a raw polarisation-camera frame (sensor named in the file name) as one
    4-angle image layer, with the sensor's defaults (super-pixel demosaicing, layout
    90/45 over 135/0; RGGB colour filter for the colour sensors, whose layer is the
    luminance stack with the colour stacks in ``metadata["colour_stack"]``)."""
    p = _single_path(path)
    if p is None:
        raise ValueError("napari-polarseg reads one raw frame at a time")
    data = read_stack(p)
    if data.metadata.get("format") != "mosaic":
        raise ValueError(f"{p}: not a single raw polarisation-camera frame")
    return [stack_layer_data(data)]


def _plain(obj: Any) -> Any:
    """Metadata as plain Python types (numpy scalars/arrays become numbers/lists)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
