"""Tracking day 1's segments through a time series: only blocks whose polarisation changed
significantly (:mod:`.change_test`) move to another segment (method "tracked" of
:func:`.timeseries.segment_timeseries`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..features import harmonics
from .change_test import CHANGE_COMPONENTS, ChangeStatistics


def _block_slices(shape: tuple[int, int], window: int) -> tuple[list[slice], list[slice]]:
    """Pixel rows and columns of every block row and column (remainder strips included)."""
    rows, cols = harmonics.pixel_block_index(shape, window)

    def spans(index: np.ndarray) -> list[slice]:
        edges = np.flatnonzero(np.diff(index)) + 1
        starts = np.concatenate([[0], edges])
        stops = np.concatenate([edges, [index.size]])
        return [slice(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]

    return spans(rows), spans(cols)


def block_majority(labels: np.ndarray, window: int) -> np.ndarray:
    """Most frequent label of every block (rows, cols), remainder strips included."""
    shape = labels.shape
    rows, cols = harmonics.pixel_block_index(shape, window)
    grid = harmonics.block_grid(shape, window)
    block = (rows[:, None] * grid[1] + cols[None, :]).ravel()
    k = int(labels.max()) + 1
    counts = np.bincount(block * k + labels.ravel(), minlength=grid[0] * grid[1] * k)
    return counts.reshape(grid[0] * grid[1], k).argmax(axis=1).reshape(grid).astype(np.int32)


def _signs(t: np.ndarray, threshold: float) -> np.ndarray:
    """Sign of every component whose |t| exceeds ``threshold`` (else 0)."""
    return np.where(np.abs(t) > threshold, np.sign(t), 0.0)


@dataclass
class _ChangedSegment:
    """A material blocks changed into: the sum of its blocks' t-vectors and mean changes."""

    t_sum: np.ndarray
    change_sum: np.ndarray
    blocks: int = 0
    first_day: int = 0

    def signs(self, threshold: float) -> np.ndarray:
        # the combined evidence of the members: Σt / √n is a t-value again
        return _signs(self.t_sum / np.sqrt(max(self.blocks, 1)), threshold)


def track_labels(
    base: np.ndarray, statistics: Sequence[ChangeStatistics]
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Carry day 1's labels through the days, moving only the blocks that changed.

    Day t + 1 starts as day t. Every change block flagged by ``statistics[t]`` (in order
    of decreasing score) moves to the segment of the material it changed into. A change
    is described by the signs of its tested components (:data:`CHANGE_COMPONENTS`: Î,
    ρ along and across the polarisation direction) that are significant on their own
    (|t| above the score threshold); a changed segment by the signs significant over
    all its blocks together (Σt / √n). A block is *compatible* with a changed segment
    when no sign of one contradicts a sign of the other:

    - a block in a changed segment whose significant signs all contradict that segment's
      goes back to the segment its pixels had before (the change was undone);
    - else it joins the compatible changed segment that shares the most signs with it
      (ties: the closest mean direction); a block already there stays, its change went
      on the same way;
    - else it starts a new changed segment, numbered after all existing ones.

    Blocks not flagged keep their segment. The sign rule groups the blocks of one
    material change although which component carries the evidence depends on the tilt
    (the intensity change dominates where ρ is small, the ρ change at grazing tilt).

    Returns the labels (T, H, W) and one dict per changed segment: ``segment``,
    ``first_day`` (1-based), ``blocks`` (change blocks that joined it) and
    ``mean_change`` (their mean change per component).
    """
    base = np.asarray(base, dtype=np.int32)
    k0 = int(base.max()) + 1
    labels = [base]
    origin = base.copy()  # the segment each pixel had before its latest move
    segments: list[_ChangedSegment] = []
    for day, st in enumerate(statistics):
        lab = labels[-1].copy()
        rows, cols = _block_slices(lab.shape, st.window)
        tvec = st.t[..., list(st.components)]
        flagged = np.argwhere(st.significant)
        order = np.argsort(-st.score[st.significant], kind="stable")
        for r, c in flagged[order]:
            sl = (rows[r], cols[c])
            t = tvec[r, c]
            own = _signs(t, st.threshold)
            cur = lab[sl]
            values, counts = np.unique(cur, return_counts=True)
            major = int(values[np.argmax(counts)])
            if major >= k0:
                theirs = segments[major - k0].signs(st.threshold)
                both = (own != 0) & (theirs != 0)
                if both.any() and np.all(own[both] != theirs[both]):
                    back = cur == major
                    cur[back] = origin[sl][back]
                    origin[sl][back] = cur[back]
                    continue
            best, best_key = _best_segment(segments, own, t, st.threshold)
            if best < 0 or (best_key[0] == 0 and best_key[1] <= 0.0):
                best = len(segments)
                segments.append(
                    _ChangedSegment(np.zeros_like(t), np.zeros(len(CHANGE_COMPONENTS)), 0, day + 2)
                )
            seg = segments[best]
            seg.t_sum += t
            seg.change_sum += st.mean[r, c]
            seg.blocks += 1
            moved = cur != k0 + best
            origin[sl][moved] = cur[moved]
            cur[...] = k0 + best
        labels.append(lab)
    info = [_segment_info(k0 + j, seg) for j, seg in enumerate(segments)]
    return np.stack(labels).astype(np.int32), info


def _best_segment(
    segments: list[_ChangedSegment], own: np.ndarray, t: np.ndarray, threshold: float
) -> tuple[int, tuple[int, float]]:
    """The compatible changed segment sharing most signs with a block (ties: the closest
    mean direction): (its index or −1, (shared signs, cosine))."""
    best, best_key = -1, (-1, -2.0)
    for j, seg in enumerate(segments):
        theirs = seg.signs(threshold)
        both = (own != 0) & (theirs != 0)
        if np.any(own[both] != theirs[both]):
            continue
        cos = float(_unit(t) @ _unit(seg.t_sum))
        key = (int(both.sum()), cos)
        if key > best_key:
            best, best_key = j, key
    return best, best_key


def _segment_info(segment: int, seg: _ChangedSegment) -> dict[str, Any]:
    """The dict :func:`track_labels` reports for a changed segment."""
    return {
        "segment": segment,
        "first_day": seg.first_day,
        "blocks": seg.blocks,
        "mean_change": {
            name: float(v)
            for name, v in zip(CHANGE_COMPONENTS, seg.change_sum / seg.blocks, strict=True)
        },
    }


def _unit(v: np.ndarray) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v
