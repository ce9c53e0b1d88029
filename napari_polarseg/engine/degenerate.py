"""Telling a degenerate segmentation apart: (nearly) everything in one segment.

With the thesis scale (s = 1) and 10–20 PCA components the block affinity falls apart
and the normalized cut peels off a few odd blocks: on the polanalyser fruits frame the
thesis defaults put 99.94 % of the pixels in one segment ([1252676, 100, 600] pixels).
Such a result says nothing about the materials, and it should not pass silently: the
command line warns, ``summary.json`` records ``"degenerate"``, the plugin's status line
says so. :func:`degenerate_result` is the one test they all use: a method that cuts the
w × w block grid (the thesis method) also counts segments below its minimum segment size
(``min_pixels``); the others are judged on their pixel labels over the used pixels
(``valid``; :meth:`~napari_polarseg.engine.result.SegmentationResult.degenerate`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

#: A segmentation is degenerate when its largest segment holds at least this share of
#: the pixels.
DEGENERATE_SHARE = 0.95


class DegenerateCheck(NamedTuple):
    """What :func:`degenerate_result` found.

    Attributes
    ----------
    degenerate : bool
        One segment holds (nearly) everything.
    largest_share : float
        Share of the pixels in the largest segment, in [0, 1].
    reason : str
        Why it is degenerate, in words ("" when it is not).
    """

    degenerate: bool
    largest_share: float
    reason: str


def segment_sizes(labels: np.ndarray) -> np.ndarray:
    """The pixel count of every segment that has pixels, in label order (any integer
    labels; a count, not a sort, for small non-negative ones)."""
    flat = np.asarray(labels).ravel()
    small = flat.size and flat.dtype.kind in "iu" and flat.min() >= 0
    if small and flat.max() < max(flat.size, 2**16):
        counts = np.bincount(flat)
        return counts[counts > 0]
    return np.unique(flat, return_counts=True)[1]


#: Pixels counted at once by :func:`used_segment_sizes` (bounds its temporaries).
COUNT_CHUNK = 1 << 22


def used_segment_sizes(labels: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """:func:`segment_sizes` of ``labels[valid]``, counted :data:`COUNT_CHUNK` pixels at
    a time (no copy of the used labels: an image's labels may be larger than memory)."""
    flat, keep = np.asarray(labels).ravel(), np.asarray(valid, dtype=bool).ravel()
    if not (flat.size and flat.dtype.kind in "iu" and flat.min() >= 0):
        return segment_sizes(flat[keep])
    top = int(flat.max()) + 1
    if top >= max(flat.size, 2**16):
        return segment_sizes(flat[keep])
    counts = np.zeros(top, dtype=np.int64)
    for start in range(0, flat.size, COUNT_CHUNK):
        part = slice(start, start + COUNT_CHUNK)
        counts += np.bincount(flat[part][keep[part]], minlength=top)
    return counts[counts > 0]


def degenerate_result(
    labels: np.ndarray,
    min_pixels: int = 1,
    share: float = DEGENERATE_SHARE,
    requested: int | None = None,
    valid: np.ndarray | None = None,
) -> DegenerateCheck:
    """Whether a labelling put (nearly) every pixel in one segment.

    Degenerate when the largest segment holds at least ``share`` of the pixels, or when
    every other segment is smaller than ``min_pixels`` (e.g. the minimum segment size,
    ``min_segment_blocks`` · w², of the cut). A labelling of one segment is degenerate
    only when more were asked for (``requested`` > 1; None counts as more). With
    ``valid``, only the used pixels count (the reason then says "of the used pixels"
    when some are left out).

    Parameters
    ----------
    labels : array of int
        Segment of every pixel (any shape; values need not be consecutive).
    min_pixels : int
        Smallest segment size, in pixels, that counts as a segment.
    share : float
        Share of the pixels in the largest segment from which the result is degenerate.
    requested : int, optional
        Number of segments asked for.
    valid : array of bool, optional
        The pixels that count (``labels``' shape; default all). None of them: not
        degenerate (nothing to judge).

    Returns
    -------
    DegenerateCheck

    Examples
    --------
    >>> import numpy as np
    >>> labels = np.zeros((100, 100), dtype=int); labels[:2, :3] = 1
    >>> degenerate_result(labels).degenerate
    True
    """
    labels = np.asarray(labels)
    pixels = "pixels"
    if valid is not None and not np.all(valid):
        sizes, pixels = used_segment_sizes(labels, np.asarray(valid, dtype=bool)), "used pixels"
    else:
        sizes = segment_sizes(labels)
    total = int(sizes.sum())
    if total == 0:
        return DegenerateCheck(False, 0.0, "")
    order = np.argsort(sizes)[::-1]
    largest = int(sizes[order[0]])
    largest_share = largest / total
    others = sizes[order[1:]]
    percent = f"{100 * largest_share:.4g} %"
    if sizes.size == 1:
        if requested is not None and requested <= 1:
            return DegenerateCheck(False, 1.0, "")
        return DegenerateCheck(True, 1.0, f"every {pixels[:-1]} is in one segment")
    if largest_share >= share:
        return DegenerateCheck(True, largest_share, f"one segment holds {percent} of the {pixels}")
    if others.max() < min_pixels:
        return DegenerateCheck(
            True,
            largest_share,
            f"every segment but the largest ({percent} of the {pixels}) is below the "
            f"minimum segment size of {int(min_pixels)} pixels",
        )
    return DegenerateCheck(False, largest_share, "")
