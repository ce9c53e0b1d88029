"""The labels of every day of a time series from day 1's segments (method "tracked",
"reference" or "joint" of :func:`.timeseries.segment_timeseries`), the segment means and
the feature distance of every block between consecutive days."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..features import harmonics
from ..features import pca as feat
from ..params import SegmentParams
from .change_test import ChangeStatistics
from .tracking import block_majority, track_labels


@dataclass
class DaySegments:
    """Labels of every day from day 1's segments (:func:`day_segments`)."""

    labels: np.ndarray
    block_labels: np.ndarray
    segment_means: np.ndarray
    changed_segments: list[dict[str, Any]]
    label_window: int
    k: int
    distance: np.ndarray


def day_segments(
    method: str,
    graph_labels: np.ndarray,
    base: np.ndarray | None,
    scores: np.ndarray,
    grid: tuple[int, ...],
    shape: tuple[int, ...],
    params: SegmentParams,
    change_stats: list[ChangeStatistics],
    change_window: int,
) -> DaySegments:
    """Pixel and block labels of every day by ``method`` (:mod:`.timeseries`) from day 1's
    block labels ``graph_labels`` (tracked: from its pixel labels ``base``, None: the
    blocks'), the segment means and the feature distance of every block between
    consecutive days."""
    k = int((graph_labels if base is None else base).max()) + 1
    n_blocks = int(np.prod(grid))
    n_days = scores.shape[0] // n_blocks
    # Mahalanobis distance under the covariance of all days' blocks = Euclidean on z
    z = feat.whiten(scores)
    changed_segments: list[dict[str, Any]] = []
    if method == "tracked":
        if base is None:
            base = harmonics.upsample_block_labels(graph_labels.reshape(grid), shape, params.window)
        labels, changed_segments = track_labels(base, change_stats)
        segment_means = pixel_label_means(labels, scores, grid, params.window)
        label_window = change_window
        block_labels = np.stack([block_majority(day, label_window) for day in labels])
    else:
        if method == "joint":
            flat = graph_labels
            segment_means = label_means(scores, flat, k)
        else:
            # every block of every day, day 1 included, takes its nearest segment mean, so
            # that identical blocks on two days always get the same segment
            means_z = label_means(z[:n_blocks], graph_labels, k)
            d2 = np.einsum("ij,ij->i", z, z)[:, None] - 2.0 * z @ means_z.T
            d2 += np.einsum("ij,ij->i", means_z, means_z)[None, :]
            flat = np.argmin(d2, axis=1).astype(np.int32)
            segment_means = label_means(scores[:n_blocks], graph_labels, k)
        label_window = params.window
        block_labels = flat.reshape(n_days, *grid).astype(np.int32)
        labels = np.stack(
            [harmonics.upsample_block_labels(b, shape, params.window) for b in block_labels]
        ).astype(np.int32)
    zd = z.reshape(n_days, n_blocks, -1)
    distance = np.sqrt(((zd[1:] - zd[:-1]) ** 2).sum(-1)).reshape(n_days - 1, *grid)
    return DaySegments(
        labels, block_labels, segment_means, changed_segments, label_window, k, distance
    )


def label_means(x: np.ndarray, labels: np.ndarray, k: int) -> np.ndarray:
    """Mean row of ``x`` per label 0..k−1 (vectorised with bincount-style sums)."""
    counts = np.bincount(labels, minlength=k).astype(float)
    sums = np.zeros((k, x.shape[1]))
    np.add.at(sums, labels, x)
    return sums / np.maximum(counts, 1.0)[:, None]


def pixel_label_means(
    labels: np.ndarray, scores: np.ndarray, grid: tuple[int, ...], window: int
) -> np.ndarray:
    """Mean feature per segment over the pixels of all days (each pixel with its
    segmentation block's features)."""
    n_days, h, w = labels.shape
    k = int(labels.max()) + 1
    n_blocks = int(np.prod(grid))
    rows, cols = harmonics.pixel_block_index((h, w), window)
    block = (rows[:, None] * grid[1] + cols[None, :]).ravel()
    x = scores.reshape(n_days, n_blocks, -1)
    sums = np.zeros((k, x.shape[-1]))
    counts = np.zeros(k)
    for t in range(n_days):
        m = np.bincount(labels[t].ravel() * n_blocks + block, minlength=k * n_blocks)
        m = m.reshape(k, n_blocks).astype(float)
        sums += m @ x[t]
        counts += m.sum(axis=1)
    return sums / np.maximum(counts, 1.0)[:, None]
