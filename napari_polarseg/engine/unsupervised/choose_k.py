"""The number of materials found by itself: model selection over k on node features.

:func:`estimate_k` clusters the nodes (superpixels) for every k of a range and scores
each partition by its **silhouette** (Rousseeuw 1987): for a node, a = mean distance to
the nodes of its own cluster, b = the smallest mean distance to the nodes of another
cluster, s = (b − a) / max(a, b); the score is the mean s over an area-weighted sample
of the nodes. The k with the largest score wins; its confidence is the margin of the
best score over the runner-up, relative to the best (0 = a tie, 1 = every other k
scores ≤ 0).

Measured (``benchmarks/evaluate_unsupervised.py``, the superpixel node features of the
default method, k in 2..6, against the true number of classes): the silhouette found
the right k on 6 of the 16 development renders and real frames and was within ±1 on 11;
the Davies–Bouldin index 4 and 8; Calinski–Harabasz 3 and 5; the BIC of a Gaussian
mixture always chose the largest k (the node features are not Gaussian blobs).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..errors import PolarsegError
from .kmeans import weighted_kmeans

#: The k tried when none is given.
K_RANGE = (2, 3, 4, 5, 6)
#: Nodes sampled (with probability ∝ weight) for the silhouette: O(sample²) distances.
SILHOUETTE_SAMPLE = 3000


def _kmeans_labels(features: np.ndarray, weights: np.ndarray) -> Callable[[int], np.ndarray]:
    """Node labels of area-weighted k-means (seeded) for a given k."""
    return lambda k: weighted_kmeans(features, k, weights).labels


def estimate_k(
    features: np.ndarray,
    weights: np.ndarray | None = None,
    k_range: Sequence[int] = K_RANGE,
    cluster: Callable[[int], np.ndarray] | None = None,
    seed: int = 0,
    tolerance: float = 0.0,
) -> tuple[int, float, dict[int, float]]:
    """(k, confidence, scores): the number of clusters with the best silhouette, or the
    fewest whose silhouette comes within ``tolerance`` of it.

    Parameters
    ----------
    features : array (n, c)
        One row per node (a superpixel's projected features).
    weights : array (n,), optional
        Node weights (pixels per superpixel); every node counts once when None.
    k_range : sequence of int
        The k to try (each ≥ 2; those ≥ n are skipped).
    cluster : callable(k) -> array (n,) of int, optional
        The clustering scored for each k (the method's own); area-weighted k-means
        when None.
    seed : int
        Seed of the node sample.
    tolerance : float
        The smallest k whose score is at least best − ``tolerance`` × |best| wins
        (parsimony: fewer materials when more explain the features hardly better);
        0 = the best score's k.

    Returns
    -------
    k : int
        The k chosen (1 when fewer than 3 nodes or no k could be scored).
    confidence : float
        (its score − the best other k's) / its score, in [0, 1] (1 when only one k
        was scored or every other k scores ≤ 0; 0 when another k scores as well or
        better).
    scores : dict k -> float
        The silhouette of every k tried (−1 for a partition with one cluster or with
        fewer than k).
    """
    x = np.asarray(features, dtype=float)
    if x.ndim != 2:
        raise PolarsegError(f"features must be (n, c), got shape {x.shape}")
    n = x.shape[0]
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    ks = sorted({int(k) for k in k_range if 2 <= int(k) < n})
    if n < 3 or not ks or x.shape[1] == 0:
        return 1, 0.0, {}
    # Imported here: scikit-learn is most of the start-up, and a run with k given
    # never needs it.
    from sklearn.metrics import silhouette_score

    cluster = cluster or _kmeans_labels(x, w)
    rng = np.random.default_rng(seed)
    sample = rng.choice(n, min(n, SILHOUETTE_SAMPLE), replace=True, p=w / w.sum())
    scores: dict[int, float] = {}
    for k in ks:
        full = np.asarray(cluster(k))
        labels = full[sample]
        # a clustering into k that fills fewer than k clusters (a cluster emptied by the
        # smoothing of the posteriors) is a smaller k's partition again, not a k of its own
        if np.unique(full).size < k or np.unique(labels).size < 2:
            scores[k] = -1.0
        else:
            scores[k] = float(silhouette_score(x[sample], labels))
    best = max(scores.values())
    chosen = min(k for k, v in scores.items() if v >= best - float(tolerance) * abs(best))
    if len(scores) < 2:
        return chosen, 1.0, scores
    own = scores[chosen]
    other = max(v for k, v in scores.items() if k != chosen)
    confidence = 1.0 if other <= 0 else (own - other) / max(own, 1e-12)
    return chosen, float(min(max(confidence, 0.0), 1.0)), scores


#: A margin below this share of the chosen k's silhouette is called a close call.
CLOSE_CALL = 0.05


def choice_text(record: dict) -> str:
    """What the number of segments found by itself was and how sure, in words, from a
    method's record (``k``, ``k_scores``: silhouette per k as text keys,
    ``k_tolerance``); "" when k was given. The chosen k's silhouette against the best
    other k's: a margin under :data:`CLOSE_CALL` of it, or a k chosen by the tolerance
    over a better-scoring one, is a close call."""
    scores = {int(j): float(s) for j, s in (record.get("k_scores") or {}).items()}
    k = record.get("k")
    if not record.get("k_found") or k not in scores:
        return ""
    tried = f"{min(scores)}–{max(scores)}" if len(scores) > 1 else str(k)
    head = f"{k} segments found by itself (k in {tried}, by the silhouette"
    others = {j: s for j, s in scores.items() if j != k}
    if not others:
        return f"{head} {scores[k]:.2f})"
    j = max(others, key=others.get)
    own, other = scores[k], others[j]
    if other > own:
        tolerance = float(record.get("k_tolerance", 0.0))
        return (
            f"{head}: the fewest within {tolerance:.0%} of the best, {own:.2f} against "
            f"{other:.2f} for k = {j}; a close call)"
        )
    margin = (own - other) / max(abs(own), 1e-12)
    verdict = "a close call" if margin < CLOSE_CALL else f"{margin:.0%} ahead"
    return f"{head} {own:.2f}; next k = {j} at {other:.2f}, {verdict})"
