"""Scribbles from a segmentation: an unsupervised result turned into editable strokes.

:func:`scribbles_from_labels` keeps each segment's interior and leaves a band along every
border unlabelled (0): the pixels deeper than ``margin`` pixels inside their segment
(Euclidean distance to the nearest pixel of another segment or of the image's unused
pixels, :func:`scipy.ndimage.distance_transform_edt`) keep their segment's value; the
border band is left for the classifier trained on these strokes to decide, so a border
the unsupervised method drew wrongly is not taught back to it. A segment thinner than
2 × ``margin`` pixels has no interior and gives no stroke; the user corrects the rest by
painting and erasing.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import PolarsegError

#: Default border band left unlabelled, pixels.
DEFAULT_MARGIN = 4


def scribbles_from_labels(
    labels: np.ndarray,
    margin: int = DEFAULT_MARGIN,
    valid: np.ndarray | None = None,
    first_value: int = 1,
) -> np.ndarray:
    """Segment interiors as scribbles (module docstring).

    Parameters
    ----------
    labels : array (H, W) of int ≥ 0
        A segmentation; every value is a segment.
    margin : int
        Pixels within this distance of another segment (or of an unused pixel) are left
        unlabelled; 0 keeps every pixel.
    valid : array (H, W) bool, optional
        The used pixels; the others are unlabelled and count as a border.
    first_value : int
        The scribble value of the smallest label (the next labels follow in order:
        value = label − min + ``first_value``), e.g. 1 for the engine's labels 0, 1, …;
        napari's segments layer (1, 2, …) keeps its values with ``first_value`` = its
        smallest label.

    Returns
    -------
    ndarray (H, W) int32
        0 = unlabelled, else the segment's scribble value.
    """
    labels = np.asarray(labels)
    if labels.ndim != 2 or labels.dtype.kind not in "biu":
        raise PolarsegError(
            f"labels must be one 2-D integer image, got {labels.dtype} {labels.shape}"
        )
    if margin < 0 or first_value < 1:
        raise PolarsegError("margin must be >= 0 and first_value >= 1")
    used = np.ones(labels.shape, bool) if valid is None else np.asarray(valid, dtype=bool)
    values = labels.astype(np.int64) - (int(labels.min()) if labels.size else 0) + first_value
    if margin == 0:
        return np.where(used, values, 0).astype(np.int32)
    # a pixel is on a border when a 4-neighbour differs (or is unused)
    border = ~used
    padded = np.pad(np.where(used, labels.astype(np.int64), -1), 1, mode="edge")
    centre = padded[1:-1, 1:-1]
    for dr, dc in ((0, 1), (2, 1), (1, 0), (1, 2)):
        border |= padded[dr : dr + labels.shape[0], dc : dc + labels.shape[1]] != centre
    depth = ndimage.distance_transform_edt(~border)
    return np.where(used & (depth > margin), values, 0).astype(np.int32)
