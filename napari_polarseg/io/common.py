"""Small helpers shared by the readers of :mod:`napari_polarseg.io` (no napari, no Qt).

Every problem with an input file is raised as
:class:`~napari_polarseg.engine.errors.PolarsegError` with one line that names the file:
:func:`input_error` makes that error, :func:`first_line` cuts a library's message to its
first line, :func:`check_read_size` refuses data too large for the memory limit before it
is read.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..engine.errors import PolarsegError
from ..engine.limits import check_bytes
from ..engine.physics.pixel_mask import auto_saturation_level

#: A file or folder name: a string or a path-like object.
PathLike = str | os.PathLike


def input_error(path: PathLike, problem: str) -> PolarsegError:
    """The one-line error ``"<path>: <problem>"`` about an input file.

    Parameters
    ----------
    path : str or path
        The file, named as the caller was given it.
    problem : str
        What is wrong with it.

    Returns
    -------
    PolarsegError
        To be raised by the caller.
    """
    return PolarsegError(f"{os.fspath(path)}: {problem}")


def metadata_angles(path: PathLike, values: Any, what: str = "the 'angles' metadata") -> Any:
    """The polariser angles a file's metadata (``what``) gives, as a float64 vector
    (degrees, as written), or None when it gives none; an input error when they are not
    numbers."""
    if values is None:
        return None
    try:
        return np.asarray(values, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise input_error(path, f"{what} is not a list of numbers: {values!r}") from None


def first_line(exc: BaseException) -> str:
    """The first non-blank line of an exception's message (its type's name if none)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def format_numbers(values: Sequence[float]) -> str:
    """``"0, 45, 90"``: numbers in their shortest form, for messages."""
    return ", ".join(f"{float(v):g}" for v in values)


def finite_number(value: Any, name: str) -> float:
    """``value`` as a finite float, or :class:`PolarsegError` naming ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise PolarsegError(f"{name} must be a finite number, got {value!r}")
    return number


def dims(shape: Sequence[int]) -> str:
    """``"4 x 480 x 640"``: an array shape, for messages."""
    return " x ".join(str(int(v)) for v in shape)


def saturation_level(
    saturation: float | str | None, dtype: np.dtype, bits: int | None = None
) -> float | None:
    """The level at or above which a recorded sample counts as saturated.

    Parameters
    ----------
    saturation : float, "auto" or None
        A level, ``"auto"`` (the integer dtype's maximum, or 2**bits - 1) or None (none).
    dtype : numpy dtype
        The data as recorded.
    bits : int, optional
        Bits per sample declared by the file (e.g. 12 for a 12-bit TIFF).

    Returns
    -------
    float or None
        None where no level applies (``saturation`` None, or float data with "auto").
    """
    if saturation is None:
        return None
    if isinstance(saturation, str):
        return auto_saturation_level(dtype, bits)
    return float(saturation)


def check_read_size(path: PathLike, shape: Sequence[int], dtype: Any, limit: int) -> None:
    """Refuse (before reading) data whose decoded size and float64 copy exceed the limit.

    Parameters
    ----------
    path : str or path
        The file, for the message.
    shape : sequence of int
        Shape announced by the file's header.
    dtype : numpy dtype or None
        Its dtype (None: 8 bytes a value).
    limit : int
        Memory limit in bytes.

    Raises
    ------
    PolarsegError
        ``"<path>: reading 7 x 9000 x 9000 values of float64 would need …"``.
    """
    count = float(np.prod([float(v) for v in shape])) if len(shape) else 1.0
    itemsize = np.dtype(dtype).itemsize if dtype is not None else 8
    check_bytes(
        count * (itemsize + 8),
        f"{os.fspath(path)}: reading {dims(shape)} values of {np.dtype(dtype).name}",
        limit,
    )
