"""The inputs of a run beside the stack, read without Qt: content digests (whether a mask
or scribbles layer was edited since a run), what the metadata records of them, the
colour stacks of a colour-polarisation layer."""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np


def content_digest(array: Any) -> str | None:
    """A short fingerprint of an array's shape, dtype and values (None for None).

    Used to tell whether a mask or scribbles layer was edited since a run.
    """
    if array is None:
        return None
    a = np.ascontiguousarray(array)
    if a.dtype == bool:
        a = np.packbits(a)
    # hashed in place (no copy), by SHA-256: the CPU's SHA instructions hash a camera
    # frame's 5 MB of scribbles in 5 ms, blake2b in 11 ms (four digests per stroke)
    digest = hashlib.sha256(a).hexdigest()[:32]
    return f"{np.shape(array)}:{np.asarray(array).dtype}:{digest}"


def region_digest(region: np.ndarray | None) -> str | None:
    """A short fingerprint of a region's content (None for no region)."""
    return None if region is None else content_digest(np.asarray(region, dtype=bool))


def input_info(layer: Any, key: str | None, digest: str | None) -> dict | None:
    """What the segments' metadata records about a mask or scribbles layer."""
    if layer is None or key is None:
        return None
    return {"name": layer.name, "layer_id": key, "digest": digest}


def colour_stack_of(layer: Any) -> np.ndarray | None:
    """The (colour, angle, H, W) stacks a colour-polarisation layer carries in
    ``metadata["colour_stack"]`` (the reader puts them there), if they fit its data."""
    meta = layer.metadata if isinstance(layer.metadata, dict) else {}
    colour = meta.get("colour_stack")
    if not isinstance(colour, np.ndarray) or colour.ndim != 4:
        return None
    return colour if colour.shape[1:] == np.shape(layer.data) else None
