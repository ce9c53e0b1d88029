"""Segmentation quality against a ground truth, and per-segment statistics.

Three measures of a labelling against the true materials (thesis section 5.4):

- :func:`adjusted_rand_index`: pixel-level agreement of the two partitions, invariant
  to the label ids (1 identical, about 0 for chance).
- :func:`segment_iou`: intersection over union of every true segment with its predicted
  segment after the optimal one-to-one matching (Hungarian algorithm).
- :func:`block_accuracy`: the thesis's block accuracy over non-overlapping w × w blocks,
  in its worst case (a block whose ground truth mixes materials is wrong) and its
  optimistic case (such a block is right); :func:`evaluate` gives it for the labels of
  a method that cuts blocks (given a window), the pixel measures for every method.

:func:`segment_statistics` summarises each segment of a result (size, mean Î, ρ, θ,
circular mean of φ, mean PCA features). Label ids may be any integers; nothing here
assumes they start at 0 or are contiguous.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import PolarsegError


def _check_pair(truth: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    truth, labels = np.asarray(truth), np.asarray(labels)
    if truth.shape != labels.shape:
        raise PolarsegError(f"ground truth is {truth.shape} but the labels are {labels.shape}")
    if truth.ndim != 2:
        raise PolarsegError(f"ground truth and labels must be 2-D images, got {truth.shape}")
    if truth.size == 0:
        raise PolarsegError("ground truth and labels are empty")
    for name, a in (("ground truth", truth), ("labels", labels)):
        if a.dtype.kind not in "biu":
            if a.dtype.kind != "f" or not np.all(np.isfinite(a)) or np.any(a != np.round(a)):
                raise PolarsegError(f"{name} must hold integer labels, got dtype {a.dtype}")
    return truth, labels


def _contingency(
    truth: np.ndarray, labels: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(true ids, predicted ids, counts[i, j] = pixels with truth i and label j)."""
    t_ids, t_inv = np.unique(truth.ravel(), return_inverse=True)
    p_ids, p_inv = np.unique(labels.ravel(), return_inverse=True)
    counts = np.bincount(
        t_inv.ravel() * p_ids.size + p_inv.ravel(), minlength=t_ids.size * p_ids.size
    )
    return t_ids, p_ids, counts.reshape(t_ids.size, p_ids.size)


def adjusted_rand_index(truth: np.ndarray, labels: np.ndarray) -> float:
    """Pixel-level adjusted Rand index of a labelling against the ground truth.

    Parameters
    ----------
    truth, labels : array (H, W) of int
        True materials and segment labels of the same pixels (any label ids).

    Returns
    -------
    float
        1 for the same partition, about 0 for a random one (can be negative).
    """
    from sklearn.metrics import adjusted_rand_score

    truth, labels = _check_pair(truth, labels)
    return float(adjusted_rand_score(truth.ravel(), labels.ravel()))


def segment_iou(
    truth: np.ndarray, labels: np.ndarray
) -> tuple[dict[int, float], float, dict[int, int | None]]:
    """Intersection over union of each true segment after optimal one-to-one matching.

    True and predicted segments are paired one-to-one so that the sum of the IoUs is
    largest (:func:`scipy.optimize.linear_sum_assignment`). A true segment left without
    a partner (fewer predicted segments than true ones) scores 0.

    Parameters
    ----------
    truth, labels : array (H, W) of int
        True materials and segment labels of the same pixels (any label ids).

    Returns
    -------
    per_segment : dict {true label: IoU}
        IoU = |T ∩ P| / |T ∪ P| of each true segment with its matched segment, in [0, 1].
    mean_iou : float
        Mean of ``per_segment`` over the true segments.
    matching : dict {true label: predicted label or None}
    """
    truth, labels = _check_pair(truth, labels)
    t_ids, p_ids, inter = _contingency(truth, labels)
    union = inter.sum(axis=1)[:, None] + inter.sum(axis=0)[None, :] - inter
    iou = inter / union
    from scipy.optimize import linear_sum_assignment  # start-up cost: when used

    rows, cols = linear_sum_assignment(iou, maximize=True)
    per = {int(t): 0.0 for t in t_ids}
    matching: dict[int, int | None] = {int(t): None for t in t_ids}
    for r, c in zip(rows, cols, strict=True):
        per[int(t_ids[r])] = float(iou[r, c])
        matching[int(t_ids[r])] = int(p_ids[c])
    return per, float(np.mean(list(per.values()))), matching


