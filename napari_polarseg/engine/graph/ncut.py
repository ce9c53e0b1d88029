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
- Larger dense W: block LOBPCG (:func:`_lobpcg`, Knyazev's method written out here) on
  N with the constraint u, a Jacobi preconditioner 1 / diag(N) and residual tolerance
  :data:`EIG_TOL` for the Fiedler vector, iterating :data:`GUARD_VECTORS` more vectors
  to the loose :data:`GUARD_TOL`. Each product reads the n² entries, so the number of
  products is what counts, and the preconditioner is what keeps it low on the thesis's
  own affinity (s = 1 with 10–20 PCA components): that graph has fallen apart into
  nearly isolated blocks, diag(N)_i = 1 − W_ii/d_i is tiny exactly there, and the
  Fiedler vectors live there: plain Lanczos (``eigsh``) needs several times as many
  products per cut (figures: docs/performance.md, "Measurements behind the code"). A
  cold solve starts from random vectors and the indicators of the blocks with the
  smallest diag(N).
- Why not ``scipy.sparse.linalg.lobpcg`` (used before): its overhead per iteration was
  about half a product; it has one tolerance for all vectors, so guards cost as much as
  the Fiedler vector; with one vector it settled on the wrong eigenpair on the
  4,750-block segment of the reference image's fourth cut (λ = 4.6e-3 after 400
  products, where the smallest is 1.4e-3: another cut than ``eigh``'s); and in float32
  it stalled at a residual of 8e-6 on the s = 2 affinity (400 iterations). The block
  takes the smallest of its Ritz values, and a segment that lost a few blocks to a
  cut has nearly its parent's next eigenvectors as its own: each child starts from its
  parent's vectors restricted to it (the Ritz vectors of those candidates).
- Dense products: one float32 matrix (from :data:`FLOAT32_MIN_NODES` nodes: W itself
  when it is float32, as the pipeline stores its affinity there, else one float32 copy)
  serves the whole tree, multiplied with BLAS ``symv`` (it reads one triangle:
  half the memory traffic of ``gemv``). A segment
  with more than :data:`COPY_MAX_FRACTION` of the nodes is multiplied through the whole
  matrix (scatter into zeros, product, gather: W[s][:, s] x = (W x̃)[s]); a smaller one
  gets its own float32 copy. Float32 round-off (~1e-7 relative per product) is ten
  times below :data:`EIG_TOL`; degrees, the split search and the Ncut values are
  summed in float64.
- Sparse W (k nearest neighbours, spatial neighbourhoods): Lanczos (``eigsh``, two
  eigenpairs of D^−½ W D^−½, tolerance EIG_TOL / 10). Products are cheap there and
  LOBPCG's per-iteration overhead dominates. pyamg is not used: Lanczos is fast
  enough. Except on a graph that has *fallen apart* (a node keeps more than
  1 − :data:`FALLEN_APART` of its degree to itself, as with the thesis scale s = 1):
  there Lanczos must resolve eigenvalues of D^−½ W D^−½ within 1e-5 of 1 and needs
  orders of magnitude more products than the block LOBPCG with its Jacobi
  preconditioner: such graphs are solved by the block LOBPCG first (figures:
  docs/performance.md, "Measurements behind the code").
- Each falls back on the other, and finally on a dense solve (up to
  :data:`DENSE_FALLBACK_MAX` nodes) when neither gave any vector.

Bounded work, isolated blocks, Cancel
-------------------------------------
- Every eigensolve of a segment may make at most ``max_products`` products with the
  affinity (:data:`MAX_CUT_PRODUCTS` by default; a product is one vector, so a block
  LOBPCG iteration with four active vectors makes four), all solvers of the solve
  together; Lanczos, when it goes first, may take :data:`LANCZOS_SHARE` of them. When
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
import scipy.linalg
import scipy.sparse as sps
from scipy.linalg.blas import get_blas_funcs
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh

from ..chunks import chunk_bounds, run_chunks
from ..errors import Cancelled, PolarsegError

#: Graphs up to this many nodes use a dense eigensolver; larger ones are iterative.
DENSE_EIGH_MAX = 300
#: Residual tolerance ‖N z − λ z‖ (unit z) of the iterative eigensolver.
EIG_TOL = 1e-6
#: Iteration cap of LOBPCG before falling back to Lanczos.
LOBPCG_MAXITER = 400
#: Default cap on the products with the affinity one segment's eigensolve may make, all
#: solvers together (module docstring: "Bounded work"); above the largest solves of
#: normal inputs (docs/performance.md, "Measurements behind the code").
MAX_CUT_PRODUCTS = 2_000
#: Share of the products Lanczos may take when it goes first (sparse graphs that have
#: not fallen apart); the rest is kept for the block LOBPCG.
LANCZOS_SHARE = 0.75
#: A sparse graph has fallen apart when one of its nodes sends less than this share of
#: its degree to other nodes (1 − W_ii / d_i, its singleton cut over its degree): then
#: the block LOBPCG, whose Jacobi preconditioner is what copes with such nodes, goes
#: before Lanczos. The polanalyser frames give 0.83–0.96 with the recommended preset
#: and 2e-14–3e-4 with the thesis preset.
FALLEN_APART = 1e-3
#: A node is isolated when less than this share of its degree leaves it: its singleton
#: cut is below the resolution of the iterative eigensolvers (:data:`EIG_TOL`).
ISOLATED_NCUT = EIG_TOL
#: Smallest ``max_products`` accepted (the block solver's first step needs a few).
MIN_CUT_PRODUCTS = 20
#: Vectors iterated along with the Fiedler vector by the dense LOBPCG (see module doc);
#: with :data:`GUARD_TOL`, the setting that made the fewest products on the reference
#: image's interactive changes (docs/performance.md, "Measurements behind the code").
GUARD_VECTORS = 3
#: Residual tolerance of the guard vectors: they widen the search space and start the
#: children; only the first vector is ever cut along, to :data:`EIG_TOL`.
GUARD_TOL = 0.05
#: Dense graphs from this many nodes are multiplied in float32 (see _DenseGraph).
FLOAT32_MIN_NODES = 2_000
#: Segments with at most this share of a dense graph's nodes get their own float32
#: copy (a product then reads (m/n)² of the matrix; the copy costs about two
#: products); larger ones are multiplied through the whole matrix.
COPY_MAX_FRACTION = 0.9
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
    if np.any(~np.isfinite(d)) or np.any(d <= 0):
        raise PolarsegError("affinity has an isolated node (zero degree) or a non-finite degree")
    return d


def _diagonal(W) -> np.ndarray:
    return np.asarray(W.diagonal(), dtype=float)


def _operator_matrix(W):
    """The matrix the sparse and fallback solvers multiply with (float32 if dense and big).

    The products are memory-bound (one pass over n² values each), so float32 halves their
    time, and float32 round-off (~1e-7) is ten times below :data:`EIG_TOL`.
    """
    if not sps.issparse(W) and W.shape[0] >= FLOAT32_MIN_NODES:
        return np.asarray(W, dtype=np.float32)
    return W


def _symmetric_product(M: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
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
class _DenseGraph:
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
            self.Wop, self.d = W, _degrees(W)
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
        self.diag = _diagonal(W)

    @property
    def n(self) -> int:
        return self.W.shape[0]

    def segment(self, idx: np.ndarray) -> _Segment:
        """Degrees, diagonal and product of the subgraph on the (sorted) nodes ``idx``."""
        n = self.n
        if idx.size == n:
            return _Segment(idx, self.W, True, self.d, self.diag, self._product(self.Wop, None))
        sub = _subgraph(self.Wop, idx) if idx.size <= COPY_MAX_FRACTION * n else None
        product = self._product(self.Wop, idx) if sub is None else self._product(sub, None)
        # degrees within the segment, in float64
        if self.W.dtype == np.float64:
            # one float64 product with the segment's indicator (symv: _symmetric_product)
            inside = np.zeros(n)
            inside[idx] = 1.0
            d = _symmetric_product(self.W)(inside[:, None])[idx, 0]
        elif sub is not None:
            d = sub.sum(axis=1, dtype=np.float64)
        else:
            # all of a node's minus those to the few nodes outside the segment
            outside = np.ones(n, dtype=bool)
            outside[idx] = False
            d = self.d[idx] - self.W[:, outside].sum(axis=1, dtype=np.float64)[idx]
        if np.any(d <= 0):
            raise PolarsegError("affinity has an isolated node (zero degree)")
        return _Segment(idx, self.W, False, d, self.diag[idx], product)

    def _product(self, M: np.ndarray, idx: np.ndarray | None) -> Callable[[np.ndarray], np.ndarray]:
        """X ↦ W[idx][:, idx] X in float64, by M (the whole matrix when idx is given)."""
        core = _symmetric_product(M)
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
class _Segment:
    """A segment (nodes ``idx``) of a dense graph ``W`` as the eigensolver and the split
    search see it: its degrees, self loops and products, and whether it is all of W."""

    idx: np.ndarray
    W: np.ndarray
    whole: bool
    d: np.ndarray
    diag: np.ndarray
    product: Callable[[np.ndarray], np.ndarray]


def _column_norms(V: np.ndarray) -> np.ndarray:
    """Euclidean norm of every column (one pass; np.linalg.norm makes temporaries)."""
    return np.sqrt(np.einsum("ij,ij->j", V, V))


def _orthonormalize(V: np.ndarray, basis: np.ndarray | None) -> np.ndarray:
    """Columns spanning V's part orthogonal to the orthonormal ``basis``, orthonormal.

    Columns are scaled to unit length, projected out of ``basis`` twice (classical
    Gram–Schmidt with reorthogonalisation), then orthonormalised among themselves through
    the eigendecomposition of their Gram matrix, dropping directions whose Gram eigenvalue
    is below 1e-10 (sin² of the angle to the rest: numerically dependent; keeping them
    would amplify round-off by up to 1/√s).
    """
    norms = _column_norms(V)
    V = V / np.where(norms > 0, norms, 1.0)
    if basis is not None:
        for _ in range(2):
            V = V - basis @ (basis.T @ V)
    s, U = np.linalg.eigh(V.T @ V)
    keep = s > 1e-10
    V = V @ (U[:, keep] / np.sqrt(s[keep]))
    if basis is not None and V.shape[1] and s[keep].min() < 1e-4:
        # the rescaling amplified what is left of the basis directions by 1/√s: once more
        V = V - basis @ (basis.T @ V)
        V = V / _column_norms(V)
    return V


class _OutOfProducts(Exception):
    """A solver asked for more products than its budget has left."""


class _Budget:
    """The products with the affinity one eigensolve may still make; checks Cancel.

    Every solver charges its products here before making them (:meth:`take`, one per
    vector), which is also where ``cancel()`` is called.

    Parameters
    ----------
    limit : int
        Products the whole solve may make.
    cancel : callable() -> bool, optional
        Returning True raises :class:`~napari_polarseg.engine.errors.Cancelled`.
    """

    def __init__(self, limit: int, cancel: Callable[[], bool] | None = None) -> None:
        self.limit = int(limit)
        self.cancel = cancel
        self.used = 0
        #: a solver was refused products: the solve ended on a best-so-far vector
        self.capped = False

    def take(self, columns: int, stop: int | None = None) -> bool:
        """Charge ``columns`` products if they fit below ``stop`` (default: the limit).

        Returns False, and marks the solve as capped when ``stop`` is the limit, if they
        do not fit.
        """
        if self.cancel is not None and self.cancel():
            raise Cancelled("the normalized cut was cancelled")
        end = self.limit if stop is None else min(stop, self.limit)
        if self.used + columns > end:
            self.capped = self.capped or end == self.limit
            return False
        self.used += columns
        return True

    def operator(
        self, n: int, product: Callable[[np.ndarray], np.ndarray], stop: int | None = None
    ) -> LinearOperator:
        """``product`` (x ↦ A x on (n,) vectors) as an operator that charges each call;
        past the budget (or ``stop``) it raises :class:`_OutOfProducts`."""

        def matvec(x: np.ndarray) -> np.ndarray:
            if not self.take(1, stop):
                raise _OutOfProducts
            return product(np.ravel(x))

        return LinearOperator((n, n), matvec=matvec, dtype=float)


_BLAS_LIBRARIES: list | None = None


def _blas_libraries() -> list:
    """threadpoolctl's controllers of the loaded BLAS libraries ([] without it)."""
    global _BLAS_LIBRARIES
    if _BLAS_LIBRARIES is None:
        try:
            from threadpoolctl import ThreadpoolController

            found = ThreadpoolController().lib_controllers
            _BLAS_LIBRARIES = [lib for lib in found if lib.user_api == "blas"]
        except Exception:  # pragma: no cover - scikit-learn brings threadpoolctl
            _BLAS_LIBRARIES = []
    return _BLAS_LIBRARIES


def _lobpcg(
    apply: Callable[[np.ndarray], np.ndarray],
    precond: np.ndarray,
    u: np.ndarray,
    X0: np.ndarray,
    size: int,
    tol: float,
    guard_tol: float,
    maxiter: int,
    budget: _Budget | None = None,
) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """:func:`_lobpcg_steps` with its tall-and-skinny algebra on one BLAS thread.

    Each iteration makes a dozen products of n × (≤ 13) blocks (Gram matrices, Ritz
    combinations, projections). OpenBLAS splits them between its threads, which on a
    loaded machine made them many times slower (docs/performance.md, "Measurements
    behind the code"). ``apply`` (the products with the affinity, memory-bound: they
    gain from the threads) runs with the caller's threads.
    """
    libs = _blas_libraries()
    saved = [lib.num_threads for lib in libs]
    if all(count == 1 for count in saved):
        return _lobpcg_steps(apply, precond, u, X0, size, tol, guard_tol, maxiter, budget)

    def threads(counts: list[int]) -> None:
        for lib, count in zip(libs, counts, strict=True):
            lib.set_num_threads(count)

    single = [1] * len(libs)

    def products(X: np.ndarray) -> np.ndarray:
        threads(saved)
        try:
            return apply(X)
        finally:
            threads(single)

    threads(single)
    try:
        return _lobpcg_steps(products, precond, u, X0, size, tol, guard_tol, maxiter, budget)
    finally:
        threads(saved)


def _lobpcg_steps(
    apply: Callable[[np.ndarray], np.ndarray],
    precond: np.ndarray,
    u: np.ndarray,
    X0: np.ndarray,
    size: int,
    tol: float,
    guard_tol: float,
    maxiter: int,
    budget: _Budget | None = None,
) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """Smallest eigenpairs of a symmetric operator orthogonal to a unit vector u.

    Block LOBPCG (Knyazev 2001) in the orthonormal-basis form of Hetmaniuk & Lehoucq
    (2006), with soft locking: each iteration applies the operator only to the
    preconditioned residuals W of the vectors not yet converged, and takes the Ritz
    vectors of span[X, P, W]. Products are never recomputed (AX, AP follow X, P by the
    same small combinations), and the operator is applied only to vectors already
    orthonormalised against X and P, so float32 noise in a product is never amplified
    by a near-dependent basis. P is kept orthonormal to X in coefficient space: it is
    the part of the new X outside the old X, orthogonalised there against the new X.

    Parameters
    ----------
    apply : callable
        (n, k) ↦ A (n, k), A symmetric with A u = 0.
    precond : ndarray (n,)
        Diagonal preconditioner (approximate inverse of diag(A)).
    u : ndarray (n, 1)
        Unit constraint vector.
    X0 : ndarray (n, c)
        Start candidates (orthonormalised here). With more than ``size`` of them, the
        block starts from the ``size`` lowest Ritz vectors of their span (c products);
        with fewer, random columns fill it up.
    size : int
        Block size b: the vector sought and b − 1 guards.
    tol, guard_tol : float
        Residual tolerances ‖A x − λ x‖ of the first vector and of the others.
    maxiter : int
        Iteration cap.
    budget : _Budget, optional
        Products the solve may make (each column given to ``apply`` is one); when the
        next iteration's products do not fit, the solve stops where it is.

    Returns (eigenvalues (b,), vectors (n, b) ascending, residual of the first, whether
    every vector converged). Not converged: the current Ritz vectors, after ``maxiter``
    iterations, when the budget is spent, or when the residuals lie in the basis already.
    Raises :class:`_OutOfProducts` if the budget cannot pay for the first product.
    """
    n, b = X0.shape[0], size
    rng = np.random.default_rng(0)
    X = _orthonormalize(X0 - u @ (u.T @ X0), u)
    while X.shape[1] < b:
        extra = rng.standard_normal((n, b - X.shape[1]))
        X = np.hstack([X, _orthonormalize(extra, np.hstack([u, X]))])
    if budget is not None and not budget.take(X.shape[1]):
        raise _OutOfProducts
    AX = apply(X)
    lam, C = np.linalg.eigh(_sym(X.T @ AX))
    X, AX, lam = X @ C[:, :b], AX @ C[:, :b], lam[:b]
    P = AP = None
    tols = np.full(b, guard_tol)
    tols[0] = tol
    resid = np.full(b, np.inf)
    for _ in range(maxiter):
        R = AX - X * lam
        resid = _column_norms(R)
        active = resid > tols
        if not active.any():
            return lam, X, float(resid[0]), True
        ub = np.hstack([u, X] if P is None else [u, X, P])
        Wk = _orthonormalize(precond[:, None] * R[:, active], ub)
        if Wk.shape[1] == 0:  # residuals inside the basis: nothing new to add
            break
        if budget is not None and not budget.take(Wk.shape[1]):
            break
        AB = np.hstack([AX, apply(Wk)] if P is None else [AX, AP, apply(Wk)])
        B = np.hstack([ub[:, 1:], Wk])
        theta, C = np.linalg.eigh(_sym(B.T @ AB))
        Cx = C[:, :b]
        X, AX, lam = B @ Cx, AB @ Cx, theta[:b]
        # P: the part of the new X outside the old X, made orthonormal to the new X
        Z = Cx.copy()
        Z[:b] = 0.0
        Z = _orthonormalize(Z, Cx)
        P, AP = (B @ Z, AB @ Z) if Z.shape[1] else (None, None)
    return lam, X, float(resid[0]), False


def _sym(H: np.ndarray) -> np.ndarray:
    return (H + H.T) / 2


def _start_candidates(
    d: np.ndarray, precond: np.ndarray, starts: list[np.ndarray | None], size: int
) -> np.ndarray:
    """Start candidates z = D^½ y for the block eigensolver of a segment.

    The given y vectors (columns of ``starts``) if any; else ``size`` random columns and
    the indicators of the ``size`` nodes with the smallest diag(N) (the nearly isolated
    ones, where the Fiedler vectors of a graph that fell apart live).
    """
    m = d.size
    cols = [np.reshape(s, (m, -1)) for s in starts if s is not None]
    if cols:
        return np.hstack(cols) * np.sqrt(d)[:, None]
    X = np.random.default_rng(0).standard_normal((m, 2 * size))
    isolated = np.argsort(-precond, kind="stable")[:size]
    X[:, size:] = 0.0
    X[isolated, size + np.arange(size)] = 1.0
    return X


def _segment_vectors(seg: _Segment, starts: list[np.ndarray], budget: _Budget) -> np.ndarray:
    """Generalized eigenvectors y (m, b) of a large dense segment: Fiedler, then guards.

    Block LOBPCG first (module docstring); if it stalls with products left, Lanczos for
    the Fiedler vector alone, with what is left of ``budget``. When the budget is spent
    the block's best vectors are returned (``budget.capped`` tells); a dense solve only
    when no solver gave any vector. Raises PolarsegError if that fails too.
    """
    m = seg.idx.size
    d = seg.d
    d_is = 1.0 / np.sqrt(d)
    u = np.sqrt(d)[:, None] / np.sqrt(d.sum())

    def laplacian(X: np.ndarray) -> np.ndarray:
        return X - d_is[:, None] * seg.product(d_is[:, None] * X)

    precond = 1.0 / np.maximum(1.0 - seg.diag / d, 1e-8)
    size = min(1 + GUARD_VECTORS, m - 1)
    best = None
    try:
        _, Z, _, converged = _lobpcg(
            laplacian,
            precond,
            u,
            _start_candidates(d, precond, starts, size),
            size,
            EIG_TOL,
            GUARD_TOL,
            LOBPCG_MAXITER,
            budget,
        )
        best = Z * d_is[:, None]
        if converged or budget.capped:
            return best
    except (_OutOfProducts, np.linalg.LinAlgError):
        pass
    start = next((s for s in starts if s is not None), None)
    op = budget.operator(m, lambda x: d_is * seg.product((d_is * x)[:, None])[:, 0])
    try:
        vals, vecs = eigsh(op, k=2, which="LA", v0=_start_vector(m, d, start), tol=1e-8)
        z = vecs[:, np.argsort(vals)[0]]
    except (_OutOfProducts, ArpackNoConvergence, np.linalg.LinAlgError, ValueError):
        if best is not None:
            return best
        z = _dense_fiedler(seg.W if seg.whole else _subgraph(seg.W, seg.idx), d)
    return (z / np.sqrt(d))[:, None]


def _scaled_product(Wop, d_is: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """x ↦ D^−½ W D^−½ x for vectors and blocks of vectors, in float64."""

    def apply(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x)
        s = d_is if x.ndim == 1 else d_is[:, None]
        y = np.asarray(Wop @ (s * x).astype(Wop.dtype, copy=False), dtype=float)
        return s * y

    return apply


def _start_vector(n: int, d: np.ndarray, start: np.ndarray | None) -> np.ndarray:
    """Starting z = D^½ y for the iterative solvers: ``start`` (a y vector) or random."""
    rng = np.random.default_rng(0)
    x = rng.standard_normal(n)
    if start is not None:
        z0 = np.asarray(start, dtype=float).reshape(n, -1)[:, 0] * np.sqrt(d)
        # a little noise keeps it from lying in the constraint space
        x = z0 + 1e-3 * np.linalg.norm(z0) / np.sqrt(n) * x
    return x


def _block_fiedler(
    Wop, W, d: np.ndarray, start: np.ndarray | None, budget: _Budget
) -> tuple[np.ndarray, bool]:
    """Smallest eigenvector z of N orthogonal to u = D^½ 1 by the block LOBPCG (any W).

    The solver of the dense segments (:func:`_lobpcg`, Jacobi preconditioner, guard
    vectors) on ``Wop``'s products. Returns (z, converged); not converged: the best
    vector when the budget was spent or the solver stalled.
    """
    n = W.shape[0]
    d_is = 1.0 / np.sqrt(d)
    u = np.sqrt(d)[:, None] / np.sqrt(d.sum())
    product = _scaled_product(Wop, d_is)
    precond = 1.0 / np.maximum(1.0 - _diagonal(W) / d, 1e-8)
    size = min(1 + GUARD_VECTORS, n - 1)
    _, Z, _, converged = _lobpcg(
        lambda X: X - product(X),
        precond,
        u,
        _start_candidates(d, precond, [start], size),
        size,
        EIG_TOL,
        GUARD_TOL,
        LOBPCG_MAXITER,
        budget,
    )
    return Z[:, 0], converged


def _lanczos_fiedler(
    Wop,
    d: np.ndarray,
    start: np.ndarray | None,
    tol: float,
    budget: _Budget,
    stop: int | None = None,
) -> np.ndarray:
    """Second eigenvector z of D^−½ W D^−½ by Lanczos, its products charged to ``budget``
    (up to ``stop`` of them); raises ArpackNoConvergence or :class:`_OutOfProducts`."""
    n = Wop.shape[0]
    product = _scaled_product(Wop, 1.0 / np.sqrt(d))
    op = budget.operator(n, product, stop)
    vals, vecs = eigsh(op, k=2, which="LA", v0=_start_vector(n, d, start), tol=tol)
    return vecs[:, np.argsort(vals)[0]]


def _sparse_fiedler(W, d: np.ndarray, start: np.ndarray | None, budget: _Budget) -> np.ndarray:
    """Smallest eigenvector z of N orthogonal to u for a graph solved iteratively as a
    whole (sparse W, or a dense one given to :func:`fiedler_vector` directly).

    Lanczos first, with :data:`LANCZOS_SHARE` of the budget, then the block LOBPCG;
    the block LOBPCG first on a graph that has fallen apart (:data:`FALLEN_APART`).
    The best vector of the block solver when the budget is spent; a dense solve when no
    solver gave any vector.
    """
    Wop = _operator_matrix(W)
    fallen = float(np.min(1.0 - _diagonal(W) / d)) < FALLEN_APART
    best = None

    def block() -> np.ndarray | None:
        nonlocal best
        try:
            z, converged = _block_fiedler(Wop, W, d, start, budget)
        except (_OutOfProducts, np.linalg.LinAlgError):
            return None
        best = z
        return z if converged or budget.capped else None

    def lanczos() -> np.ndarray | None:
        stop = None if fallen else budget.used + int(LANCZOS_SHARE * budget.limit)
        try:
            return _lanczos_fiedler(Wop, d, start, EIG_TOL / 10, budget, stop)
        except (_OutOfProducts, ArpackNoConvergence, np.linalg.LinAlgError, ValueError):
            # a graph that has fallen apart (many near-isolated nodes) has a highly
            # degenerate spectrum where an iterative solver can stall
            return None

    for solve in (block, lanczos) if fallen else (lanczos, block):
        z = solve()
        if z is not None:
            return z
        if budget.capped:
            break
    if best is not None:
        return best
    return _dense_fiedler(W, d)


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
    """Sign of y (or of each column) such that the entry of largest magnitude is positive."""
    if y.ndim == 1:
        return y if y[np.argmax(np.abs(y))] >= 0 else -y
    pivots = y[np.argmax(np.abs(y), axis=0), np.arange(y.shape[1])]
    return y * np.where(pivots >= 0, 1.0, -1.0)


def _check_products(max_products: int) -> int:
    if not isinstance(max_products, (int, np.integer)) or max_products < MIN_CUT_PRODUCTS:
        raise PolarsegError(
            f"max_products must be an integer >= {MIN_CUT_PRODUCTS}, got {max_products!r}"
        )
    return int(max_products)


def fiedler_vector(
    W,
    start: np.ndarray | None = None,
    max_products: int = MAX_CUT_PRODUCTS,
    cancel: Callable[[], bool] | None = None,
) -> np.ndarray:
    """Second-smallest generalized eigenvector y of (D − W) y = λ D y (thesis eq. 4.32).

    Sign fixed so that the entry of largest magnitude is positive. Solvers: module
    docstring (dense ``eigh`` for small graphs; block LOBPCG for large dense W, Lanczos
    for sparse W, each falling back on the other and finally on a dense solve).

    Parameters
    ----------
    W : ndarray or sparse matrix (n, n)
        Symmetric non-negative affinity with positive degrees.
    start : ndarray (n,), optional
        Starting guess (a y vector, e.g. from an earlier affinity) for the iterative
        solvers.
    max_products : int
        Most products with W the iterative solvers may make (module docstring, "Bounded
        work"); past it the best vector found is returned.
    cancel : callable() -> bool, optional
        Called before every product; True raises
        :class:`~napari_polarseg.engine.errors.Cancelled`.
    """
    budget = _Budget(_check_products(max_products), cancel)
    return _fiedler(W, start, budget)


def _fiedler(W, start: np.ndarray | None, budget: _Budget) -> np.ndarray:
    n = W.shape[0]
    if n > DENSE_EIGH_MAX and not sps.issparse(W):
        seg = _DenseGraph(W).segment(np.arange(n))
        return _fix_sign(_segment_vectors(seg, [start], budget)[:, 0])
    d = _degrees(W)
    z = _sparse_fiedler(W, d, start, budget) if n > DENSE_EIGH_MAX else _dense_fiedler(W, d)
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
    if sps.issparse(W):
        Ws = _subgraph(W, order)
        d = np.asarray(Ws.sum(axis=1)).ravel()
        lower = np.asarray(sps.tril(Ws, k=-1).sum(axis=1)).ravel()
        diag = Ws.diagonal()
    else:
        W = np.asarray(W)
        d = W.sum(axis=1, dtype=np.float64)[order]
        diag = np.diagonal(W)[order]
        lower = _lower_prefix_sums(W, order)
    return _split_from_sums(y, order, d, diag, lower, min_size)


def _segment_split(seg: _Segment, y: np.ndarray, min_size: int) -> tuple[np.ndarray | None, float]:
    """:func:`best_split` of a dense segment, reading its rows from the whole matrix."""
    n = y.size
    if n < 2 * min_size or n < 2:
        return None, np.inf
    order = np.argsort(y, kind="stable")
    lower = _lower_prefix_sums(seg.W, order, None if seg.whole else seg.idx)
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


def _lower_prefix_sums(
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
    W, min_size: int = 1, start: np.ndarray | None = None, budget: _Budget | None = None
) -> tuple[np.ndarray | None, float, np.ndarray | None]:
    if W.shape[0] < max(2, 2 * min_size):
        return None, np.inf, None
    y = _fiedler(W, start, budget or _Budget(MAX_CUT_PRODUCTS))
    mask, value = best_split(W, y, min_size)
    return mask, value, y


def bipartition(
    W, min_size: int = 1, max_products: int = MAX_CUT_PRODUCTS
) -> tuple[np.ndarray | None, float]:
    """Best two-way normalized cut of a graph: (mask of one side, Ncut value).

    ``max_products`` caps the eigensolver's products (:func:`fiedler_vector`).
    """
    mask, value, _ = _bipartition(W, min_size, None, _Budget(_check_products(max_products)))
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
    _graph: _DenseGraph | None = field(default=None, init=False, repr=False)
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
    _solving: _Budget | None = field(default=None, init=False, repr=False)
    _cancel: Callable[[], bool] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        n = self.W.shape[0]
        if self.W.shape != (n, n):
            raise PolarsegError(f"affinity must be square, got shape {self.W.shape}")
        self.max_products = _check_products(self.max_products)
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

    def _solve(self, work: Callable[[_Budget], tuple]) -> tuple:
        """``work(budget)`` with a fresh budget, its products and cap counted."""
        budget = _Budget(self.max_products, self._cancel)
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

    def _dense_graph(self) -> _DenseGraph | None:
        """The shared dense graph, for a dense W above DENSE_EIGH_MAX nodes."""
        if self._graph is None and not sps.issparse(self.W) and self.W.shape[0] > DENSE_EIGH_MAX:
            self._graph = _DenseGraph(self.W)
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
                        block = _fix_sign(
                            self._solve(lambda budget: _segment_vectors(seg, starts, budget))
                        )
                        self._blocks[sid] = block
                        self._vectors[idx.tobytes()] = block
                        split = _segment_split(seg, block[:, 0], self.min_size)
                        result = (*split, block[:, 0])
            else:
                sub = self.W if idx.size == self.W.shape[0] else _subgraph(self.W, idx)
                if not sps.issparse(sub):
                    sub = np.asarray(sub, dtype=float)  # small: solved and split in float64
                peeled = None
                if idx.size > DENSE_EIGH_MAX and idx.size >= max(2, 2 * self.min_size):
                    peeled = self._peel(_degrees(sub), _diagonal(sub))
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
        self._history.append(_first_appearance_order(labels))
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


def _first_appearance_order(labels: np.ndarray) -> np.ndarray:
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
