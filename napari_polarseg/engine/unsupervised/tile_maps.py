"""The maps of one tile of a large image, as the whole image's code would read them."""

from __future__ import annotations

import numpy as np

from ..features.pixel_features import check_maps
from ..physics.pixel_mask import nearest_valid
from ..tiles import Box


def filled_box(
    maps: tuple[np.ndarray, ...], valid: np.ndarray | None, box: Box
) -> tuple[tuple[np.ndarray, ...], np.ndarray | None, np.ndarray | None]:
    """(maps, valid, nearest) of one box: its part of Î, ρ, φ checked as the whole
    image's (float32, non-finite values 0:
    :func:`~..features.pixel_features.check_maps`), outside ``valid`` filled from the
    nearest valid pixel of the box; the box's valid pixels (None: all) and the flat
    index in the box of every pixel's nearest valid one (None: no fill)."""
    parts = check_maps(*(m[box] for m in maps))
    if valid is None:
        return parts, None, None
    v = valid[box]
    if v.all() or not v.any():  # nothing to fill, or nothing to fill from
        return parts, (None if v.all() else v), None
    rows, cols = nearest_valid(v)
    nearest = rows * v.shape[1] + cols
    return tuple(m.ravel()[nearest] for m in parts), v, nearest
