"""Recursive two-way normalized cuts (Shi & Malik), thesis section 4.4.1.

The relaxed Ncut problem (eq. 4.32) is the generalized eigenproblem (D − W) y = λ D y.
With z = D^½ y it becomes the ordinary symmetric problem N z = λ z for the normalized
Laplacian N = I − D^−½ W D^−½, whose smallest eigenvector is known, u = D^½ 1 (λ = 0), so
the second-smallest generalized eigenvector is D^−½ times the smallest eigenvector of N
orthogonal to u.

Eigensolvers
------------
- Up to :data:`DENSE_EIGH_MAX` nodes: ``scipy.linalg.eigh`` of the whole normalized
  affinity (exact, and robust to repeated eigenvalues).
- Larger dense W: LOBPCG (``scipy.sparse.linalg.lobpcg``) on N with the constraint u, a
  Jacobi preconditioner 1 / diag(N) and residual tolerance :data:`EIG_TOL`, applying W
  as an operator (the normalized matrix is never formed; float32 products from
  :data:`FLOAT32_MIN_NODES` nodes). Each product reads all n² entries, so the number of
  products is what counts, and the preconditioner is what keeps it low on the thesis's
  own affinity (s = 1 with 10–20 PCA components): that graph has fallen apart into
  nearly isolated blocks, diag(N)_i = 1 − W_ii/d_i is tiny exactly there, and the
  Fiedler vectors live there. On the 4,752-block reference image plain Lanczos
  (``eigsh``) needs ~400 products per cut where LOBPCG needs ~70.
- Sparse W (k nearest neighbours, spatial neighbourhoods): Lanczos (``eigsh``, two
  eigenpairs of D^−½ W D^−½, tolerance EIG_TOL / 10). Products are cheap there and
  LOBPCG's per-iteration overhead dominates (4 s against 0.5 s on a 19,584-block
  camera frame). pyamg is not used: Lanczos already takes well under a second.
- Each falls back on the other, and finally on a dense solve (up to
  :data:`DENSE_FALLBACK_MAX` nodes).
- A :class:`CutTree` can be warm-started from the Fiedler vectors of an earlier tree on
  the same blocks (the pipeline does this when only the affinity changed, e.g. its
  scale): the solve for a segment with the same blocks starts from the old vector
  (on the reference image, s = 1 → 2: ~60 instead of ~90 products).

The splitting point along y is the one with the lowest Ncut value (eq. 4.29) over *all*
thresholds between distinct values of y, found in one pass with cumulative sums.

Segments are split greedily: at each step the segment whose best bipartition has the
lowest Ncut is split, until the requested number of segments, an Ncut threshold, or the
minimum segment size stops it. The sequence of splits is cached, so asking for fewer or
more segments later costs nothing or only the extra splits.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sps
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh, lobpcg

from .errors import PolarsegError

#: Graphs up to this many nodes use a dense eigensolver; larger ones are iterative.
DENSE_EIGH_MAX = 300
#: Residual tolerance ‖N z − λ z‖ (unit z) of the iterative eigensolver.
EIG_TOL = 1e-6
#: Iteration cap of LOBPCG before falling back to Lanczos.
LOBPCG_MAXITER = 400
#: Dense graphs from this many nodes are multiplied in float32 (see _operator_matrix).
FLOAT32_MIN_NODES = 2_000
#: Largest graph the last-resort dense eigendecomposition is tried on.
DENSE_FALLBACK_MAX = 12_000


def _subgraph(W, idx: np.ndarray):
    """W restricted to the nodes ``idx`` (sorted), as a copy.

    A dense matrix is gathered by runs of consecutive indices when there are few (a cut
    that peels off a handful of nodes leaves long runs: plain slice copies), else by
    rows then columns (2-D fancy indexing with ``np.ix_`` is 2–3 times slower).
    """
    if sps.issparse(W):
        return W[idx][:, idx]
    breaks = np.flatnonzero(np.diff(idx) != 1) + 1
    if breaks.size > 64:
        return W[idx][:, idx]
    starts = np.concatenate([[0], breaks])
    stops = np.concatenate([breaks, [idx.size]])
    rows = W[idx]
    out = np.empty((idx.size, idx.size), dtype=W.dtype)
    for a, b in zip(starts, stops, strict=True):
        out[:, a:b] = rows[:, idx[a] : idx[a] + (b - a)]
    return out


def _degrees(W) -> np.ndarray:
    d = np.asarray(W.sum(axis=1), dtype=float).ravel()
    if np.any(d <= 0):
        raise PolarsegError("affinity has an isolated node (zero degree)")
    return d


def _diagonal(W) -> np.ndarray:
    return np.asarray(W.diagonal(), dtype=float)


def _operator_matrix(W):
    """The matrix the iterative eigensolvers multiply with.

    A dense W of :data:`FLOAT32_MIN_NODES` nodes or more is multiplied as a float32 copy:
    the products are memory-bound (one pass over n² values each), so they take half the
    time, and float32 round-off (~1e-7) is a hundred times below :data:`EIG_TOL`. Degrees,
    the split search and the Ncut values stay float64.
    """
    if not sps.issparse(W) and W.shape[0] >= FLOAT32_MIN_NODES:
        return np.asarray(W, dtype=np.float32)
    return W


def _scaled_product(Wop, d_is: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """x ↦ D^−½ W D^−½ x for vectors and blocks of vectors, in float64."""

    def apply(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x)
        s = d_is if x.ndim == 1 else d_is[:, None]
        y = np.asarray(Wop @ (s * x).astype(Wop.dtype, copy=False), dtype=float)
        return s * y

    return apply


def _laplacian_operator(Wop, d_is: np.ndarray) -> LinearOperator:
    """N = I − D^−½ W D^−½ as an operator on vectors and blocks of vectors."""
    n = Wop.shape[0]
    product = _scaled_product(Wop, d_is)

    def apply(x: np.ndarray) -> np.ndarray:
        return np.asarray(x) - product(x)

    return LinearOperator((n, n), matvec=apply, matmat=apply, dtype=float)


def _start_vector(n: int, d: np.ndarray, start: np.ndarray | None) -> np.ndarray:
    """Starting z = D^½ y for the iterative solvers: ``start`` (a y vector) or random."""
    rng = np.random.default_rng(0)
    x = rng.standard_normal(n)
    if start is not None:
        z0 = np.asarray(start, dtype=float).ravel() * np.sqrt(d)
        # a little noise keeps it from lying in the constraint space
        x = z0 + 1e-3 * np.linalg.norm(z0) / np.sqrt(n) * x
    return x


def _lobpcg_fiedler(Wop, W, d: np.ndarray, start: np.ndarray | None) -> np.ndarray:
    """Smallest eigenvector z of N orthogonal to u = D^½ 1 by LOBPCG; raises if it fails."""
    n = W.shape[0]
    d_is = 1.0 / np.sqrt(d)
    u = np.sqrt(d)[:, None] / np.sqrt(d.sum())
    diag = np.maximum(1.0 - _diagonal(W) / d, 1e-8)

    def jacobi(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x)
        return x / (diag if x.ndim == 1 else diag[:, None])

    precond = LinearOperator((n, n), matvec=jacobi, matmat=jacobi, dtype=float)
    op = _laplacian_operator(Wop, d_is)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        vals, vecs = lobpcg(
            op,
            _start_vector(n, d, start)[:, None],
            M=precond,
            Y=u,
            tol=EIG_TOL,
            maxiter=LOBPCG_MAXITER,
            largest=False,
        )
    z = vecs[:, 0]
    resid = np.linalg.norm(op @ z - vals[0] * z)
    if not np.isfinite(resid) or resid > 10 * EIG_TOL * np.linalg.norm(z):
        raise ArpackNoConvergence("LOBPCG did not converge", vals, vecs)
    return z


def _lanczos_fiedler(Wop, d: np.ndarray, start: np.ndarray | None, tol: float) -> np.ndarray:
    """Second eigenvector z of D^−½ W D^−½ by Lanczos; raises ArpackNoConvergence."""
    n = Wop.shape[0]
    product = _scaled_product(Wop, 1.0 / np.sqrt(d))
    op = LinearOperator((n, n), matvec=lambda x: product(np.ravel(x)), dtype=float)
    vals, vecs = eigsh(op, k=2, which="LA", v0=_start_vector(n, d, start), tol=tol)
    return vecs[:, np.argsort(vals)[0]]


def _dense_fiedler(W, d: np.ndarray) -> np.ndarray:
    """Second eigenvector z of D^−½ W D^−½ from a full dense eigendecomposition."""
    n = W.shape[0]
    if n > DENSE_FALLBACK_MAX:
        raise PolarsegError(
            f"the eigensolvers did not converge on a {n}-block graph; "
            "try a larger window or a larger affinity scale"
        )
    d_is = 1.0 / np.sqrt(d)
    dense = W.toarray() if sps.issparse(W) else np.asarray(W, dtype=float)
    M = dense * d_is[:, None] * d_is[None, :]
    # full decomposition: the subset driver can drop vectors of repeated eigenvalues
    _, vecs = scipy.linalg.eigh(M, driver="evd")
    return vecs[:, max(n - 2, 0)]


def _fix_sign(y: np.ndarray) -> np.ndarray:
    pivot = np.argmax(np.abs(y))
    return y if y[pivot] >= 0 else -y


def fiedler_vector(W, start: np.ndarray | None = None) -> np.ndarray:
    """Second-smallest generalized eigenvector y of (D − W) y = λ D y (thesis eq. 4.32).

    Sign fixed so that the entry of largest magnitude is positive. Solvers: module
    docstring (dense ``eigh`` for small graphs; LOBPCG for large dense W, Lanczos for
    sparse W, each falling back on the other and finally on a dense solve).

    Parameters
    ----------
    W : ndarray or sparse matrix (n, n)
        Symmetric non-negative affinity with positive degrees.
    start : ndarray (n,), optional
        Starting guess (a y vector, e.g. from an earlier affinity) for the iterative
        solvers.
    """
    n = W.shape[0]
    d = _degrees(W)
    z = None
    if n > DENSE_EIGH_MAX:
        Wop = _operator_matrix(W)
        if sps.issparse(W):
            solvers = (
                lambda: _lanczos_fiedler(Wop, d, start, EIG_TOL / 10),
                lambda: _lobpcg_fiedler(Wop, W, d, start),
            )
        else:
            solvers = (
                lambda: _lobpcg_fiedler(Wop, W, d, start),
                lambda: _lanczos_fiedler(Wop, d, start, 1e-8),
            )
        for solve in solvers:
            try:
                z = solve()
                break
            except (ArpackNoConvergence, np.linalg.LinAlgError, ValueError):
                # a graph that has fallen apart (many near-isolated nodes) has a highly
                # degenerate spectrum where an iterative solver can stall
                continue
    if z is None:
        z = _dense_fiedler(W, d)
    return _fix_sign(z / np.sqrt(d))


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
    if sps.issparse(W):
        Ws = _subgraph(W, order)
        d = np.asarray(Ws.sum(axis=1)).ravel()
        lower = np.asarray(sps.tril(Ws, k=-1).sum(axis=1)).ravel()
        diag = Ws.diagonal()
    else:
        W = np.asarray(W)
        d = W.sum(axis=1)[order]
        diag = np.diagonal(W)[order]
        lower = _lower_prefix_sums(W, order)
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


def _lower_prefix_sums(W: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Σ_{q < p} W[order[p], order[q]] for every position p of the sorted order.

    Row i of W contributes its entries to nodes ranked before it: a masked row sum,
    computed in row chunks on the cores (no permuted n × n copy, no triangle mask).
    """
    from .harmonics import run_chunks

    n = order.size
    rank = np.empty(n, dtype=np.intp)
    rank[order] = np.arange(n)
    sums = np.empty(n)

    def work(a: int, b: int) -> None:
        before = rank[None, :] < rank[a:b, None]
        sums[a:b] = np.where(before, W[a:b], 0.0).sum(axis=1)

    step = max(1, 2**18 // max(n, 1))
    run_chunks([(a, min(n, a + step)) for a in range(0, n, step)], work, n * n // 8)
    return sums[order]


def _bipartition(
    W, min_size: int = 1, start: np.ndarray | None = None
) -> tuple[np.ndarray | None, float, np.ndarray | None]:
    if W.shape[0] < max(2, 2 * min_size):
        return None, np.inf, None
    y = fiedler_vector(W, start)
    mask, value = best_split(W, y, min_size)
    return mask, value, y


def bipartition(W, min_size: int = 1) -> tuple[np.ndarray | None, float]:
    """Best two-way normalized cut of a graph: (mask of one side, Ncut value)."""
    mask, value, _ = _bipartition(W, min_size)
    return mask, value


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
    _candidates: dict[int, tuple[np.ndarray | None, float, np.ndarray | None]] = field(
        default_factory=dict, init=False
    )
    warm: dict[bytes, np.ndarray] | None = None
    _vectors: dict[bytes, np.ndarray] = field(default_factory=dict, init=False)
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

    def _candidate(self, pos: int) -> tuple[np.ndarray | None, float, np.ndarray | None]:
        sid = self._ids[pos]
        if sid not in self._candidates:
            idx = self._segments[pos]
            sub = self.W if idx.size == self.W.shape[0] else _subgraph(self.W, idx)
            key = idx.tobytes()
            start = None if self.warm is None else self.warm.get(key)
            mask, value, ys = _bipartition(sub, self.min_size, start)
            if ys is not None:
                self._vectors[key] = ys
            self._candidates[sid] = (mask, value, ys)
        return self._candidates[sid]

    def fiedler_vectors(self) -> dict[bytes, np.ndarray]:
        """Fiedler vector of every segment solved so far, keyed by its node indices' bytes.

        Pass it as ``warm`` to a new tree on the same nodes (e.g. after the affinity scale
        changed) to start each identical segment's eigensolve from the old vector.
        """
        return dict(self._vectors)

    def _split_once(self) -> bool:
        best_pos, best_val = -1, np.inf
        for pos in range(len(self._segments)):
            mask, val, _ = self._candidate(pos)
            if mask is not None and val < best_val:
                best_pos, best_val = pos, val
        if best_pos < 0 or (self.threshold is not None and best_val > self.threshold):
            self._exhausted = True
            return False
        mask, _, _ = self._candidates.pop(self._ids[best_pos])
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
