"""Single image files (frames): reading one, making it grey, listing a folder of them.

A frame is a ``.png``, ``.jpg``/``.jpeg`` or single-page ``.tif``/``.tiff``
(:data:`FRAME_SUFFIXES`). Colour frames (H, W, 3 or 4) become grey by the ITU-R BT.601
luma weights 0.299 R + 0.587 G + 0.114 B (alpha ignored) unless ``channel`` picks one
channel (:func:`to_grey`). Before a picture is decoded, the size its header announces is
checked against the memory limit.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from ..engine.errors import PolarsegError
from ..engine.limits import memory_limit
from .common import PathLike, check_read_size, first_line, input_error
from .tiff import colour_last, frame_axes, read_tiff, tifffile_messages

#: File types read as single frames (in a folder, or as a raw mosaic).
FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
#: ITU-R BT.601 luma weights of R, G, B.
LUMA_BT601 = np.array([0.299, 0.587, 0.114])


def single_frame_file(path: Path) -> bool:
    """Whether ``path`` is one image file holding a single 2-D frame (never raises)."""
    suffix = path.suffix.lower()
    if not path.is_file() or suffix not in FRAME_SUFFIXES:
        return False
    if suffix not in (".tif", ".tiff"):
        return True
    try:
        with tifffile_messages(), tifffile.TiffFile(path) as tif:
            axes = tif.series[0].axes if tif.series else ""
            return len(tif.pages) == 1 and frame_axes(axes) == axes
    except Exception:
        return False


def natural_key(name: str) -> list[Any]:
    """Sort key of a file name with its digit runs as numbers (``f2`` before ``f10``)."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def frame_files(folder: Path) -> list[Path]:
    """The files of a folder with an image frame's suffix (hidden files skipped), in the
    folder's own order."""
    return [
        f
        for f in folder.iterdir()
        if f.is_file() and not f.name.startswith(".") and f.suffix.lower() in FRAME_SUFFIXES
    ]


def folder_frames(folder: Path) -> list[Path]:
    """The image frames of a folder (:func:`frame_files`), in natural name order.

    Raises
    ------
    PolarsegError
        If the folder holds no frame.
    """
    files = frame_files(folder)
    if not files:
        raise input_error(folder, f"no image frames ({', '.join(FRAME_SUFFIXES)}) in the folder")
    return sorted(files, key=lambda f: natural_key(f.name))


def to_grey(image: np.ndarray, channel: int | None = None) -> np.ndarray:
    """Grey image from an image with a trailing colour axis.

    Parameters
    ----------
    image : array (..., C)
        C = 2 (grey + alpha), 3 (RGB) or 4 (RGBA).
    channel : int, optional
        Take this channel as it is instead of the luma.

    Returns
    -------
    ndarray (...)
        ``0.299 R + 0.587 G + 0.114 B`` (ITU-R BT.601, float64) for RGB/RGBA, the grey
        channel for grey + alpha, or the chosen channel in its own dtype.

    Raises
    ------
    PolarsegError
        If ``channel`` is out of range or C is not 2, 3 or 4.
    """
    image = np.asarray(image)
    n_channels = image.shape[-1]
    if channel is not None:
        if not 0 <= channel < n_channels:
            raise PolarsegError(
                f"channel {channel} does not exist in an image with {n_channels} channels"
            )
        return image[..., channel]
    if n_channels == 2:
        return image[..., 0]
    if n_channels in (3, 4):
        return image[..., :3].astype(np.float64) @ LUMA_BT601
    raise PolarsegError(f"cannot make a grey image from {n_channels} colour channels")


def _picture_header(path: Path) -> tuple[tuple[int, ...], np.dtype] | None:
    """Shape and dtype a PNG/JPEG decodes to, from its header (None if unknown)."""
    try:
        from PIL import Image

        cap = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = None  # only the header is read; the size is checked below
        try:
            with Image.open(path) as image:
                width, height = image.size
                bands = len(image.getbands())
                mode = image.mode
        finally:
            Image.MAX_IMAGE_PIXELS = cap
    except Exception:
        return None
    itemsize = {"I;16": 2, "I;16B": 2, "I;16L": 2, "I": 4, "F": 4}.get(mode, 1)
    shape = (height, width) if bands == 1 else (height, width, bands)
    return shape, np.dtype(f"u{itemsize}") if itemsize < 4 else np.dtype(np.float32)


def _read_picture(path: Path, limit: int = 0) -> np.ndarray:
    """A PNG/JPEG (or any picture scikit-image reads), its size checked first."""
    from skimage import io as skio

    header = _picture_header(path)
    if header is not None:
        check_read_size(path, header[0], header[1], limit or memory_limit())
    try:
        return np.asarray(skio.imread(path))
    except Exception as exc:
        reason = first_line(exc)
        if "could not find a backend" in reason.lower():  # imageio's text repeats the path
            kind = path.suffix.lstrip(".").upper() or "image"
            reason = f"its content is not a {kind} image that any reader recognises"
        raise input_error(path, f"cannot read the image ({reason})") from exc


