"""Recursive two-way normalized cuts (Shi & Malik), thesis section 4.4.1.

The relaxed Ncut problem (eq. 4.32) is the generalized eigenproblem (D − W) y = λ D y.
With z = D^½ y it becomes the ordinary symmetric problem N z = λ z for the normalized
Laplacian N = I − D^−½ W D^−½, whose smallest eigenvector is known, u = D^½ 1 (λ = 0), so
the second-smallest generalized eigenvector is D^−½ times the smallest eigenvector of N
orthogonal to u.

The eigensolvers (dense ``eigh``, block LOBPCG, Lanczos, and their fallbacks) are
those of :mod:`.eigensolver`; the dense affinity and its segments, :mod:`.dense_graph`.

Bounded work, isolated blocks, Cancel
-------------------------------------
- Every eigensolve of a segment may make at most ``max_products`` products with the
  affinity (:data:`MAX_CUT_PRODUCTS` by default; a product is one vector, so a block
  LOBPCG iteration with four active vectors makes four), all solvers of the solve
  together; Lanczos, when it goes first, may take
  :data:`~napari_polarseg.engine.graph.eigensolver.LANCZOS_SHARE` of them. When
  the budget is spent, the cut is made along the best vector the block LOBPCG has (its
  lowest Ritz vector) and :meth:`CutTree.cut_limits` counts the solve as capped. The
  cap is set well above the largest solves of normal inputs, so that it only stops
  pathological graphs; the time bound is the cap times a product's cost (both
  measured: docs/performance.md, "Measurements behind the code").
- Isolated blocks: a block of a segment that keeps all but less than
  :data:`ISOLATED_NCUT` of its degree to itself has a singleton cut below what an
  iterative solver resolves (its residual tolerance is :data:`EIG_TOL`): many
  eigenvalues lie below the tolerance, and the solver may return any mixture of their
  vectors. Above :data:`DENSE_EIGH_MAX` nodes such a segment is not solved at all: its
  candidate split peels off its most isolated block (the exact minimum of the singleton
  Ncut values, what ``eigh`` finds on such graphs), counted as ``isolated_skipped``.
  Not with ``min_size`` > 1, where a single block cannot be split off; the capped
  solve then decides. Small graphs keep the exact ``eigh`` (on the bundled scenes at
  the thesis scale it sometimes prefers a few-block segment to the most isolated block).
- Cancel: ``labels(k, cancel=...)`` and ``prefetch(cancel=...)`` call ``cancel()``
  before every product and raise :class:`~napari_polarseg.engine.errors.Cancelled`
  when it returns True (a product takes milliseconds, so a cut stops within a few);
  the tree stays consistent (the interrupted solve is simply not kept).
- A :class:`CutTree` can be warm-started from the eigenvectors of an earlier tree on
  the same blocks (the pipeline does this when the affinity changed but not the block
  grid, e.g. its scale or the refractive index): each segment's solve also starts from
  the vectors of the smallest old segment containing it, restricted to it (fewer
  products than a cold start).

The splitting point along y is the one with the lowest Ncut value (eq. 4.29) over *all*
thresholds between distinct values of y, found in one pass with cumulative sums.

Segments are split greedily: at each step the segment whose best bipartition has the
lowest Ncut is split, until the requested number of segments, an Ncut threshold, or the
minimum segment size stops it. The sequence of splits is cached, so asking for fewer or
more segments later costs nothing or only the extra splits; :meth:`CutTree.prefetch`
solves the next split's candidates ahead (the plugin does it in idle time).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sps

from ..chunks import chunk_bounds, run_chunks
from ..errors import PolarsegError
from .budget import MAX_CUT_PRODUCTS, Budget, check_products
from .dense_graph import COPY_MAX_FRACTION, DenseGraph, Segment, degrees, diagonal, subgraph
from .eigensolver import DENSE_EIGH_MAX, EIG_TOL, fix_sign, segment_vectors, solve_fiedler

#: A node is isolated when less than this share of its degree leaves it: its singleton
#: cut is below the resolution of the iterative eigensolvers (:data:`EIG_TOL`).
ISOLATED_NCUT = EIG_TOL


def best_split(W, y: np.ndarray, min_size: int = 1) -> tuple[np.ndarray | None, float]:
    """Threshold of ``y`` with the lowest Ncut (eq. 4.29), subject to a minimum size.

    Returns (mask of the nodes at or below the threshold, Ncut value), or (None, inf)
    when no admissible split exists (too few nodes, or y constant).
    """
    n = y.size
    if n < 2 * min_size or n < 2:
        return None, np.inf
    order = np.argsort(y, kind="stable")
    if sps.issparse(W):
        Ws = subgraph(W, order)
        d = np.asarray(Ws.sum(axis=1)).ravel()
        lower = np.asarray(sps.tril(Ws, k=-1).sum(axis=1)).ravel()
        diag = Ws.diagonal()
    else:
        W = np.asarray(W)
        d = W.sum(axis=1, dtype=np.float64)[order]
        diag = np.diagonal(W)[order]
        lower = lower_prefix_sums(W, order)
    return _split_from_sums(y, order, d, diag, lower, min_size)


def _segment_split(seg: Segment, y: np.ndarray, min_size: int) -> tuple[np.ndarray | None, float]:
    """:func:`best_split` of a dense segment, reading its rows from the whole matrix."""
    n = y.size
    if n < 2 * min_size or n < 2:
        return None, np.inf
    order = np.argsort(y, kind="stable")
    lower = lower_prefix_sums(seg.W, order, None if seg.whole else seg.idx)
    return _split_from_sums(y, order, seg.d[order], seg.diag[order], lower, min_size)


def _split_from_sums(
    y: np.ndarray,
    order: np.ndarray,
    d: np.ndarray,
    diag: np.ndarray,
    lower: np.ndarray,
    min_size: int,
) -> tuple[np.ndarray | None, float]:
    """Best threshold from sorted degrees, self loops and lower prefix sums (eq. 4.29)."""
    n = y.size
    ys = y[order]
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


def lower_prefix_sums(
    W: np.ndarray, order: np.ndarray, idx: np.ndarray | None = None
) -> np.ndarray:
    """Σ_{q < p} W_s[order[p], order[q]] for every position p of the sorted order.

    W_s is W, or W[idx][:, idx] when ``idx`` is given (read through the rows of W, no
    copy: nodes outside the segment rank last and are never "earlier"). Row i of W_s
    contributes its entries to nodes ranked before it: a masked row sum, computed in row
    chunks on the cores (no permuted n × n copy, no triangle mask).
    """
    m, n = order.size, W.shape[0]
    nodes = np.arange(m) if idx is None else idx
    rank = np.full(n, m, dtype=np.intp)
    rank[nodes[order]] = np.arange(m)
    # most of W's rows: read all of them as contiguous views (the few others are summed
    # and dropped), rather than gathering the segment's rows into copies
    rows = np.arange(n) if m >= COPY_MAX_FRACTION * n else nodes
    sums = np.empty(rows.size)

    def work(a: int, b: int) -> None:
        part = rows[a:b]
        contiguous = part[-1] - part[0] == b - a - 1
        block = W[part[0] : part[-1] + 1] if contiguous else W[part]
        before = rank[None, :] < rank[part, None]
        # (np.sum(..., where=before) reads the same but took twice as long)
        sums[a:b] = np.where(before, block, block.dtype.type(0)).sum(axis=1, dtype=np.float64)

    step = max(1, 2**20 // max(n, 1))  # rows per chunk: ~8 MB of float64
    run_chunks(chunk_bounds(rows.size, step), work, rows.size * n // 8)
    if rows.size != m:
        sums = sums[nodes]
    return sums[order]


def _bipartition(
    W, min_size: int = 1, start: np.ndarray | None = None, budget: Budget | None = None
) -> tuple[np.ndarray | None, float, np.ndarray | None]:
    if W.shape[0] < max(2, 2 * min_size):
        return None, np.inf, None
    y = solve_fiedler(W, start, budget or Budget(MAX_CUT_PRODUCTS))
    mask, value = best_split(W, y, min_size)
    return mask, value, y


def bipartition(
    W, min_size: int = 1, max_products: int = MAX_CUT_PRODUCTS
) -> tuple[np.ndarray | None, float]:
    """Best two-way normalized cut of a graph: (mask of one side, Ncut value).

    ``max_products`` caps the eigensolver's products (:func:`fiedler_vector`).
    """
    mask, value, _ = _bipartition(W, min_size, None, Budget(check_products(max_products)))
    return mask, value


def isolated_split(d: np.ndarray, diag: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The split that peels off a graph's most isolated node, if it is isolated.

    A node is isolated when less than :data:`ISOLATED_NCUT` of its degree ``d`` leaves it
    (``diag`` holds the self loops W_ii). Returns (mask of that node alone, the Ncut value
    of the split, eq. 4.29), or None when no node is isolated.
    """
    cut = np.maximum(np.asarray(d, dtype=float) - diag, 0.0)
    share = cut / d
    i = int(np.argmin(share))
    if not share[i] < ISOLATED_NCUT or d.size < 2:
        return None
    mask = np.zeros(d.size, dtype=bool)
    mask[i] = True
    return mask, float(cut[i] / d[i] + cut[i] / (d.sum() - d[i]))