def block_accuracy(truth: np.ndarray, labels: np.ndarray, window: int) -> tuple[float, float]:
    """Block accuracy of thesis section 5.4, worst case and optimistic case.

    The image is cut into non-overlapping ``window`` × ``window`` blocks from the top-left
    corner; the remainder strips at the bottom and right (when the size is not a multiple
    of w) are ignored. A block's predicted label is its majority label (ties go to the
    smallest label id). A block whose ground truth holds more than one material is
    *mixed*: wrong in the worst case, right in the optimistic case. A *pure* block is
    right when its predicted label is the one matched to its true material, the
    one-to-one matching of true and predicted labels that makes the most pure blocks
    right (Hungarian algorithm on the block counts).

    Parameters
    ----------
    truth, labels : array (H, W) of int
        True materials and segment labels of the same pixels (any label ids).
    window : int
        Block side w in pixels, 1 <= w <= min(H, W).

    Returns
    -------
    worst_case, optimistic : float
        Shares of right blocks, in [0, 1]; ``worst_case <= optimistic``.
    """
    truth, labels = _check_pair(truth, labels)
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
        raise PolarsegError(f"window must be a positive integer, got {window!r}")
    h, w = truth.shape
    if window > h or window > w:
        raise PolarsegError(f"window size {window} is larger than the image ({h} x {w} pixels)")
    r, c = h // window, w // window
    t_ids, t_inv = np.unique(truth, return_inverse=True)
    p_ids, p_inv = np.unique(labels, return_inverse=True)

    def blocks(a: np.ndarray) -> np.ndarray:
        a = a.reshape(h, w)[: r * window, : c * window].reshape(r, window, c, window)
        return a.transpose(0, 2, 1, 3).reshape(r * c, window * window)

    tb, pb = blocks(t_inv), blocks(p_inv)
    n_blocks = tb.shape[0]
    pure = np.all(tb == tb[:, :1], axis=1)
    # majority label per block: counts of every label id per block, argmax = smallest tie
    k = p_ids.size
    offsets = np.arange(n_blocks)[:, None] * k
    counts = np.bincount((pb + offsets).ravel(), minlength=n_blocks * k).reshape(n_blocks, k)
    majority = np.argmax(counts, axis=1)
    # pure blocks per (true material, majority label); best one-to-one matching
    table = np.zeros((t_ids.size, k), dtype=np.int64)
    np.add.at(table, (tb[pure, 0], majority[pure]), 1)
    from scipy.optimize import linear_sum_assignment  # start-up cost: when used

    rows, cols = linear_sum_assignment(table, maximize=True)
    right = int(table[rows, cols].sum())
    n_mixed = int(n_blocks - np.count_nonzero(pure))
    return right / n_blocks, (right + n_mixed) / n_blocks


def evaluate(truth: np.ndarray, labels: np.ndarray, window: int | None = None) -> dict[str, Any]:
    """Every measure of a labelling against the ground truth, JSON-ready.

    Parameters
    ----------
    truth, labels : array (H, W) of int
        True materials and segment labels of the same pixels.
    window : int, optional
        Block side w (pixels) of :func:`block_accuracy`, for labels of a method that cuts
        the w × w block grid (the thesis method); None (a method without blocks): no
        block accuracy, the pixel-level measures only.

    Returns
    -------
    dict
        ``adjusted_rand_index``, ``iou_per_segment`` ({true label: IoU}), ``mean_iou``,
        ``matching`` ({true label: predicted label or None}), ``block_accuracy_worst``,
        ``block_accuracy_optimistic``, ``window`` (these three None without a window),
        ``n_true_segments``, ``n_predicted_segments``.
    """
    truth, labels = _check_pair(truth, labels)
    per, mean_iou, matching = segment_iou(truth, labels)
    worst = optimistic = None
    if window is not None:
        worst, optimistic = block_accuracy(truth, labels, window)
    return {
        "adjusted_rand_index": adjusted_rand_index(truth, labels),
        "iou_per_segment": per,
        "mean_iou": mean_iou,
        "matching": matching,
        "block_accuracy_worst": worst,
        "block_accuracy_optimistic": optimistic,
        "window": None if window is None else int(window),
        "n_true_segments": int(np.unique(truth).size),
        "n_predicted_segments": int(np.unique(labels).size),
    }


#: Columns of :func:`segment_statistics` (``segments.csv`` adds the material's name).
STATISTICS_COLUMNS = (
    "segment",
    "pixels",
    "area_fraction",
    "mean_intensity",
    "mean_dop",
    "mean_zenith_deg",
    "circular_mean_phase_deg",
    "mean_pca_1",
    "mean_pca_2",
    "mean_pca_3",
)


def _masked_means(values: np.ndarray, index: np.ndarray, weights: np.ndarray, k: int) -> np.ndarray:
    total = np.bincount(index, weights=weights, minlength=k)
    sums = np.bincount(index, weights=values * weights, minlength=k)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, sums / np.where(total > 0, total, 1), np.nan)


def segment_pca_means(
    k: int,
    block_labels: np.ndarray | None,
    features: np.ndarray | None,
    block_valid: np.ndarray | None,
) -> np.ndarray:
    """(k, 3) means of the first three PCA block features per segment (NaN where none)."""
    pca = np.full((k, 3), np.nan)
    if block_labels is not None and features is not None:
        bl = np.asarray(block_labels).ravel().astype(np.int64)
        f = np.asarray(features, dtype=np.float64).reshape(bl.size, -1)
        bw = np.ones(bl.size) if block_valid is None else np.asarray(block_valid, float).ravel()
        kb = max(k, int(bl.max()) + 1)
        for j in range(min(3, f.shape[1])):
            pca[:, j] = _masked_means(f[:, j], bl, bw, kb)[:k]
    return pca


