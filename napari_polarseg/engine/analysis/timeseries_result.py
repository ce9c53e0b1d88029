"""What :func:`.timeseries.segment_timeseries` returns: the labels of every day, the change
maps and scores, the shared features, and a JSON-ready summary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from ..params import SegmentParams
from ..pipeline import Pipeline
from .change_test import ChangeStatistics


@dataclass
class TimeSeriesResult:
    """Segments of several days of one view, consistent over time, and their changes.

    Attributes
    ----------
    params : SegmentParams
        Parameters used for every day.
    method : {"tracked", "reference", "joint"}
        How the blocks were segmented (module docstring).
    labels : ndarray (T, H, W) int32
        Segment of every pixel on each day; segment k means the same material on every
        day (0 = first segment; for ``tracked``, 0 … ``n_base_segments`` − 1 are day 1's
        segments and the later ones the materials blocks changed into).
    block_labels : ndarray (T, rows, cols) int32
        Segment of every block of the label grid (side ``label_window``: the w × w
        segmentation blocks for ``reference`` and ``joint``, the change blocks for
        ``tracked``; the majority of the block's pixels).
    changes : ndarray (T − 1, H, W) bool
        ``changes[t]``: the pixel is in another segment on day t + 1 than on day t (the
        change map; block-shaped).
    block_changes : ndarray (T − 1, rows, cols) bool
        The same per block of the label grid.
    change_score : ndarray (T − 1, H, W) float32
        Graded change map: the change score of the pixel's change block
        (:class:`ChangeStatistics`; 3.09 = the evidence of a p-value of 0.001 that the
        polarisation image changed), whatever the segments did.
    block_change_score : ndarray (T − 1, rows_c, cols_c)
        The same per change block (side ``change_window``).
    change_significant : ndarray (T − 1, rows_c, cols_c) bool
        Change blocks whose change is significant at ``false_alarm``; for ``tracked``
        these are the blocks that moved to a changed segment (or stayed in one).
    change_statistics : list of ChangeStatistics
        The full test of each pair of consecutive days.
    feature_distance : ndarray (T − 1, H, W) float32
        Mahalanobis distance (covariance of all days' blocks) between the shared-basis
        features of the pixel's segmentation block on day t and on day t + 1 (the older,
        weaker graded measure, kept for comparison).
    block_feature_distance : ndarray (T − 1, rows_w, cols_w)
        The same per segmentation block.
    features : ndarray (T, n_blocks, n_components)
        Block features of every day in the shared PCA basis.
    explained_variance_ratio : ndarray (n_components,)
        Share of the variance (over all days' blocks) each kept component explains.
    components : ndarray (n_components, n_features)
        The shared principal axes.
    segment_means : ndarray (K, n_components)
        Mean feature vector of each segment (``joint``: over all days' blocks;
        ``reference``: over day 1's; ``tracked``: over the pixels of all days, each with
        its segmentation block's features).
    ncut_values : list of float
        Ncut value of each split.
    n_base_segments : int
        Segments of the cut (day 1 for ``tracked`` and ``reference``).
    changed_segments : list of dict
        ``tracked`` only: for every segment after the base ones, the day it first
        appears, its change blocks and their mean change
        (:data:`~napari_polarseg.engine.analysis.change_test.CHANGE_COMPONENTS`).
    label_window, change_window : int
        Sides of the label-grid and change blocks.
    false_alarm : float
        Per-block false-alarm probability of the change test.
    change_from : {"all", "polarisation", "intensity"}
        What the change test compared (:func:`change_statistics`).
    pipelines : list of Pipeline
        The per-day pipelines (their cached stages hold Î, ρ, φ, normals, coefficients).
    timings : dict
        Seconds per step.
    """

    params: SegmentParams
    method: str
    labels: np.ndarray
    block_labels: np.ndarray
    changes: np.ndarray
    block_changes: np.ndarray
    change_score: np.ndarray
    block_change_score: np.ndarray
    change_significant: np.ndarray
    change_statistics: list[ChangeStatistics]
    feature_distance: np.ndarray
    block_feature_distance: np.ndarray
    features: np.ndarray
    explained_variance_ratio: np.ndarray
    components: np.ndarray
    segment_means: np.ndarray
    ncut_values: list[float]
    n_base_segments: int
    changed_segments: list[dict[str, Any]]
    label_window: int
    change_window: int
    false_alarm: float
    change_from: str
    pipelines: list[Pipeline] = field(default_factory=list, repr=False)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def n_days(self) -> int:
        return int(self.labels.shape[0])

    @property
    def n_segments(self) -> int:
        return int(self.labels.max()) + 1

    def changed_fraction(self) -> np.ndarray:
        """Share of the pixels that changed segment between each pair of consecutive days."""
        if self.changes.shape[0] == 0:
            return np.zeros(0)
        return self.changes.reshape(self.changes.shape[0], -1).mean(axis=1)

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures: segments per day, changes per pair of days, PCA, timings."""
        k = self.n_segments
        return {
            "method": self.method,
            "n_days": self.n_days,
            "n_segments": k,
            "n_base_segments": self.n_base_segments,
            "changed_segments": [dict(s) for s in self.changed_segments],
            "segment_pixels": [
                np.bincount(day.ravel(), minlength=k).tolist() for day in self.labels
            ],
            "label_window": self.label_window,
            "block_grid": list(self.block_labels.shape[1:]),
            "changed_blocks": [int(c.sum()) for c in self.block_changes],
            "changed_pixels": [int(c.sum()) for c in self.changes],
            "changed_pixel_fraction": [float(v) for v in self.changed_fraction()],
            "change_window": self.change_window,
            "change_grid": list(self.block_change_score.shape[1:]),
            "false_alarm": self.false_alarm,
            "change_from": self.change_from,
            "score_threshold": float(stats.norm.isf(self.false_alarm)),
            "significant_change_blocks": [int(s.sum()) for s in self.change_significant],
            "max_change_score": [float(s.max(initial=0.0)) for s in self.block_change_score],
            "intensity_gain": [s.gain for s in self.change_statistics],
            "noise_inflation": [s.inflation for s in self.change_statistics],
            "mean_feature_distance": [float(d.mean()) for d in self.block_feature_distance],
            "n_components": int(self.features.shape[-1]),
            "explained_variance": float(np.sum(self.explained_variance_ratio)),
            "explained_variance_ratio": [float(v) for v in self.explained_variance_ratio],
            "ncut_values": [float(v) for v in self.ncut_values],
            "seconds": {name: round(v, 6) for name, v in self.timings.items()},
        }
