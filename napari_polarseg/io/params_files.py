"""Segmentation parameters from a JSON file (``polarseg segment --params``, the plugin's
*Load parameters…*, the batch widget)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..engine.errors import PolarsegError
from ..engine.params import SegmentParams
from .common import PathLike


def read_params_dict(path: PathLike) -> dict[str, Any]:
    """The fields of a parameters JSON file, as ``polarseg segment --params`` reads it.

    Either a SegmentParams object (``SegmentParams.to_json``, what the plugin's *Save
    parameters…* writes) or a ``params.json`` written by ``polarseg`` (its ``"params"``
    entry). Invalid JSON, anything but a JSON object or an unreadable file raise
    :class:`PolarsegError` naming the file; the fields are not checked here.

    Parameters
    ----------
    path : str or path
        The JSON file.

    Returns
    -------
    dict
        Field name → value, as in the file.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise PolarsegError(f"{path}: cannot read the parameters file ({reason})") from None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise PolarsegError(f"{path}: parameters file is not valid JSON ({exc})") from None
    if isinstance(data, dict) and isinstance(data.get("params"), dict):
        data = data["params"]  # a params.json written by polarseg
    if not isinstance(data, dict):
        raise PolarsegError(f"{path}: parameters file must hold a JSON object")
    return data


def read_params_file(path: PathLike) -> SegmentParams:
    """SegmentParams from a parameters JSON file (:func:`read_params_dict`).

    Missing fields take the thesis defaults; an unknown field or a value out of range
    raise :class:`PolarsegError` naming the file.

    Parameters
    ----------
    path : str or path
        A SegmentParams object or a ``params.json`` written by ``polarseg``.

    Returns
    -------
    SegmentParams
        The parameters, checked (:meth:`SegmentParams.from_dict`).
    """
    data = read_params_dict(path)
    try:
        return SegmentParams.from_dict(data)
    except PolarsegError as exc:
        raise PolarsegError(f"{path}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise PolarsegError(f"{path}: a parameter has the wrong type ({exc})") from None