def _pixel_means(
    maps: list[np.ndarray], index: np.ndarray, k: int, valid: np.ndarray | None
) -> list[np.ndarray]:
    """The mean of every flat map over each segment's pixels where every map is finite
    (and ``valid``), NaN for a segment with none; one count of those pixels, and no
    masked copies when every pixel is used."""
    ok = np.ones(index.size, dtype=bool)
    for v in maps:
        ok &= np.isfinite(v)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool).ravel()
    every = bool(ok.all())
    total = np.bincount(index, weights=None if every else ok.astype(np.float64), minlength=k)
    out = []
    for v in maps:
        sums = np.bincount(index, weights=v if every else np.where(ok, v, 0.0), minlength=k)
        with np.errstate(invalid="ignore", divide="ignore"):
            out.append(np.where(total > 0, sums / np.where(total > 0, total, 1), np.nan))
    return out


def segment_statistics(
    labels: np.ndarray,
    intensity: np.ndarray,
    dop: np.ndarray,
    zenith: np.ndarray,
    phase: np.ndarray,
    *,
    valid: np.ndarray | None = None,
    block_labels: np.ndarray | None = None,
    features: np.ndarray | None = None,
    block_valid: np.ndarray | None = None,
) -> list[dict[str, Any]]:
    """Per-segment statistics of a segmentation (one dict per segment, label order).

    Parameters
    ----------
    labels : array (H, W) of int
        Segment of every pixel (ids 0..K-1).
    intensity, dop, zenith, phase : array (H, W)
        Î (input units), ρ (0..1), θ and φ (radians; φ in [0, π)).
    valid : array (H, W) of bool, optional
        Pixels whose values count in the means (default all finite ones).
    block_labels : array (R, C) of int, optional
        Segment of every block; with ``features`` gives the mean PCA features.
    features : array (R*C, F), optional
        PCA block features (thesis section 4.3.3), row-major over the block grid.
    block_valid : array (R*C,) of bool, optional
        Blocks whose features count (default all).

    Returns
    -------
    list of dict
        Keys :data:`STATISTICS_COLUMNS`: ``pixels`` (all pixels of the segment),
        ``area_fraction`` (of the image), the means over its valid pixels of Î, ρ and θ
        (degrees), the circular mean of φ with period π (degrees in [0, 180):
        ½ atan2(mean sin 2φ, mean cos 2φ), the axial mean, since φ and φ + π are the same
        polariser phase), and the means of the first three PCA features over its blocks
        (NaN where the segment has no valid pixel or block, or fewer than 3 features).
    """
    labels = np.asarray(labels)
    k = segment_count(labels, intensity, dop, zenith, phase)
    index = labels.ravel().astype(np.int64)
    maps = [np.asarray(a, dtype=np.float64).ravel() for a in (intensity, dop, zenith)]
    phi = np.asarray(phase, dtype=np.float64).ravel()
    with np.errstate(invalid="ignore"):  # φ not finite: left out of the means
        maps += [np.sin(2 * phi), np.cos(2 * phi)]
    means = _pixel_means(maps, index, k, valid)
    pixels = np.bincount(index, minlength=k)
    pca = segment_pca_means(k, block_labels, features, block_valid)
    return statistics_rows(pixels, index.size, means, pca)


def segment_count(labels: np.ndarray, *maps: np.ndarray) -> int:
    """The number of segments k of :func:`segment_statistics`' ``labels`` (ids 0..k−1),
    after checking that they are non-negative and that every map has their shape."""
    shape = np.shape(labels)
    for name, a in zip(("intensity", "dop", "zenith", "phase"), maps, strict=True):
        if np.shape(a) != shape:
            raise PolarsegError(f"{name} is {np.shape(a)} but the labels are {shape}")
    if not np.size(labels):
        return 0
    if int(np.min(labels)) < 0:
        raise PolarsegError("segment labels must be non-negative")
    return int(np.max(labels)) + 1


def statistics_rows(
    pixels: np.ndarray, size: int, means: list[np.ndarray], pca: np.ndarray
) -> list[dict[str, Any]]:
    """The rows of :func:`segment_statistics` from each segment's pixel count, the image's
    ``size`` (pixels), the per-segment means of Î, ρ, θ (radians), sin 2φ and cos 2φ over
    the used pixels, and the (k, 3) PCA means."""
    i_mean, d_mean, z_mean, s, c = means
    phase_mean = np.mod(np.rad2deg(0.5 * np.arctan2(s, c)), 180.0)
    return [
        {
            "segment": i,
            "pixels": int(pixels[i]),
            "area_fraction": float(pixels[i] / size),
            "mean_intensity": float(i_mean[i]),
            "mean_dop": float(d_mean[i]),
            "mean_zenith_deg": float(np.rad2deg(z_mean[i])),
            "circular_mean_phase_deg": float(phase_mean[i]),
            "mean_pca_1": float(pca[i, 0]),
            "mean_pca_2": float(pca[i, 1]),
            "mean_pca_3": float(pca[i, 2]),
        }
        for i in range(len(pixels))
    ]
