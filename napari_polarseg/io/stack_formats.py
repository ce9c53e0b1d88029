"""One reader per kind of angle stack: a multi-page TIFF, an ``.npz``/``.npy``, frame files
(a folder or a list), a raw mono or colour-polarisation mosaic; :data:`STACK_FORMATS`, the
suffix -> reader table of the stack files (the lazy TIFF and the Zarr readers are their
own modules, :mod:`~napari_polarseg.io.lazy_tiff` and :mod:`~napari_polarseg.io.zarr_stack`).

Each returns a :class:`~napari_polarseg.io.stack_data.StackData` whose angles may still be
missing; :func:`napari_polarseg.io.readers.read_stack` picks the reader and checks the
result.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from ..engine.errors import PolarsegError
from ..engine.limits import check_bytes
from ..engine.physics.colour_mosaic import (
    COLOURS,
    demosaic_colour,
    demosaic_colour_flags,
    luminance,
)
from ..engine.physics.mosaic import demosaic, demosaic_flags
from ..tiff_angles import FROM_JSON
from .angles import angle_from_name, enough_angles
from .arrays import read_arrays
from .common import dims, first_line, input_error, metadata_angles, saturation_level
from .frames import grey_frames, load_frame
from .lazy_stack import LazyReader
from .lazy_tiff import LAZY_TIFF
from .mosaic_checks import check_mosaic_channels, periodicity_warning
from .read_options import ReadOptions
from .stack_data import BlackLevel, StackData
from .tiff import SINGLE_IMAGE, colour_last, frame_axes, read_tiff, tifffile_messages
from .zarr_stack import LAZY_ZARR, read_zarr_stack, zarr_carries_angles


def read_tiff_stack(path: Path, opts: ReadOptions, black: BlackLevel) -> StackData:
    """A multi-page TIFF, its angles from its metadata (if any)."""
    data, axes, meta = read_tiff(path, opts.max_bytes())
    data, colour = colour_last(data, frame_axes(axes))
    if data.ndim == (3 if colour else 2):
        raise input_error(path, SINGLE_IMAGE)
    bits = meta.get("bits_per_sample")
    level = saturation_level(opts.saturation, data.dtype, bits)
    stack, saturated = grey_frames(path, data, colour, opts.channel, True, level)
    stack = black.subtract(path, stack)
    info = {"format": "tiff", **{k: v for k, v in meta.items() if k != "description"}}
    info["saturation_level"] = level
    angles = metadata_angles(path, meta["description"].get("angles"))
    if meta["description"].get("angles_from") not in (None, FROM_JSON):
        info["angles_from"] = meta["description"]["angles_from"]
    return StackData(stack, angles, os.fspath(path), info, saturated=saturated)


def read_array_stack(path: Path, opts: ReadOptions, black: BlackLevel) -> StackData:
    """An ``.npy`` stack, or an ``.npz`` with ``stack`` and optionally ``angles``,
    ``labels`` (ground truth) and ``params`` (a JSON string)."""
    info: dict[str, Any] = {"format": path.suffix.lower().lstrip(".")}
    data, more = read_arrays(
        path,
        ("stack",),
        optional=("angles", "labels", "params"),
        only=False,
        limit=opts.max_bytes(),
    )
    angles, ground_truth = more.get("angles"), more.get("labels")
    if "params" in more:
        try:
            info["params"] = json.loads(str(more["params"]))
        except ValueError as exc:
            raise input_error(path, f"cannot read the NumPy file ({first_line(exc)})") from exc
    colour = data.ndim == 4 and data.shape[-1] in (2, 3, 4)
    level = saturation_level(opts.saturation, data.dtype)
    stack, saturated = grey_frames(path, data, colour, opts.channel, True, level)
    stack = black.subtract(path, stack)
    info["saturation_level"] = level
    if angles is not None:
        if angles.dtype.kind not in "uif":
            raise input_error(
                path, f"the 'angles' array must hold numbers, got dtype {angles.dtype}"
            )
        angles = metadata_angles(path, angles.tolist())
    if ground_truth is not None and ground_truth.shape != stack.shape[1:]:
        raise input_error(
            path,
            f"ground-truth labels are {ground_truth.shape} but the frames are {stack.shape[1:]}",
        )
    return StackData(stack, angles, os.fspath(path), info, ground_truth, saturated)


def _sorted_by_angle(files: list[Path]) -> tuple[list[Path], np.ndarray]:
    """Frame files sorted by the angle in their names, and those angles."""
    named = [angle_from_name(f) for f in files]
    for f, a in zip(files, named, strict=True):
        if a is None:
            raise input_error(
                f,
                "no angle in the file name (the last number in the name is the angle in "
                "degrees, e.g. leaf_030.png); or give the angles",
            )
    order = np.argsort(named, kind="stable")
    return [files[i] for i in order], np.asarray(named, dtype=np.float64)[order]


def read_frame_files(
    source: Path,
    files: list[Path],
    angles_given: bool,
    opts: ReadOptions,
    black: BlackLevel,
    kind: str,
) -> StackData:
    """One frame a file (``kind`` ``"folder"`` or ``"files"``); without given angles, the
    angles come from the file names and the frames are sorted by them."""
    angles = None
    if not angles_given:
        files, angles = _sorted_by_angle(files)
    frames, flags, levels = [], [], []
    for f in files:
        data, colour, bits = load_frame(f, opts.max_bytes())
        level = saturation_level(opts.saturation, data.dtype, bits)
        frame, saturated = grey_frames(f, data, colour, opts.channel, False, level)
        if frames and frame.shape != frames[0].shape:
            raise input_error(
                f,
                f"frame is {frame.shape[0]} x {frame.shape[1]} pixels but {files[0].name} is "
                f"{frames[0].shape[0]} x {frames[0].shape[1]}; all frames must have one size",
            )
        if not frames:  # the whole stack and its float64 copy, before reading the rest
            check_bytes(
                len(files) * frame.size * 16.0,
                f"{os.fspath(source)}: reading {len(files)} frames of {dims(frame.shape)} pixels",
                opts.max_bytes(),
            )
        frames.append(frame)
        flags.append(saturated)
        levels.append(level)
    saturated = np.stack(flags) if all(s is not None for s in flags) else None
    stack = black.subtract(source, np.stack(frames))
    info = {"format": kind, "files": [f.name if kind == "folder" else os.fspath(f) for f in files]}
    known = [lv for lv in levels if lv is not None]
    info["saturation_level"] = min(known) if known else None
    return StackData(stack, angles, os.fspath(source), info, saturated=saturated)


def _decode_mosaic(
    path: Path,
    raw: np.ndarray,
    saturated_raw: np.ndarray | None,
    layout: Sequence[float],
    method: str,
    bayer: str | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(stack, angles, saturated, colour stack) of a raw frame, mono or colour."""
    try:
        if bayer is None:
            stack, angles = demosaic(raw, layout, method)
            saturated = (
                None if saturated_raw is None else demosaic_flags(saturated_raw, layout, method)
            )
            return stack, angles, saturated, None
        colour_stack, angles = demosaic_colour(raw, layout, bayer, method)
        saturated = None
        if saturated_raw is not None:
            flags = demosaic_colour_flags(saturated_raw, layout, bayer, method)
            saturated = flags.any(axis=0)
        return luminance(colour_stack), angles, saturated, colour_stack
    except PolarsegError as exc:
        raise input_error(path, str(exc)) from None


