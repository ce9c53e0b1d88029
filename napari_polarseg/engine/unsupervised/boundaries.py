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
        spread = _spread(flat, maps.reshape(2, -1), means)
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


#: (count (k,), sums (2, k), spread (2,)) of :func:`segment_stats`.
SegmentStats = tuple[np.ndarray, np.ndarray, np.ndarray]


def segment_stats(count: np.ndarray, sums: np.ndarray, squares: np.ndarray) -> SegmentStats:
    """What :func:`refined_labels` reads of the segments, from their pixel counts n_k
    (k,), the sums Σv (2, k) and the sums of squares Σv² (2, k) of log Î and ρ over
    their pixels: (n_k, Σv, the pooled spread √((Σ_k Σv² − Σ_k (Σv)² / n_k) / Σ n_k)
    of each map), the spread in the units of the maps (log Î: ln of the input's units;
    ρ: none)."""
    count = np.asarray(count, dtype=np.float64)
    within = squares.sum(axis=1) - (sums**2 / np.maximum(count, 1.0)).sum(axis=1)
    spread = np.sqrt(np.maximum(within, 0.0) / max(float(count.sum()), 1.0)) + 1e-12
    return count, np.asarray(sums, dtype=np.float64), spread


def _spread(flat: np.ndarray, values: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Pooled within-segment standard deviation of log Î and of ρ, (2,): the units of
    :func:`refine_boundaries`, from the flat labels, the (2, P) ``values`` of
    :func:`refine_maps` and the (2, k) segment means."""
    pairs = zip(values, means, strict=True)
    return np.array([np.sqrt(np.mean((v - m[flat]) ** 2)) + 1e-12 for v, m in pairs])


def refined_labels(
    labels: np.ndarray,
    i: np.ndarray,
    d: np.ndarray,
    k: int,
    maps: np.ndarray | None = None,
    stats: SegmentStats | None = None,
) -> np.ndarray:
    """Labels after up to :data:`REFINE_PASSES` passes of :func:`refine_boundaries`;
    ``maps``: :func:`refine_maps` of ``i`` and ``d`` when already made; ``stats``: the
    segments' pixel counts, sums of log Î and ρ and pooled spread of a larger image
    that ``labels`` is a tile of (:func:`segment_stats`), else taken from ``labels``.

    The same labels as calling :func:`refine_boundaries` pass after pass (with the
    spread of the first labels), but each pass looks only at the pixels that can be on
    a border: a pixel joins the border only when it or a neighbour changed label, so
    after the first pass the candidates are the last border and the 3 × 3
    neighbourhoods of the pixels that moved. The segment sums are updated from the
    moved pixels instead of recounted over the image, and each border pixel's distance
    to every segment is computed once (k values) and then read for its neighbours.
    Written by hand: no library keeps per-label means under label changes.
    """
    maps = refine_maps(i, d) if maps is None else maps
    h, w = labels.shape
    values = maps.reshape(2, -1)
    if stats is None:
        first = np.ascontiguousarray(labels, dtype=np.int32).ravel()
        count = np.bincount(first, minlength=k).astype(np.float64)
        sums = np.stack([np.bincount(first, v, k) for v in values])
        spread = _spread(first, values, sums / np.maximum(count, 1.0))
    else:
        count, sums, spread = (np.array(a, dtype=np.float64) for a in stats)
    # the labels inside a frame of the label k (no segment): a neighbour's flat index
    # is the pixel's plus a fixed offset, and the frame is never a candidate
    padded = np.full((h + 2, w + 2), k, dtype=np.int32)
    padded[1:-1, 1:-1] = labels
    flat = padded.ravel()
    offsets = ((np.arange(3)[:, None] - 1) * (w + 2) + np.arange(3)[None, :] - 1).ravel()
    rows, cols = np.nonzero(_border(padded[1:-1, 1:-1]))
    candidates = (rows + 1) * (w + 2) + cols + 1
    mark = np.zeros((h + 2, w + 2), dtype=bool)  # scratch for the next candidates
    marked = mark.ravel()
    for _ in range(REFINE_PASSES):
        neighbours = flat[candidates[None, :] + offsets[:, None]]  # (9, b)
        own = flat[candidates]
        on_border = ((neighbours != own) & (neighbours != k)).any(axis=0)
        pixels, neighbours = candidates[on_border], neighbours[:, on_border]
        if pixels.size == 0:
            break
        r, c = np.divmod(pixels, w + 2)
        inside = (r - 1) * w + (c - 1)  # the pixels' indices in the maps
        mu = sums / np.maximum(count, 1.0) / spread[:, None]  # (2, k)
        x = values[:, inside] / spread[:, None]  # (2, b)
        to_segment = np.full((k + 1, pixels.size), np.inf)  # row k: the frame
        to_segment[:k] = ((x[:, None, :] - mu[:, :, None]) ** 2).sum(axis=0)
        dist = to_segment[neighbours, np.arange(pixels.size)]  # (9, b)
        new = neighbours[np.argmin(dist, axis=0), np.arange(pixels.size)]
        moved = new != flat[pixels]
        if not moved.any():
            break  # converged: no border pixel moved
        where, at, old, new = pixels[moved], inside[moved], flat[pixels[moved]], new[moved]
        count -= np.bincount(old, minlength=k)
        count += np.bincount(new, minlength=k)
        for j, v in enumerate(values):
            sums[j] -= np.bincount(old, v[at], k)
            sums[j] += np.bincount(new, v[at], k)
        flat[where] = new
        marked[pixels] = True
        marked[(where[None, :] + offsets[:, None]).ravel()] = True
        mark[[0, -1], :] = mark[:, [0, -1]] = False  # the frame
        candidates = np.flatnonzero(marked)
        marked[candidates] = False
    return np.ascontiguousarray(padded[1:-1, 1:-1])
