"""NumPy files: the array of an ``.npy``, or the arrays picked out of an ``.npz``.

:func:`read_arrays` is the one way the package takes arrays out of a NumPy file (the
angle stack of an ``.npz``, a mask, scribbles or ground truth, a dark frame): read with
``allow_pickle=False``, the picked array's size checked against the memory limit from its
header before it is read, and every problem raised as one line naming the file.
"""

from __future__ import annotations

import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..engine.errors import PolarsegError
from .common import PathLike, check_read_size, first_line, input_error


def _npy_header(handle: Any) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype from the header of an open ``.npy`` stream."""
    version = np.lib.format.read_magic(handle)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
    else:
        shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
    return tuple(shape), dtype


def array_header(path: Path, name: str) -> tuple[tuple[int, ...], np.dtype] | None:
    """Shape and dtype of an array from its header, without reading it (never raises).

    Parameters
    ----------
    path : Path
        An ``.npy`` file (its array), or an ``.npz`` archive.
    name : str
        In an ``.npz``: the array's name (member ``<name>.npy``).

    Returns
    -------
    tuple or None
        ``(shape, dtype)``, or None if the header cannot be read.
    """
    try:
        if path.suffix.lower() == ".npy":
            with open(path, "rb") as handle:
                return _npy_header(handle)
        with zipfile.ZipFile(path) as archive, archive.open(f"{name}.npy") as handle:
            return _npy_header(handle)
    except Exception:
        return None  # np.load reports the problem


def _pick(names: Sequence[str], found: Sequence[str], only: bool) -> str | None:
    """The first of ``names`` in ``found``, else (if ``only``) its only name, else None."""
    picked = [n for n in names if n in found]
    if not picked and only and len(found) == 1:
        picked = list(found)
    return picked[0] if picked else None


def _either(names: Sequence[str]) -> str:
    """``"'a'"``, ``"'a' or 'b'"``, ``"'a', 'b' or 'c'"``: names for a message."""
    quoted = [repr(n) for n in names]
    return " or ".join([", ".join(quoted[:-1]), quoted[-1]] if len(quoted) > 1 else quoted)


def _check_size(path: PathLike, name: str, limit: int | None) -> None:
    """Refuse an array whose header announces more than the memory limit allows."""
    if limit is None:
        return
    header = array_header(Path(path), name)
    if header is not None:
        check_read_size(path, header[0], header[1], limit)


def read_arrays(
    path: PathLike,
    names: Sequence[str],
    *,
    optional: Sequence[str] = (),
    only: bool = True,
    limit: int | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The array of an ``.npy``, or the one picked out of an ``.npz``, read without pickles.

    Parameters
    ----------
    path : str or path
        The file (named as given in the messages); whether it holds one array or an
        archive of them is found from its content.
    names : sequence of str
        In an ``.npz``: the names of the wanted array, in order of preference.
    optional : sequence of str
        In an ``.npz``: other arrays returned too when present (e.g. a stack's angles).
    only : bool
        In an ``.npz`` with none of ``names``: take its only array, if it has just one.
    limit : int, optional
        Memory limit in bytes, checked against the picked array's header before it is
        read (None: not checked).

    Returns
    -------
    array : ndarray
        The array of the ``.npy``, or the picked array of the ``.npz``.
    others : dict
        The arrays of ``optional`` the ``.npz`` holds, by name (empty for an ``.npy``).

    Raises
    ------
    PolarsegError
        ``"<path>: no array named 'a' or 'b' in the .npz file (found: x, y)"``;
        ``"<path>: cannot read the NumPy file (<reason>)"`` for a damaged file, pickled
        data or object arrays; the memory limit's message for an array too large.

    Examples
    --------
    >>> mask, _ = read_arrays("mask.npz", ("mask", "labels"))          # doctest: +SKIP
    >>> stack, more = read_arrays("scene.npz", ("stack",), optional=("angles",),
    ...                           only=False)                           # doctest: +SKIP
    """
    try:
        # our own handle: np.load leaks the one it opens when a damaged .npz is refused
        with open(path, "rb") as handle:
            if Path(path).suffix.lower() == ".npy":
                _check_size(path, "", limit)
            loaded = np.load(handle, allow_pickle=False)
            if isinstance(loaded, np.ndarray):
                return loaded, {}
            with loaded:
                name = _pick(names, loaded.files, only)
                if name is None:
                    wanted = _either(names)
                    found = ", ".join(loaded.files) or "none"
                    raise input_error(
                        path, f"no array named {wanted} in the .npz file (found: {found})"
                    )
                _check_size(path, name, limit)
                others = {n: loaded[n] for n in optional if n in loaded.files}
                return loaded[name], others
    except PolarsegError:
        raise
    except Exception as exc:
        raise input_error(path, f"cannot read the NumPy file ({first_line(exc)})") from exc