@dataclass
class CutTree:
    """Greedy recursive normalized cuts on an affinity, extended lazily and cached.

    ``labels(k)`` returns the node labels after the first k − 1 splits (fewer if the
    threshold or the minimum size stops earlier); labels are numbered in order of first
    appearance along the nodes, so label 0 is the segment of node 0.

    A large dense W is kept once (plus one float32 copy for the products) for the whole
    tree; each segment's eigensolve starts from its parent's eigenvectors restricted to
    it (module docstring).

    Each eigensolve makes at most ``max_products`` products with W (module docstring,
    "Bounded work"); a segment above :data:`DENSE_EIGH_MAX` nodes with an isolated block
    is not solved but peels that block off (:func:`isolated_split`, when ``min_size`` is
    1). :meth:`cut_limits` says how often either happened. ``labels`` and ``prefetch``
    take a ``cancel`` callable, called before every product.
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
    _graph: DenseGraph | None = field(default=None, init=False, repr=False)
    #: eigenvector block (y vectors) of each solved segment, by segment id
    _blocks: dict[int, np.ndarray] = field(default_factory=dict, init=False, repr=False)
    #: a child's start: its parent's block restricted to it, by segment id
    _starts: dict[int, np.ndarray] = field(default_factory=dict, init=False, repr=False)
    _warm_index: list[tuple[np.ndarray, np.ndarray]] | None = field(
        default=None, init=False, repr=False
    )
    #: products an eigensolve may make (module docstring, "Bounded work")
    max_products: int = MAX_CUT_PRODUCTS
    _counts: dict[str, int] = field(default_factory=dict, init=False, repr=False)
    #: the counts when each entry of _history was made
    _count_history: list[dict[str, int]] = field(default_factory=list, init=False, repr=False)
    _solving: Budget | None = field(default=None, init=False, repr=False)
    _cancel: Callable[[], bool] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        n = self.W.shape[0]
        if self.W.shape != (n, n):
            raise PolarsegError(f"affinity must be square, got shape {self.W.shape}")
        self.max_products = check_products(self.max_products)
        self._segments = [np.arange(n)]
        self._ids = [self._new_id()]
        self._history = [np.zeros(n, dtype=np.int32)]
        self._counts = {"eigensolver_capped": 0, "isolated_skipped": 0, "products": 0}
        self._count_history = [dict(self._counts)]

    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id

    @property
    def ncut_values(self) -> list[float]:
        """Ncut value of each split made so far, in order."""
        return list(self._ncut_values)

    @property
    def products(self) -> int:
        """Products with W the eigensolvers made so far (the running solve's included)."""
        solving = self._solving
        return self._counts["products"] + (0 if solving is None else solving.used)

    def cut_limits(self, k: int | None = None) -> dict[str, int]:
        """How often the work limits acted, up to the labels of ``k`` segments.

        ``eigensolver_capped``: eigensolves that spent ``max_products`` and cut along their
        best vector; ``isolated_skipped``: segments not solved because they peel off an
        isolated block; ``products``: products with W made; ``max_products``: the cap.
        Counted over the solves made until ``labels(k)`` was available (by default, all
        so far, prefetched ones included).
        """
        counts = self._counts
        if k is not None and 1 <= k <= len(self._count_history):
            counts = self._count_history[k - 1]
        return {**counts, "max_products": self.max_products}

    def _solve(self, work: Callable[[Budget], tuple]) -> tuple:
        """``work(budget)`` with a fresh budget, its products and cap counted."""
        budget = Budget(self.max_products, self._cancel)
        self._solving = budget
        try:
            return work(budget)
        finally:
            self._solving = None
            self._counts["products"] += budget.used
            self._counts["eigensolver_capped"] += int(budget.capped)

    def _peel(self, d: np.ndarray, diag: np.ndarray) -> tuple | None:
        """The candidate of a large segment with an isolated block (module docstring)."""
        if self.min_size > 1:
            return None
        split = isolated_split(d, diag)
        if split is None:
            return None
        self._counts["isolated_skipped"] += 1
        return (*split, None)

    def _dense_graph(self) -> DenseGraph | None:
        """The shared dense graph, for a dense W above DENSE_EIGH_MAX nodes."""
        if self._graph is None and not sps.issparse(self.W) and self.W.shape[0] > DENSE_EIGH_MAX:
            self._graph = DenseGraph(self.W)
        return self._graph

    def _candidate(self, pos: int) -> tuple[np.ndarray | None, float, np.ndarray | None]:
        sid = self._ids[pos]
        if sid not in self._candidates:
            idx = self._segments[pos]
            graph = self._dense_graph()
            if graph is not None and idx.size > DENSE_EIGH_MAX:
                if idx.size < max(2, 2 * self.min_size):
                    result: tuple = (None, np.inf, None)
                else:
                    seg = graph.segment(idx)
                    peeled = self._peel(seg.d, seg.diag)
                    if peeled is not None:
                        result = peeled
                    else:
                        starts = [self._warm_start(idx), self._starts.get(sid)]
                        block = fix_sign(
                            self._solve(lambda budget: segment_vectors(seg, starts, budget))
                        )
                        self._blocks[sid] = block
                        self._vectors[idx.tobytes()] = block
                        split = _segment_split(seg, block[:, 0], self.min_size)
                        result = (*split, block[:, 0])
            else:
                sub = self.W if idx.size == self.W.shape[0] else subgraph(self.W, idx)
                if not sps.issparse(sub):
                    sub = np.asarray(sub, dtype=float)  # small: solved and split in float64
                peeled = None
                if idx.size > DENSE_EIGH_MAX and idx.size >= max(2, 2 * self.min_size):
                    peeled = self._peel(degrees(sub), diagonal(sub))
                if peeled is not None:
                    result = peeled
                else:
                    warm = None if self.warm is None else self.warm.get(idx.tobytes())
                    result = self._solve(
                        lambda budget: _bipartition(sub, self.min_size, warm, budget)
                    )
                    if result[2] is not None:
                        self._vectors[idx.tobytes()] = result[2]
            self._starts.pop(sid, None)
            self._candidates[sid] = result
        return self._candidates[sid]

    def _warm_start(self, idx: np.ndarray) -> np.ndarray | None:
        """The vectors of the smallest segment of the ``warm`` tree containing ``idx``,
        restricted to it (the same segment's, when the old tree had it)."""
        if not self.warm:
            return None
        exact = self.warm.get(idx.tobytes())
        if exact is not None:
            return exact
        if self._warm_index is None:
            self._warm_index = sorted(
                ((np.frombuffer(k, dtype=idx.dtype), v) for k, v in self.warm.items()),
                key=lambda kv: kv[0].size,
            )
        n = self.W.shape[0]
        for old, vectors in self._warm_index:
            if old.size < idx.size or old.size > n or old.max(initial=-1) >= n:
                continue
            inside = np.zeros(n, dtype=bool)
            inside[old] = True
            if inside[idx].all():
                return np.reshape(vectors, (old.size, -1))[np.searchsorted(old, idx)]
        return None

    def fiedler_vectors(self) -> dict[bytes, np.ndarray]:
        """Eigenvectors of every segment solved so far, keyed by its node indices' bytes.

        Each value is the segment's Fiedler vector y, or for a large dense graph an
        (m, b) block: the Fiedler vector, then the guard vectors of the block eigensolver.
        Pass the dict as ``warm`` to a new tree on the same nodes (e.g. after the affinity
        scale changed): each segment's eigensolve then starts from the vectors of the
        smallest old segment that contains it, restricted to it.
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
        parent = self._ids[best_pos]
        mask, _, _ = self._candidates.pop(parent)
        block = self._blocks.pop(parent, None)
        idx = self._segments[best_pos]
        children = (idx[mask], idx[~mask])
        ids = (self._new_id(), self._new_id())
        self._segments[best_pos], self._ids[best_pos] = children[0], ids[0]
        self._segments.append(children[1])
        self._ids.append(ids[1])
        if block is not None:
            # a child's next eigenvectors are nearly its parent's restricted to it: the
            # parent's guards first (the Fiedler vector restricted is nearly constant
            # on a side), then its Fiedler vector
            reordered = np.hstack([block[:, 1:], block[:, :1]])
            for side, sid in zip((mask, ~mask), ids, strict=True):
                self._starts[sid] = reordered[side]
        labels = np.empty(self.W.shape[0], dtype=np.int32)
        for lab, seg in enumerate(self._segments):
            labels[seg] = lab
        self._history.append(first_appearance_order(labels))
        self._count_history.append(dict(self._counts))
        self._ncut_values.append(best_val)
        return True

    def prefetch(self, cancel: Callable[[], bool] | None = None) -> Iterator[int]:
        """Solve the candidate split of every current segment not solved yet.

        What the next split (``labels(k + 1)`` after ``labels(k)`` reached the tree's
        current k segments) computes first, so that afterwards it only compares the
        candidates: an idle-time precomputation (the plugin runs it after showing a
        result). Yields the position of each segment solved, so that a caller can stop
        between two solves; the results are exactly those ``labels`` would compute.
        ``cancel`` is called before every product of a solve (True raises
        :class:`~napari_polarseg.engine.errors.Cancelled`; that solve is not kept).
        """
        if self._exhausted:
            return
        for pos in range(len(self._segments)):
            if self._ids[pos] not in self._candidates:
                self._cancel = cancel
                try:
                    self._candidate(pos)
                finally:
                    self._cancel = None
                yield pos

    def labels(self, k: int, cancel: Callable[[], bool] | None = None) -> np.ndarray:
        """Node labels 0..k'−1 for k' = min(k, reachable) segments.

        ``cancel`` is called before every product of the eigensolvers; True raises
        :class:`~napari_polarseg.engine.errors.Cancelled` (the splits made so far stay).
        """
        if k < 1:
            raise PolarsegError(f"number of segments must be >= 1, got {k}")
        self._cancel = cancel
        try:
            while len(self._history) < k and not self._exhausted:
                self._split_once()
        finally:
            self._cancel = None
        return self._history[min(k, len(self._history)) - 1].copy()


def first_appearance_order(labels: np.ndarray) -> np.ndarray:
    """Renumber labels 0, 1, … in order of first appearance."""
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(first)
    remap = np.empty(order.size, dtype=np.int32)
    remap[order] = np.arange(order.size, dtype=np.int32)
    uniq = np.unique(labels)
    return remap[np.searchsorted(uniq, labels)]


def recursive_ncut(
    W,
    n_segments: int,
    min_size: int = 1,
    threshold: float | None = None,
    max_products: int = MAX_CUT_PRODUCTS,
) -> np.ndarray:
    """Labels of the graph's nodes after recursive two-way normalized cuts."""
    tree = CutTree(W, min_size=min_size, threshold=threshold, max_products=max_products)
    return tree.labels(n_segments)
