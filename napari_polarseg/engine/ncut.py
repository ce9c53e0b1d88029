"""Recursive two-way normalized cuts (Shi & Malik), thesis section 4.4.1.

The relaxed Ncut problem (eq. 4.32) is the generalized eigenproblem (D − W) y = λ D y.
With z = D^½ y it becomes the ordinary symmetric problem D^−½ W D^−½ z = (1 − λ) z, so
the second-smallest generalized eigenvector is D^−½ times the eigenvector of the
second-*largest* eigenvalue of the normalized affinity. That is solved with
``scipy.sparse.linalg.eigsh`` (Lanczos, two eigenpairs) or, for small graphs, with
``scipy.linalg.eigh`` restricted to the two top eigenpairs.

The splitting point along y is the one with the lowest Ncut value (eq. 4.29) over *all*
thresholds between distinct values of y, found in one pass with cumulative sums.

Segments are split greedily: at each step the segment whose best bipartition has the
lowest Ncut is split, until the requested number of segments, an Ncut threshold, or the
minimum segment size stops it. The sequence of splits is cached, so asking for fewer or
more segments later costs nothing or only the extra splits.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sps
from scipy.sparse.linalg import ArpackNoConvergence, eigsh

from .errors import PolarsegError

#: Graphs up to this many nodes use a dense eigensolver; larger ones use Lanczos.
DENSE_EIGH_MAX = 300


def _subgraph(W, idx: np.ndarray):
    if sps.issparse(W):
        return W[idx][:, idx]
    return W[np.ix_(idx, idx)]


def fiedler_vector(W) -> np.ndarray:
    """Second-smallest generalized eigenvector y of (D − W) y = λ D y.

    Parameters
    ----------
    W : ndarray or sparse matrix (n, n)
        Symmetric non-negative affinity with positive degrees.
    """
    n = W.shape[0]
    d = np.asarray(W.sum(axis=1)).ravel()
    if np.any(d <= 0):
        raise PolarsegError("affinity has an isolated node (zero degree)")
    d_is = 1.0 / np.sqrt(d)
    if sps.issparse(W):
        M = sps.diags(d_is) @ W @ sps.diags(d_is)
    else:
        M = W * d_is[:, None] * d_is[None, :]
    z = None
    if n > DENSE_EIGH_MAX and n >= 4:
        v0 = np.random.default_rng(0).standard_normal(n)
        try:
            vals, vecs = eigsh(M, k=2, which="LA", v0=v0, tol=1e-8)
            z = vecs[:, np.argsort(vals)[0]]
        except ArpackNoConvergence:
            # A graph that has fallen apart (many near-isolated nodes) has a highly
            # degenerate top eigenvalue 1 where Lanczos stalls; solve it densely instead.
            z = None
    if z is None:
        dense = M.toarray() if sps.issparse(M) else M
        # full decomposition: the subset driver can drop vectors of repeated eigenvalues
        _, vecs = scipy.linalg.eigh(dense, driver="evd")
        z = vecs[:, n - 2]
    y = z * d_is
    # fix the sign so results are reproducible
    pivot = np.argmax(np.abs(y))
    return y if y[pivot] >= 0 else -y


def best_split(W, y: np.ndarray, min_size: int = 1) -> tuple[np.ndarray | None, float]:
    """Threshold of ``y`` with the lowest Ncut (eq. 4.29), subject to a minimum size.

    Returns (mask of the nodes at or below the threshold, Ncut value), or (None, inf)
    when no admissible split exists (too few nodes, or y constant).
    """
    n = y.size
    if n < 2 * min_size or n < 2:
        return None, np.inf
    order = np.argsort(y, kind="stable")
    ys = y[order]
    Ws = _subgraph(W, order)
    d = np.asarray(Ws.sum(axis=1)).ravel()
    if sps.issparse(Ws):
        lower = np.asarray(sps.tril(Ws, k=-1).sum(axis=1)).ravel()
        diag = Ws.diagonal()
    else:
        lower = np.tril(Ws, k=-1).sum(axis=1)
        diag = np.diagonal(Ws)
    # W(A_k, A_k) for the prefix A_k = first k nodes: add 2 * row-to-earlier + self loop
    within = np.cumsum(2.0 * lower + diag)
    assoc = np.cumsum(d)
    total = assoc[-1]
    cut = assoc - within
    k = np.arange(1, n + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ncut = cut / assoc + cut / (total - assoc)
    valid = (k >= min_size) & (k <= n - min_size) & (k < n)
    # only thresholds between distinct values of y can be realised
    gap = np.zeros(n, dtype=bool)
    scale = max(np.abs(ys).max(), 1e-300)
    gap[:-1] = (ys[1:] - ys[:-1]) > 1e-12 * scale
    valid &= gap & np.isfinite(ncut)
    if not valid.any():
        return None, np.inf
    kbest = int(np.argmin(np.where(valid, ncut, np.inf)))
    mask = np.zeros(n, dtype=bool)
    mask[order[: kbest + 1]] = True
    return mask, float(ncut[kbest])


def bipartition(W, min_size: int = 1) -> tuple[np.ndarray | None, float]:
    """Best two-way normalized cut of a graph: (mask of one side, Ncut value)."""
    if W.shape[0] < max(2, 2 * min_size):
        return None, np.inf
    y = fiedler_vector(W)
    return best_split(W, y, min_size)


@dataclass
class CutTree:
    """Greedy recursive normalized cuts on an affinity, extended lazily and cached.

    ``labels(k)`` returns the node labels after the first k − 1 splits (fewer if the
    threshold or the minimum size stops earlier); labels are numbered in order of first
    appearance along the nodes, so label 0 is the segment of node 0.
    """

    W: np.ndarray | sps.spmatrix
    min_size: int = 1
    threshold: float | None = None
    _segments: list[np.ndarray] = field(default_factory=list, init=False)
    _candidates: dict[int, tuple[np.ndarray | None, float]] = field(
        default_factory=dict, init=False
    )
    _history: list[np.ndarray] = field(default_factory=list, init=False)
    _ncut_values: list[float] = field(default_factory=list, init=False)
    _exhausted: bool = field(default=False, init=False)
    _next_id: int = field(default=0, init=False)
    _ids: list[int] = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        n = self.W.shape[0]
        if self.W.shape != (n, n):
            raise PolarsegError(f"affinity must be square, got shape {self.W.shape}")
        self._segments = [np.arange(n)]
        self._ids = [self._new_id()]
        self._history = [np.zeros(n, dtype=np.int32)]

    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id

    @property
    def ncut_values(self) -> list[float]:
        """Ncut value of each split made so far, in order."""
        return list(self._ncut_values)

    def _candidate(self, pos: int) -> tuple[np.ndarray | None, float]:
        sid = self._ids[pos]
        if sid not in self._candidates:
            idx = self._segments[pos]
            self._candidates[sid] = bipartition(_subgraph(self.W, idx), self.min_size)
        return self._candidates[sid]

    def _split_once(self) -> bool:
        best_pos, best_val = -1, np.inf
        for pos in range(len(self._segments)):
            mask, val = self._candidate(pos)
            if mask is not None and val < best_val:
                best_pos, best_val = pos, val
        if best_pos < 0 or (self.threshold is not None and best_val > self.threshold):
            self._exhausted = True
            return False
        mask, _ = self._candidates.pop(self._ids[best_pos])
        idx = self._segments[best_pos]
        self._segments[best_pos] = idx[mask]
        self._ids[best_pos] = self._new_id()
        self._segments.append(idx[~mask])
        self._ids.append(self._new_id())
        labels = np.empty(self.W.shape[0], dtype=np.int32)
        for lab, seg in enumerate(self._segments):
            labels[seg] = lab
        self._history.append(_first_appearance_order(labels))
        self._ncut_values.append(best_val)
        return True

    def labels(self, k: int) -> np.ndarray:
        """Node labels 0..k'−1 for k' = min(k, reachable) segments."""
        if k < 1:
            raise PolarsegError(f"number of segments must be >= 1, got {k}")
        while len(self._history) < k and not self._exhausted:
            self._split_once()
        return self._history[min(k, len(self._history)) - 1].copy()


def _first_appearance_order(labels: np.ndarray) -> np.ndarray:
    """Renumber labels 0, 1, … in order of first appearance."""
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(first)
    remap = np.empty(order.size, dtype=np.int32)
    remap[order] = np.arange(order.size, dtype=np.int32)
    uniq = np.unique(labels)
    return remap[np.searchsorted(uniq, labels)]


def recursive_ncut(
    W, n_segments: int, min_size: int = 1, threshold: float | None = None
) -> np.ndarray:
    """Labels of the graph's nodes after recursive two-way normalized cuts."""
    return CutTree(W, min_size=min_size, threshold=threshold).labels(n_segments)
