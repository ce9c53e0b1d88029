"""Weighted k-means (Lloyd's algorithm, greedy k-means++ seeding) on a few thousand nodes.

Minimises the weighted within-cluster sum of squares Σᵢ wᵢ ‖xᵢ − c_{l(i)}‖² (the k-means
inertia, in the units of x squared) by alternating assignment to the nearest centre and
weighted centre means, from ``n_init`` seedings; the lowest inertia wins.

Written by hand, not taken from scikit-learn, for one reason: importing
``sklearn.cluster`` in a fresh process costs a large share of the default method's time
budget (``docs/performance.md``), for a problem of a few thousand superpixels in a few
dimensions that numpy solves in milliseconds; scipy's ``kmeans2`` takes no sample
weights (the superpixels' areas). The seeding and the stopping rule follow
scikit-learn's ``KMeans`` (greedy k-means++ with 2 + ⌊ln k⌋ trials per centre; stop when
the squared shift of the centres is at most ``tol`` × the mean variance of the
features), and ``tests/test_kmeans.py`` checks the result against it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import PolarsegError


@dataclass(frozen=True)
class KMeansFit:
    """Result of :func:`weighted_kmeans`.

    Attributes
    ----------
    labels : ndarray (n,) int32
        Cluster of every sample, 0 … k − 1.
    centres : ndarray (k, d) float64
        Weighted mean of each cluster.
    inertia : float
        Σ wᵢ ‖xᵢ − c_{l(i)}‖² at the returned centres (units of x squared × weight).
    """

    labels: np.ndarray
    centres: np.ndarray
    inertia: float


def squared_distances(x: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """‖xᵢ − c_j‖², (n, k), clipped at 0 (expanded form, one matrix product)."""
    d = (x * x).sum(axis=1)[:, None] - 2.0 * x @ centres.T + (centres * centres).sum(axis=1)
    return np.maximum(d, 0.0)


def kmeans_plus_plus(
    x: np.ndarray, k: int, weight: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """k initial centres (k, d) by greedy k-means++ (Arthur & Vassilvitskii 2007).

    Each new centre is drawn with probability ∝ wᵢ D(xᵢ)², D the distance to the
    nearest centre so far; of 2 + ⌊ln k⌋ such draws the one that lowers the weighted
    potential Σ wᵢ D² most is kept.
    """
    n = x.shape[0]
    trials = 2 + int(math.log(k))
    centres = np.empty((k, x.shape[1]))
    p = weight / weight.sum()
    centres[0] = x[rng.choice(n, p=p)]
    closest = squared_distances(x, centres[:1])[:, 0]
    for c in range(1, k):
        potential = weight * closest
        total = potential.sum()
        if total <= 0:  # every sample sits on a centre: any sample will do
            picks = rng.choice(n, size=trials)
        else:
            picks = rng.choice(n, size=trials, p=potential / total)
        cand = np.minimum(closest[:, None], squared_distances(x, x[picks]))  # (n, trials)
        best = int(np.argmin(weight @ cand))
        centres[c] = x[picks[best]]
        closest = cand[:, best]
    return centres


def lloyd(
    x: np.ndarray,
    centres: np.ndarray,
    weight: np.ndarray,
    max_iter: int,
    tol: float,
) -> KMeansFit:
    """Lloyd's iterations from ``centres`` until their squared shift ≤ ``tol`` (absolute)
    or ``max_iter``; an emptied cluster keeps its previous centre."""
    k = centres.shape[0]
    for _ in range(max_iter):
        labels = np.argmin(squared_distances(x, centres), axis=1)
        mass = np.bincount(labels, weights=weight, minlength=k)
        sums = np.stack(
            [np.bincount(labels, weights=weight * x[:, j], minlength=k) for j in range(x.shape[1])],
            axis=1,
        )
        new = np.where(mass[:, None] > 0, sums / np.maximum(mass, 1e-300)[:, None], centres)
        shift = float(((new - centres) ** 2).sum())
        centres = new
        if shift <= tol:
            break
    d = squared_distances(x, centres)
    labels = np.argmin(d, axis=1)
    inertia = float(weight @ d[np.arange(x.shape[0]), labels])
    return KMeansFit(labels.astype(np.int32), centres, inertia)


def weighted_kmeans(
    x: np.ndarray,
    k: int,
    weight: np.ndarray | None = None,
    n_init: int = 10,
    seed: int = 0,
    max_iter: int = 300,
    tol: float = 1e-4,
) -> KMeansFit:
    """Weighted k-means of the rows of ``x`` (n, d) into ``k`` clusters (module docstring).

    Parameters
    ----------
    x : array (n, d)
        Samples (finite).
    k : int
        Number of clusters, 1 ≤ k ≤ n.
    weight : array (n,), optional
        Non-negative sample weights, not all 0 (default: all 1).
    n_init : int
        Seedings tried; the fit of lowest inertia is returned.
    seed : int
        Seed of the random draws (deterministic for a given seed).
    max_iter : int
        Most Lloyd iterations per seeding.
    tol : float
        Stop when the squared shift of the centres is at most ``tol`` × the mean
        variance of the columns of ``x`` (scikit-learn's convention).

    Raises
    ------
    PolarsegError
        k outside [1, n], x not 2-D or not finite, or weights negative or all zero.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or not np.isfinite(x).all():
        raise PolarsegError(f"k-means needs a finite 2-D array, got shape {x.shape}")
    n = x.shape[0]
    if not 1 <= int(k) <= n:
        raise PolarsegError(f"k-means needs 1 <= k <= {n} samples, got k = {k}")
    w = np.ones(n) if weight is None else np.asarray(weight, dtype=np.float64)
    if w.shape != (n,) or (w < 0).any() or w.sum() <= 0:
        raise PolarsegError("k-means weights must be one non-negative value per sample")
    rng = np.random.default_rng(seed)
    abs_tol = tol * float(np.mean(np.var(x, axis=0))) if n > 1 else 0.0
    best: KMeansFit | None = None
    for _ in range(max(1, int(n_init))):
        fit = lloyd(x, kmeans_plus_plus(x, int(k), w, rng), w, max_iter, abs_tol)
        if best is None or fit.inertia < best.inertia:
            best = fit
    assert best is not None
    return best
