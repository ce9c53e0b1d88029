"""Segment numbers that survive a rerun, so that a segment keeps its colour.

The viewer colours a segment by its label (:mod:`napari_polarseg.palette`). The
superpixel methods number their segments anew at every run: with one segment more
(``n_segments`` 3 → 4), the same leaf could come back as segment 3 instead of 2, and so
in another colour. :func:`keep_numbers` renumbers a rerun's segments: a new segment that
lies mostly (more than half of its pixels) in a segment shown before takes that
segment's number, the largest overlaps first; the others take the numbers left, in
order. The numbers stay 0 … n − 1 (labels 1 … n in the viewer), so the result, its
plots and its exported files agree with what the viewer shows. The thesis method's
recursive cuts keep their numbers by themselves (a cut splits one segment and numbers
the new part last) and a classifier's labels are the strokes' values: neither is
renumbered. No Qt, no napari.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np


def surviving_order(new: np.ndarray, shown: np.ndarray, n: int) -> np.ndarray:
    """The renumbering (``order[k]`` is the new number of new segment ``k``) that gives
    each new segment lying mostly in a shown one that one's number.

    Parameters
    ----------
    new : int array (H, W)
        The new segments, 0 … n − 1.
    shown : int array (H, W)
        What the viewer shows: label v is segment v − 1 (0 = none); labels above ``n``
        cannot be kept and count as none.
    n : int
        The number of new segments.
    """
    flat_new = np.asarray(new, dtype=np.int64).ravel()
    old = np.asarray(shown, dtype=np.int64).ravel()
    old = np.where((old >= 1) & (old <= n), old, 0)
    overlap = np.bincount(flat_new * (n + 1) + old, minlength=n * (n + 1)).reshape(n, n + 1)
    sizes = overlap.sum(axis=1)
    order = np.full(n, -1, dtype=np.int64)
    taken = np.zeros(n, dtype=bool)
    ranked = np.argsort(-overlap[:, 1:], axis=None, kind="stable")
    for flat in ranked:
        k, v = divmod(int(flat), n)
        count = overlap[k, v + 1]
        if 2 * count <= sizes[k]:
            if count == 0:
                break
            continue
        if order[k] < 0 and not taken[v]:
            order[k], taken[v] = v, True
    free = iter(np.flatnonzero(~taken))
    for k in np.flatnonzero(order < 0):
        order[k] = next(free)
    return order


def renumbered(labels: np.ndarray, order: np.ndarray) -> np.ndarray:
    """``labels`` with every value k in 0 … len(order) − 1 replaced by ``order[k]``
    (other values, if any, kept)."""
    labels = np.asarray(labels)
    inside = (labels >= 0) & (labels < order.size)
    mapped = order[np.clip(labels, 0, order.size - 1)].astype(labels.dtype)
    return np.where(inside, mapped, labels)


def keep_numbers(result: Any, shown: np.ndarray | None) -> Any:
    """``result`` (a :class:`~napari_polarseg.engine.SegmentationResult`) with its
    segments renumbered after ``shown`` (the labels on screen, module docstring); the
    same object when nothing changes: no labels shown (or of another size), a
    classifier's result, a method that cuts the block grid."""
    labels = np.asarray(result.labels)
    if shown is None or np.shape(shown) != labels.shape or labels.size == 0:
        return result
    if result.materials is not None or result.cuts_blocks or labels.min() < 0:
        return result
    order = surviving_order(labels, shown, int(labels.max()) + 1)
    if np.array_equal(order, np.arange(order.size)):
        return result
    return replace(
        result,
        labels=renumbered(labels, order),
        block_labels=renumbered(result.block_labels, order),
    )