def read_mosaic(path: Path, opts: ReadOptions, black: BlackLevel) -> StackData:
    """A raw mono (``opts.bayer`` None) or colour-polarisation frame, decoded with the
    layout ``opts.mosaic_deg`` by ``opts.demosaic``."""
    layout, method, bayer = opts.mosaic_deg, opts.demosaic, opts.bayer
    assert layout is not None
    if path.is_dir():
        raise input_error(path, "a mosaic layout needs a single raw frame, not a folder")
    data, colour, bits = load_frame(path, opts.max_bytes())
    data = check_mosaic_channels(path, data, colour)
    colour = colour and data.ndim == 3
    level = saturation_level(opts.saturation, data.dtype, bits)
    raw, saturated_raw = grey_frames(path, data, colour, opts.channel, False, level)
    if method == "interpolated":
        planes = 10 if bayer is None else 20  # 12 colour planes, luminance, work space
        check_bytes(
            raw.size * 8.0 * planes,
            f"{os.fspath(path)}: interpolating a {dims(raw.shape)} mosaic",
            opts.max_bytes(),
        )
    raw = black.subtract(path, raw)
    warning = periodicity_warning(path, raw)
    stack, angles, saturated, colour_stack = _decode_mosaic(
        path, raw, saturated_raw, layout, method, bayer
    )
    info: dict[str, Any] = {
        "format": "mosaic",
        "demosaic": method,
        "mosaic_layout_deg": [float(a) for a in np.asarray(layout, dtype=float).ravel()],
        "raw_shape": list(raw.shape),
        "saturation_level": level,
    }
    if bayer is not None:
        info["bayer"] = bayer
        info["colours"] = list(COLOURS)
    if bits is not None:
        info["bits_per_sample"] = bits
    if warning is not None:
        info["mosaic_warning"] = warning
    return StackData(
        stack, angles, os.fspath(path), info, saturated=saturated, colour_stack=colour_stack
    )


