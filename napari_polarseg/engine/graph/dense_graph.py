"""A dense block affinity and its segments, as the eigensolvers and the split search use them.

One float32 copy of a large dense W (from :data:`FLOAT32_MIN_NODES` nodes; W itself when
it is float32, as the pipeline stores it) serves every segment of a cut tree; products use
BLAS ``symv``, which reads one triangle (half the memory traffic of ``gemv``). A segment
with more than :data:`COPY_MAX_FRACTION` of the nodes is multiplied through the whole
matrix (W[s][:, s] x = (W x̃)[s]); a smaller one gets its own float32 copy. Degrees are
summed in float64.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sps
from scipy.linalg.blas import get_blas_funcs

from ..chunks import chunk_bounds, run_chunks
from ..errors import PolarsegError

#: Dense graphs from this many nodes are multiplied in float32 (see DenseGraph).
FLOAT32_MIN_NODES = 2_000


#: Segments with at most this share of a dense graph's nodes get their own float32
#: copy (a product then reads (m/n)² of the matrix; the copy costs about two
#: products); larger ones are multiplied through the whole matrix.
COPY_MAX_FRACTION = 0.9


def subgraph(W, idx: np.ndarray):
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


def degrees(W) -> np.ndarray:
    d = np.asarray(W.sum(axis=1), dtype=float).ravel()
    if np.any(~np.isfinite(d)) or np.any(d <= 0):
        raise PolarsegError("affinity has an isolated node (zero degree) or a non-finite degree")
    return d


def diagonal(W) -> np.ndarray:
    return np.asarray(W.diagonal(), dtype=float)


def operator_matrix(W):
    """The matrix the sparse and fallback solvers multiply with (float32 if dense and big).

    The products are memory-bound (one pass over n² values each), so float32 halves their
    time, and float32 round-off (~1e-7) is ten times below
    :data:`~napari_polarseg.engine.graph.eigensolver.EIG_TOL`.
    """
    if not sps.issparse(W) and W.shape[0] >= FLOAT32_MIN_NODES:
        return np.asarray(W, dtype=np.float32)
    return W


def symmetric_product(M: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """X ↦ M X (columns) for a symmetric M, in M's precision.

    BLAS ``symv`` per column: it reads one triangle only, half the memory of ``gemv``.
    symv wants Fortran order or it copies the whole matrix on every call; a symmetric M
    equals its transpose, so a C-ordered M is passed as M.T (a fancy-indexed copy can
    come out in either order). Not one ``gemm`` for a block: for the few columns used
    here OpenBLAS's gemm was slower than the symv calls, and after a gemm or a gemv on a
    large matrix the next few dozen symv calls ran slower (so the tree uses no gemv
    either; docs/performance.md, "Measurements behind the code").
    """
    symv = get_blas_funcs("symv", (M,))
    MT = M.T if M.flags.c_contiguous else np.asfortranarray(M)

    def apply(X: np.ndarray) -> np.ndarray:
        out = np.empty(X.shape, dtype=M.dtype, order="F")
        for c in range(X.shape[1]):
            out[:, c] = symv(1.0, MT, X[:, c])
        return out

    return apply


@dataclass
class DenseGraph:
    """A dense affinity and its one copy for products (float32 from FLOAT32_MIN_NODES).

    Shared by all segments of a :class:`CutTree`: no per-segment float64 copies. A
    float32 W of that size (the pipeline stores its affinity so) is used as it is, for
    the products too; degrees are always summed in float64.
    """

    W: np.ndarray
    Wop: np.ndarray = field(init=False, repr=False)
    d: np.ndarray = field(init=False, repr=False)
    diag: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n = self.W.shape[0]
        single = np.asarray(self.W).dtype == np.float32 and n >= FLOAT32_MIN_NODES
        W = self.W = np.ascontiguousarray(self.W, dtype=np.float32 if single else float)
        if n < FLOAT32_MIN_NODES:
            self.Wop, self.d = W, degrees(W)
        else:
            # the float32 copy (unless W is float32) and the float64 degrees in one pass
            # over W, in row chunks on the cores
            self.Wop = W if single else np.empty((n, n), dtype=np.float32)
            self.d = np.empty(n)

            def work(a: int, b: int) -> None:
                if not single:
                    self.Wop[a:b] = W[a:b]
                self.d[a:b] = W[a:b].sum(axis=1, dtype=np.float64)

            step = max(1, 2**20 // n)
            run_chunks(chunk_bounds(n, step), work, n * n // 8)
            if not np.all(np.isfinite(self.d)) or np.any(self.d <= 0):
                raise PolarsegError(
                    "affinity has an isolated node (zero degree) or a non-finite degree"
                )
        self.diag = diagonal(W)

    @property
    def n(self) -> int:
        return self.W.shape[0]

    def segment(self, idx: np.ndarray) -> Segment:
        """Degrees, diagonal and product of the subgraph on the (sorted) nodes ``idx``."""
        n = self.n
        if idx.size == n:
            return Segment(idx, self.W, True, self.d, self.diag, self._product(self.Wop, None))
        sub = subgraph(self.Wop, idx) if idx.size <= COPY_MAX_FRACTION * n else None
        product = self._product(self.Wop, idx) if sub is None else self._product(sub, None)
        # degrees within the segment, in float64
        if self.W.dtype == np.float64:
            # one float64 product with the segment's indicator (symv: symmetric_product)
            inside = np.zeros(n)
            inside[idx] = 1.0
            d = symmetric_product(self.W)(inside[:, None])[idx, 0]
        elif sub is not None:
            d = sub.sum(axis=1, dtype=np.float64)
        else:
            # all of a node's minus those to the few nodes outside the segment
            outside = np.ones(n, dtype=bool)
            outside[idx] = False
            d = self.d[idx] - self.W[:, outside].sum(axis=1, dtype=np.float64)[idx]
        if np.any(d <= 0):
            raise PolarsegError("affinity has an isolated node (zero degree)")
        return Segment(idx, self.W, False, d, self.diag[idx], product)

    def _product(self, M: np.ndarray, idx: np.ndarray | None) -> Callable[[np.ndarray], np.ndarray]:
        """X ↦ W[idx][:, idx] X in float64, by M (the whole matrix when idx is given)."""
        core = symmetric_product(M)
        n = M.shape[0]

        def apply(X: np.ndarray) -> np.ndarray:
            if idx is None:
                Y = core(np.asfortranarray(X, dtype=M.dtype))
            else:
                # W[s][:, s] x = (W x̃)[s], x̃ = x scattered into zeros
                full = np.zeros((n, X.shape[1]), dtype=M.dtype, order="F")
                full[idx] = X
                Y = core(full)[idx]
            return np.asarray(Y, dtype=float)

        return apply


@dataclass
class Segment:
    """A segment (nodes ``idx``) of a dense graph ``W`` as the eigensolver and the split
    search see it: its degrees, self loops and products, and whether it is all of W."""

    idx: np.ndarray
    W: np.ndarray
    whole: bool
    d: np.ndarray
    diag: np.ndarray
    product: Callable[[np.ndarray], np.ndarray]
