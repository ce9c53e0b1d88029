"""Segment borders moved onto the pixels they belong to.

A watershed border on a straight edge can sit a few pixels off: every pixel on a
segment border moves to the neighbouring segment whose mean (log Î, ρ) it resembles
most (:func:`refine_boundaries`), in up to :data:`REFINE_PASSES` one-pixel passes
(:func:`refined_labels`).
"""

from __future__ import annotations

import numpy as np

from ..features.pixel_features import EPS_INTENSITY

#: Most passes of :func:`refine_boundaries` (each moves a border by at most one pixel;
#: the passes stop when one moves nothing).
REFINE_PASSES = 5


def refine_boundaries(
    labels: np.ndarray,
    intensity: np.ndarray,
    dop: np.ndarray,
    n_labels: int,
    spread: np.ndarray | None = None,
) -> np.ndarray:
    """Pixels on a segment border moved to the neighbouring segment they resemble most.

    For every pixel with a different label in its 3 × 3 neighbourhood: the label, among
    those of the neighbourhood, whose segment mean of (log Î, ρ) is nearest in units of
    ``spread``, the pooled within-segment spread of each (computed from ``labels`` when
    not given). One pass (each moves a border by at most a pixel), vectorised over the
    border pixels only.
    """
    return _refine_pass(labels, refine_maps(intensity, dop), n_labels, spread)


def refine_maps(intensity: np.ndarray, dop: np.ndarray) -> np.ndarray:
    """(2, H, W) float64: log Î and ρ, what the refinement compares."""
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY)).astype(np.float64)
    return np.stack([log_i, dop.astype(np.float64)])


def _refine_pass(
    labels: np.ndarray, maps: np.ndarray, n_labels: int, spread: np.ndarray | None
) -> np.ndarray:
    """One pass of :func:`refine_boundaries` on the (2, H, W) ``maps``: the border
    pixels are found by comparing shifted views and only their neighbourhoods gathered
    (a full 9-plane stack of the labels costs more than the whole pass)."""
    flat = labels.ravel()
    count = np.maximum(np.bincount(flat, minlength=n_labels), 1)
    means = np.stack([np.bincount(flat, m.ravel(), n_labels) / count for m in maps])
    if spread is None:
        resid = maps - means[:, labels]
        spread = np.sqrt((resid.reshape(2, -1) ** 2).mean(axis=1)) + 1e-12
    # the 3 × 3 neighbourhood of every pixel (edge-padded): row and column offsets
    pad = np.pad(labels, 1, mode="edge")
    offsets = [(r, c) for r in range(3) for c in range(3)]
    border = _border(labels)
    if not border.any():
        return labels
    rows, cols = np.nonzero(border)
    cand = np.stack([pad[rows + r, cols + c] for r, c in offsets])  # (9, b) candidates
    x = maps[:, rows, cols] / spread[:, None]  # (2, b)
    mu = means / spread[:, None]  # (2, k)
    d = ((x[:, None, :] - mu[:, cand]) ** 2).sum(axis=0)  # (9, b)
    out = labels.copy()
    out[rows, cols] = cand[np.argmin(d, axis=0), np.arange(cand.shape[1])]
    return out


def _border(labels: np.ndarray) -> np.ndarray:
    """Pixels with a different label among their 8 neighbours inside the image: each
    of the four neighbour directions compared once, both pixels of a differing pair
    marked."""
    border = np.zeros(labels.shape, dtype=bool)
    for a, b in (
        ((slice(None), slice(1, None)), (slice(None), slice(None, -1))),  # left-right
        ((slice(1, None), slice(None)), (slice(None, -1), slice(None))),  # up-down
        ((slice(1, None), slice(1, None)), (slice(None, -1), slice(None, -1))),  # diagonal
        ((slice(1, None), slice(None, -1)), (slice(None, -1), slice(1, None))),  # anti-diag.
    ):
        differ = labels[a] != labels[b]
        border[a] |= differ
        border[b] |= differ
    return border


def _spread(labels: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """Pooled within-segment standard deviation of log Î and of ρ, (2,), from the
    (2, H, W) ``maps`` of :func:`refine_maps`: the units of :func:`refine_boundaries`."""
    flat = labels.ravel()
    n = int(flat.max()) + 1
    count = np.maximum(np.bincount(flat, minlength=n), 1)
    out = []
    for m in (maps[0].ravel(), maps[1].ravel()):
        mean = np.bincount(flat, m, n) / count
        out.append(np.sqrt(np.mean((m - mean[flat]) ** 2)) + 1e-12)
    return np.array(out)


def refined_labels(
    labels: np.ndarray, i: np.ndarray, d: np.ndarray, k: int, maps: np.ndarray | None = None
) -> np.ndarray:
    """Labels after up to :data:`REFINE_PASSES` passes of :func:`refine_boundaries`;
    ``maps``: :func:`refine_maps` of ``i`` and ``d`` when already made."""
    maps = refine_maps(i, d) if maps is None else maps
    spread = _spread(labels, maps)
    for _ in range(REFINE_PASSES):
        moved = _refine_pass(labels, maps, k, spread)
        if np.array_equal(moved, labels):
            break  # converged: no border pixel moved
        labels = moved
    return labels.astype(np.int32)