def load_frame(path: Path, limit: int) -> tuple[np.ndarray, bool, int | None]:
    """One image file as it is recorded.

    Parameters
    ----------
    path : Path
        A file of :data:`FRAME_SUFFIXES`.
    limit : int
        Memory limit in bytes (0: the default limit).

    Returns
    -------
    data : ndarray
        (H, W), or (H, W, C) with a colour axis.
    colour : bool
        Whether the last axis is colour.
    bits : int or None
        A TIFF's bits per sample, when fewer than its dtype holds.

    Raises
    ------
    PolarsegError
        If the file is missing, not an image file type, unreadable, too large, or a TIFF
        of several frames.
    """
    if not path.is_file():
        raise input_error(path, "no such file")
    suffix = path.suffix.lower()
    if suffix not in FRAME_SUFFIXES:
        raise input_error(path, f"not an image file type ({', '.join(FRAME_SUFFIXES)})")
    if suffix not in (".tif", ".tiff"):
        data = _read_picture(path, limit)
        return data, data.ndim == 3 and data.shape[-1] in (2, 3, 4), None
    data, axes, meta = read_tiff(path, limit)
    data, colour = colour_last(data, axes)
    extra = data.ndim - (3 if colour else 2)
    if extra > 0 and int(np.prod(data.shape[:extra])) == 1:
        data = data.reshape(data.shape[extra:])
    elif extra > 0:
        raise input_error(
            path,
            f"the TIFF holds {int(np.prod(data.shape[:extra]))} frames; a single image "
            "was expected",
        )
    return data, colour, meta.get("bits_per_sample")


def read_frame(path: PathLike, channel: int | None = None) -> np.ndarray:
    """Read one image file as a single grey frame (H, W).

    Parameters
    ----------
    path : str or path
        A ``.png``, ``.jpg``/``.jpeg`` or single-page ``.tif``/``.tiff`` file.
    channel : int, optional
        Colour channel to take from a colour image (default: BT.601 luma).

    Returns
    -------
    ndarray (H, W)
        The frame, in the file's dtype for grey images, float64 for luma.

    Raises
    ------
    PolarsegError
        If the file is missing, unreadable, not an image, holds several frames, or
        ``channel`` is given for a grey image or is out of range.
    """
    path = Path(path)
    data, colour, _ = load_frame(path, memory_limit())
    return grey_frames(path, data, colour, channel, frames=False)[0]


def _saturated(data: np.ndarray, colour: bool, channel: int | None, level: float) -> np.ndarray:
    """Samples at or above ``level`` as recorded (colour: the chosen channel, or any of
    R, G, B)."""
    with np.errstate(invalid="ignore"):
        hits = data >= level
    if colour:
        n_channels = data.shape[-1]
        if channel is not None and 0 <= channel < n_channels:
            hits = hits[..., channel]
        else:
            hits = hits[..., : 3 if n_channels >= 3 else 1].any(axis=-1)
    return hits


def grey_frames(
    path: Path,
    data: np.ndarray,
    colour: bool,
    channel: int | None,
    frames: bool,
    level: float | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Colour conversion and dimension check: (H, W), or (N, H, W) if ``frames``.

    Parameters
    ----------
    path : Path
        The file, for messages.
    data : ndarray
        As recorded, with a trailing colour axis if ``colour``.
    colour : bool
        Whether the last axis is colour.
    channel : int, optional
        Colour channel to take (default: BT.601 luma).
    frames : bool
        A stack of frames is expected, not a single image.
    level : float, optional
        Saturation level.

    Returns
    -------
    grey : ndarray
        The grey data.
    saturated : ndarray of bool or None
        If ``level`` is given, the samples at or above it in the data as recorded (for
        colour: in the chosen channel, or in any of R, G, B).
    """
    want = 3 if frames else 2
    shape = data.shape[:-1] if colour else data.shape
    if len(shape) != want:
        what = "a stack of frames (frames, rows, columns)" if frames else "a single 2-D image"
        raise input_error(path, f"expected {what}, got an array of shape {data.shape}")
    if data.dtype == np.bool_:
        data = data.astype(np.uint8)
    if not np.issubdtype(data.dtype, np.number) or np.iscomplexobj(data):
        raise input_error(path, f"image data must be real numbers, got dtype {data.dtype}")
    saturated = None if level is None else _saturated(data, colour, channel, level)
    if colour:
        try:
            data = to_grey(data, channel)
        except PolarsegError as exc:
            raise input_error(path, str(exc)) from None
    elif channel is not None:
        raise input_error(path, f"channel {channel} was chosen but the image is grey")
    return data, saturated
