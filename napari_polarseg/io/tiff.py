"""The first series of a TIFF file, with its bit depth, angle metadata and warnings.

tifffile's log warnings are collected instead of reaching stderr; those that mean the file
is cut short or damaged (:data:`CORRUPT_HINTS`) make the read fail with one line naming
the file. The angles come from any metadata :func:`napari_polarseg.tiff_angles.tiff_angles`
understands.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from ..engine.errors import PolarsegError
from ..engine.limits import memory_limit
from ..tiff_angles import tiff_angles
from .common import check_read_size, first_line, input_error

#: tifffile log messages that mean the file is cut short or damaged.
CORRUPT_HINTS = ("invalid page offset", "truncat", "corrupt", "failed to read", "invalid ifd")


class _Collect(logging.Handler):
    """A logging handler that keeps the messages of warnings and worse."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextlib.contextmanager
def tifffile_messages() -> Iterator[list[str]]:
    """Collect tifffile's log warnings instead of letting them reach stderr: every
    opening of a user's TIFF goes through it, so a damaged file is said once, in our
    words, not as a raw library line."""
    logger = logging.getLogger("tifffile")
    handler = _Collect()
    propagate = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield handler.messages
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


#: Why a TIFF of one (grey or colour) image is not read as an angle stack.
SINGLE_IMAGE = (
    "the TIFF holds a single image, not an angle stack "
    "(for a raw polarisation-camera frame give the mosaic layout, --mosaic)"
)

#: Axes of one planar page of 3 or 4 samples, as ``tifffile.imwrite(path, stack)`` stores
#: a (3, H, W) or (4, H, W) array (planar RGB or RGBA): read as that many frames.
PLANAR_SAMPLES = "SYX"
#: The axes such a page is read with: one frame per sample.
PLANAR_AS_FRAMES = "QYX"


def frame_axes(axes: str) -> str:
    """``axes`` with a planar page's samples read as frames (:data:`PLANAR_SAMPLES`):
    ``tifffile.imwrite`` stores a 3- or 4-angle stack that way, while a colour image is
    stored with its samples last (``YXS``); every other ``axes`` unchanged."""
    return PLANAR_AS_FRAMES if axes == PLANAR_SAMPLES else axes


def _angle_metadata(tif: tifffile.TiffFile, shape: tuple[int, ...], axes: str) -> dict[str, Any]:
    """``{"angles": ..., "angles_from": ...}`` from the file's metadata, or ``{}``."""
    frames = [n for n, ax in zip(shape, axes, strict=False) if ax not in "YXS"]
    found = tiff_angles(tif, int(np.prod(frames)) if frames else 1)
    if found is None:
        return {}
    return {"angles": found[0], "angles_from": found[1]}


def _corrupt(texts: list[str]) -> bool:
    """Whether any of ``texts`` says the file is cut short or damaged."""
    return any(hint in text.lower() for text in texts for hint in CORRUPT_HINTS)


def read_tiff(path: Path, limit: int = 0) -> tuple[np.ndarray, str, dict[str, Any]]:
    """Array, axes string and metadata of the first series of a TIFF.

    Parameters
    ----------
    path : Path
        The file.
    limit : int
        Memory limit in bytes, checked against the series' size before it is read
        (0: :func:`~napari_polarseg.engine.limits.memory_limit`).

    Returns
    -------
    data : ndarray
        The series.
    axes : str
        tifffile's axes letters of ``data`` (``S`` = colour samples).
    meta : dict
        ``description``: the angle metadata (``angles``, ``angles_from``) or ``{}``;
        ``bits_per_sample`` when fewer than the dtype holds; ``warnings``: tifffile's.

    Raises
    ------
    PolarsegError
        If the file holds no image, is too large, unreadable, truncated or corrupt.
    """
    with tifffile_messages() as messages:
        try:
            with tifffile.TiffFile(path) as tif:
                if not tif.series:
                    raise input_error(path, "the TIFF file holds no image")
                series = tif.series[0]
                check_read_size(path, series.shape, series.dtype, limit or memory_limit())
                bits = None
                with contextlib.suppress(Exception):
                    bits = int(series.keyframe.bitspersample)
                data = series.asarray()
                axes = series.axes
                meta = _angle_metadata(tif, series.shape, frame_axes(axes))
        except PolarsegError:
            raise
        except Exception as exc:
            reason = first_line(exc)
            if _corrupt([reason, *messages]):
                problem = "the TIFF file is truncated or corrupt"
            else:
                problem = "cannot read the TIFF file"
            raise input_error(path, f"{problem} ({reason})") from exc
    for message in messages:
        if _corrupt([message]):
            raise input_error(path, f"the TIFF file is truncated or corrupt ({message})")
    meta = {"description": meta}
    if bits is not None and data.dtype.kind in "ui" and bits < data.dtype.itemsize * 8:
        meta["bits_per_sample"] = bits
    if messages:
        meta["warnings"] = list(messages)
    return data, axes, meta


def colour_last(data: np.ndarray, axes: str) -> tuple[np.ndarray, bool]:
    """Move a TIFF samples axis ``S`` last; report whether there is one.

    Parameters
    ----------
    data : ndarray
        A series as :func:`read_tiff` returns it.
    axes : str
        Its axes letters.

    Returns
    -------
    data : ndarray
        With the colour axis last, if any.
    colour : bool
        Whether there is a colour axis.
    """
    if "S" not in axes:
        return data, False
    return np.moveaxis(data, axes.index("S"), -1), True
