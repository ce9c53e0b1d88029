"""npe2 writer: a labels layer (e.g. ``segments``) as an integer TIFF, written atomically.

The file is written through :func:`napari_polarseg.io.atomic_output` (a temporary file in
the destination folder, flushed to disk and moved into place with :func:`os.replace`), so a
failed save never leaves a truncated file where a good one was. This module imports
neither napari nor Qt.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from .io import atomic_output

#: Extensions the writer produces; another extension gets ``.tif`` appended.
EXTENSIONS = (".tif", ".tiff")


def _label_dtype(data: np.ndarray) -> np.dtype:
    """Smallest integer type holding every label (unsigned when none is negative)."""
    if data.size == 0:
        return np.dtype(np.uint8)
    lo, hi = int(data.min()), int(data.max())
    for dtype in (np.uint8, np.uint16, np.uint32) if lo >= 0 else (np.int8, np.int16, np.int32):
        info = np.iinfo(dtype)
        if info.min <= lo and hi <= info.max:
            return np.dtype(dtype)
    return np.dtype(np.int64)


def labels_to_tiff(path: str | os.PathLike, data: Any, metadata: dict | None = None) -> str:
    """Write integer labels (H, W) or (Z, H, W) to ``path`` as a TIFF, atomically.

    Parameters
    ----------
    path : str or path
        Destination; ``.tif`` is appended unless it ends in ``.tif``/``.tiff``.
    data : array
        Integer labels (values are kept; napari's label 0 is background).
    metadata : dict, optional
        JSON-serialisable items stored in the TIFF's ImageDescription.

    Returns
    -------
    str
        The path written.
    """
    out = Path(os.fspath(path))
    if out.suffix.lower() not in EXTENSIONS:
        out = out.with_name(out.name + ".tif")
    labels = np.asarray(data)
    if labels.ndim < 2:
        raise ValueError(f"labels must have at least 2 dimensions, got shape {labels.shape}")
    if not (np.issubdtype(labels.dtype, np.integer) or labels.dtype == np.bool_):
        raise ValueError(f"labels must be integers, got dtype {labels.dtype}")
    labels = labels.astype(_label_dtype(labels), copy=False)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(out) as tmp:
        tifffile.imwrite(
            tmp, labels, photometric="minisblack", compression="zlib", metadata=metadata or {}
        )
    return str(out)


def write_labels(path: str, data: Any, meta: dict[str, Any]) -> list[str]:
    """npe2 single-layer writer for labels layers: save as an integer TIFF.

    Parameters
    ----------
    path : str
        Destination chosen in napari (``.tif`` appended if it has another extension).
    data : array
        The labels layer's data.
    meta : dict
        The layer's attributes (``name`` is stored in the TIFF's metadata).

    Returns
    -------
    list of str
        The path written.
    """
    name = meta.get("name") if isinstance(meta, dict) else None
    extra = {"layer": str(name)} if name else {}
    return [labels_to_tiff(path, data, extra)]