def _tiff_json_angles(path: Path) -> Any:
    """The ``angles`` entry of a TIFF's JSON metadata (tifffile's shaped metadata, else
    the first page's JSON description), or None (never raises)."""
    try:
        with tifffile_messages(), tifffile.TiffFile(path) as tif:
            if len(tif.pages) < 1:
                return None
            shaped = tif.shaped_metadata
            if shaped:
                return dict(shaped[0]).get("angles")
            description = tif.pages[0].description or ""
            if description.lstrip().startswith("{"):
                meta = json.loads(description)
                return meta.get("angles") if isinstance(meta, dict) else None
    except Exception:
        return None
    return None


def _tiff_carries_angles(path: Path) -> bool:
    return enough_angles(_tiff_json_angles(path))


def _npz_carries_angles(path: Path) -> bool:
    try:
        with np.load(path, allow_pickle=False) as data:
            return "stack" in data.files and "angles" in data.files
    except Exception:
        return False


def _never(path: Path) -> bool:
    return False


@dataclass(frozen=True)
class StackFormat:
    """A kind of file that holds a whole angle stack.

    Attributes
    ----------
    read : callable
        ``read(path, options, black_level) -> StackData`` (angles may still be missing).
    carries_angles : callable
        ``carries_angles(path) -> bool``, a cheap look at the file (its header, the names
        of its arrays): whether it names its own polariser angles, so that it can be
        opened without being told them (the napari reader claims only those files).
    lazy : LazyReader or None
        How the format is read block by block (:mod:`napari_polarseg.io.lazy_stack`),
        when it can be; :func:`~napari_polarseg.io.read_stack` does when it is large or
        asked to.
    """

    read: Callable[[Path, ReadOptions, BlackLevel], StackData]
    carries_angles: Callable[[Path], bool]
    lazy: LazyReader | None = None


_TIFF = StackFormat(read_tiff_stack, _tiff_carries_angles, LAZY_TIFF)
_NPZ = StackFormat(read_array_stack, _npz_carries_angles)

#: File suffix (lower case) -> the format of a file that holds a whole stack; the one
#: table :func:`~napari_polarseg.io.read_stack` and the napari reader pick a reader by.
#: Single image files (:data:`~napari_polarseg.io.frames.FRAME_SUFFIXES`) are frames of
#: a folder or a list, or raw mosaic frames.
STACK_FORMATS: dict[str, StackFormat] = {
    ".tif": _TIFF,
    ".tiff": _TIFF,
    ".npz": _NPZ,
    ".npy": StackFormat(read_array_stack, _never),
    ".zarr": StackFormat(read_zarr_stack, zarr_carries_angles, LAZY_ZARR),
}
