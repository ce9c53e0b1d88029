"""Label images drawn by a user: masks (:func:`read_mask`) and labels (:func:`read_labels`:
scribbles, ground truth).

Both are read the same way (:func:`read_label_image`): a ``.tif``/``.tiff``/``.png``
(e.g. a napari Labels layer saved as an image), an ``.npy``, or an ``.npz`` (a named array,
or its only one; :func:`napari_polarseg.io.arrays.read_arrays`), with the same checks and
messages: the file type, the file's presence, one 2-D image.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..engine.limits import memory_limit
from .arrays import read_arrays
from .common import PathLike, input_error
from .frames import load_frame

#: File types read as masks and labels.
MASK_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".npz")


def read_label_image(path: PathLike, what: str, names: Sequence[str]) -> tuple[np.ndarray, bool]:
    """The array of a mask or labels file, as recorded.

    Parameters
    ----------
    path : str or path
        A file of :data:`MASK_SUFFIXES`, named as given in the messages.
    what : str
        What the file is, for the messages (``"mask"``, ``"scribbles"``,
        ``"ground truth"``).
    names : sequence of str
        In an ``.npz``: the arrays looked for, in order (else its only array).

    Returns
    -------
    data : ndarray
        The image or array, its size checked against the memory limit before reading.
    colour : bool
        Whether the last axis is colour (an RGB(A) picture).

    Raises
    ------
    PolarsegError
        ``"<path>: unsupported <what> file type '.txt' (…)"``, ``"<path>: no such file"``,
        or the readers' one-line messages.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in MASK_SUFFIXES:
        kinds = ", ".join(MASK_SUFFIXES)
        raise input_error(path, f"unsupported {what} file type {suffix!r} ({kinds})")
    if not Path(path).is_file():
        raise input_error(path, "no such file")
    if suffix in (".npy", ".npz"):
        return np.asarray(read_arrays(path, names, limit=memory_limit())[0]), False
    data, colour, _ = load_frame(Path(path), memory_limit())
    return data, colour


def one_image(path: PathLike, image: np.ndarray, what: str, shape: Sequence[int]) -> np.ndarray:
    """``image`` without its leading axes of length 1, which must leave one 2-D image.

    Parameters
    ----------
    path : str or path
        The file, for the message.
    image : ndarray
        The array read (or a map of it, e.g. its non-zero pixels).
    what : str
        What the file is, for the message.
    shape : sequence of int
        The array's shape as read, for the message.

    Raises
    ------
    PolarsegError
        ``"<path>: the <what> must be one 2-D image, got an array of shape (…)"``.
    """
    while image.ndim > 2 and image.shape[0] == 1:
        image = image[0]
    if image.ndim != 2:
        raise input_error(
            path, f"the {what} must be one 2-D image, got an array of shape {tuple(shape)}"
        )
    return image


def read_mask(
    path: PathLike, shape: Sequence[int], raw_shape: Sequence[int] | None = None
) -> np.ndarray:
    """Read a user mask (a labels image): non-zero = segment here, 0 = leave out.

    Parameters
    ----------
    path : str or path
        ``.tif``/``.tiff``/``.png`` (a napari labels layer saved as an image; colour
        images count a pixel as set if any channel is non-zero), ``.npy``, or ``.npz``
        (the array ``mask`` or ``labels``, or its only array).
    shape : (H, W)
        Size of the frames the mask applies to.
    raw_shape : (2H, 2W) or (4H, 4W), optional
        Size of the raw mosaic the frames come from by super-pixel demosaicing (mono:
        2 × 2, colour-polarisation: 4 × 4 pixels per output pixel); a mask of this size
        is reduced to the frames' size (an output pixel is used only if all the raw
        pixels it comes from are set).

    Returns
    -------
    ndarray (H, W) of bool

    Raises
    ------
    PolarsegError
        If the file is missing or unreadable, not a single 2-D image, or of another size.
    """
    data, colour = read_label_image(path, "mask", ("mask", "labels"))
    if data.dtype.kind not in "biuf":
        raise input_error(path, f"the mask must hold numbers, got dtype {data.dtype}")
    with np.errstate(invalid="ignore"):
        keep = np.nan_to_num(data.astype(np.float64)) != 0 if data.dtype.kind == "f" else data != 0
    if colour:
        keep = keep.any(axis=-1)
    keep = one_image(path, keep, "mask", data.shape)
    h, w = (int(v) for v in shape)
    if keep.shape == (h, w):
        return keep
    if raw_shape is not None and keep.shape == tuple(int(v) for v in raw_shape):
        f = keep.shape[0] // h
        if f in (2, 4) and keep.shape == (f * h, f * w):
            return keep.reshape(h, f, w, f).all(axis=(1, 3))
    raise input_error(
        path,
        f"the mask is {keep.shape[0]} x {keep.shape[1]} pixels but the frames are {h} x {w}",
    )


def read_labels(path: PathLike, shape: Sequence[int], what: str) -> np.ndarray:
    """Read a labels image (scribbles, ground truth) of the outputs' size as int64.

    Parameters
    ----------
    path : str or path
        ``.tif``/``.tiff``/``.png`` (single channel, e.g. a napari Labels layer saved as
        an image), ``.npy`` or ``.npz`` (the array ``labels``, ``scribbles`` or ``mask``,
        or its only array).
    shape : (H, W)
        Size of the outputs the labels belong to.
    what : str
        What the labels are, for the messages (``"scribbles"``, ``"ground truth"``).

    Returns
    -------
    ndarray (H, W) of int64

    Raises
    ------
    PolarsegError
        Naming the file and the problem: missing, unreadable, colour, not one 2-D image,
        not integer labels, or of another size.
    """
    data, colour = read_label_image(path, what, ("labels", "scribbles", "mask"))
    if colour:
        raise input_error(path, f"the {what} must be a single-channel labels image")
    data = one_image(path, data, what, data.shape)
    if data.dtype == np.bool_:
        data = data.astype(np.uint8)
    if data.dtype.kind == "f":
        if not np.all(np.isfinite(data)) or np.any(data != np.round(data)):
            raise input_error(path, f"the {what} must hold integer labels")
    elif data.dtype.kind not in "iu":
        raise input_error(path, f"the {what} must hold integer labels, got {data.dtype}")
    h, w = (int(v) for v in shape)
    if data.shape != (h, w):
        raise input_error(
            path,
            f"the {what} image is {data.shape[0]} x {data.shape[1]} pixels but the "
            f"outputs are {h} x {w}",
        )
    return data.astype(np.int64)
