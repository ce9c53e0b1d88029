"""Eigensolvers of the relaxed normalized cut: the Fiedler vector of a graph or segment.

The relaxed Ncut problem (eq. 4.32) is the generalized eigenproblem (D − W) y = λ D y;
with z = D^½ y it is the smallest eigenvector of the normalized Laplacian
N = I − D^−½ W D^−½ orthogonal to u = D^½ 1 (:mod:`.ncut`).

Eigensolvers
------------
- Up to :data:`DENSE_EIGH_MAX` nodes: ``scipy.linalg.eigh`` of the whole normalized
  affinity (exact, and robust to repeated eigenvalues).
- Larger dense W: block LOBPCG (:func:`lobpcg`, Knyazev's method written out here) on
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
- Dense products: :mod:`.dense_graph` (one float32 matrix for the whole tree, BLAS
  ``symv``). Float32 round-off (~1e-7 relative per product) is ten times below
  :data:`EIG_TOL`; degrees, the split search and the Ncut values are summed in float64.
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
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.sparse as sps

from ..errors import PolarsegError
from .budget import MAX_CUT_PRODUCTS, Budget, OutOfProducts, check_products
from .dense_graph import DenseGraph, Segment, degrees, diagonal, operator_matrix, subgraph

#: Graphs up to this many nodes use a dense eigensolver; larger ones are iterative.
DENSE_EIGH_MAX = 300


#: Residual tolerance ‖N z − λ z‖ (unit z) of the iterative eigensolver.
EIG_TOL = 1e-6


#: Iteration cap of LOBPCG before falling back to Lanczos.
LOBPCG_MAXITER = 400


#: Share of the products Lanczos may take when it goes first (sparse graphs that have
#: not fallen apart); the rest is kept for the block LOBPCG.
LANCZOS_SHARE = 0.75


#: A sparse graph has fallen apart when one of its nodes sends less than this share of
#: its degree to other nodes (1 − W_ii / d_i, its singleton cut over its degree): then
#: the block LOBPCG, whose Jacobi preconditioner is what copes with such nodes, goes
#: before Lanczos. The polanalyser frames give 0.83–0.96 with the recommended preset
#: and 2e-14–3e-4 with the thesis preset.
FALLEN_APART = 1e-3


#: Vectors iterated along with the Fiedler vector by the dense LOBPCG (see module doc);
#: with :data:`GUARD_TOL`, the setting that made the fewest products on the reference
#: image's interactive changes (docs/performance.md, "Measurements behind the code").
GUARD_VECTORS = 3


#: Residual tolerance of the guard vectors: they widen the search space and start the
#: children; only the first vector is ever cut along, to :data:`EIG_TOL`.
GUARD_TOL = 0.05


#: Largest graph the last-resort dense eigendecomposition is tried on.
DENSE_FALLBACK_MAX = 12_000


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


def lobpcg(
    apply: Callable[[np.ndarray], np.ndarray],
    precond: np.ndarray,
    u: np.ndarray,
    X0: np.ndarray,
    size: int,
    tol: float,
    guard_tol: float,
    maxiter: int,
    budget: Budget | None = None,
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
    budget: Budget | None = None,
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
    budget : Budget, optional
        Products the solve may make (each column given to ``apply`` is one); when the
        next iteration's products do not fit, the solve stops where it is.

    Returns (eigenvalues (b,), vectors (n, b) ascending, residual of the first, whether
    every vector converged). Not converged: the current Ritz vectors, after ``maxiter``
    iterations, when the budget is spent, or when the residuals lie in the basis already.
    Raises :class:`OutOfProducts` if the budget cannot pay for the first product.
    """
    b = size
    X, AX, lam = _lobpcg_start(apply, u, X0, b, budget)
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


def _lobpcg_start(
    apply: Callable[[np.ndarray], np.ndarray],
    u: np.ndarray,
    X0: np.ndarray,
    b: int,
    budget: Budget | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first block of :func:`_lobpcg_steps`: (X, A X, Ritz values), b columns.

    X0 projected out of u and orthonormalised, filled up with seeded random columns to b,
    then the b lowest Ritz vectors of its span (one product per column). Raises
    :class:`OutOfProducts` if the budget cannot pay for those products.
    """
    n = X0.shape[0]
    rng = np.random.default_rng(0)
    X = _orthonormalize(X0 - u @ (u.T @ X0), u)
    while X.shape[1] < b:
        extra = rng.standard_normal((n, b - X.shape[1]))
        X = np.hstack([X, _orthonormalize(extra, np.hstack([u, X]))])
    if budget is not None and not budget.take(X.shape[1]):
        raise OutOfProducts
    AX = apply(X)
    lam, C = np.linalg.eigh(_sym(X.T @ AX))
    return X @ C[:, :b], AX @ C[:, :b], lam[:b]


def _sym(H: np.ndarray) -> np.ndarray:
    return (H + H.T) / 2


def start_candidates(
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


def _block_vectors(
    laplacian: Callable[[np.ndarray], np.ndarray],
    d: np.ndarray,
    diag: np.ndarray,
    starts: list[np.ndarray | None],
    budget: Budget,
) -> tuple[np.ndarray, bool]:
    """Fiedler and guard vectors z (n, b) of N by the block LOBPCG, and whether converged.

    The one set-up of :func:`lobpcg` for a normalised Laplacian ``laplacian``
    (X ↦ N X) with degrees ``d`` and self loops ``diag``: constraint u = D^½ 1 / ‖·‖,
    Jacobi preconditioner 1 / diag(N) = 1 / (1 − W_ii / d_i), :data:`GUARD_VECTORS`
    guards, start candidates from ``starts`` (y vectors) or :func:`start_candidates`.
    """
    u = np.sqrt(d)[:, None] / np.sqrt(d.sum())
    precond = 1.0 / np.maximum(1.0 - diag / d, 1e-8)
    size = min(1 + GUARD_VECTORS, d.size - 1)
    _, Z, _, converged = lobpcg(
        laplacian,
        precond,
        u,
        start_candidates(d, precond, starts, size),
        size,
        EIG_TOL,
        GUARD_TOL,
        LOBPCG_MAXITER,
        budget,
    )
    return Z, converged


def segment_vectors(seg: Segment, starts: list[np.ndarray], budget: Budget) -> np.ndarray:
    """Generalized eigenvectors y (m, b) of a large dense segment: Fiedler, then guards.

    Block LOBPCG first (module docstring); if it stalls with products left, Lanczos for
    the Fiedler vector alone, with what is left of ``budget``. When the budget is spent
    the block's best vectors are returned (``budget.capped`` tells); a dense solve only
    when no solver gave any vector. Raises PolarsegError if that fails too.
    """
    from scipy.sparse.linalg import ArpackNoConvergence, eigsh  # start-up cost when used

    m = seg.idx.size
    d = seg.d
    d_is = 1.0 / np.sqrt(d)

    def laplacian(X: np.ndarray) -> np.ndarray:
        return X - d_is[:, None] * seg.product(d_is[:, None] * X)

    best = None
    try:
        Z, converged = _block_vectors(laplacian, d, seg.diag, starts, budget)
        best = Z * d_is[:, None]
        if converged or budget.capped:
            return best
    except (OutOfProducts, np.linalg.LinAlgError):
        pass
    start = next((s for s in starts if s is not None), None)
    op = budget.operator(m, lambda x: d_is * seg.product((d_is * x)[:, None])[:, 0])
    try:
        vals, vecs = eigsh(op, k=2, which="LA", v0=_start_vector(m, d, start), tol=1e-8)
        z = vecs[:, np.argsort(vals)[0]]
    except (OutOfProducts, ArpackNoConvergence, np.linalg.LinAlgError, ValueError):
        if best is not None:
            return best
        z = _dense_fiedler(seg.W if seg.whole else subgraph(seg.W, seg.idx), d)
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
    Wop, W, d: np.ndarray, start: np.ndarray | None, budget: Budget
) -> tuple[np.ndarray, bool]:
    """Smallest eigenvector z of N orthogonal to u = D^½ 1 by the block LOBPCG (any W).

    The solver of the dense segments (:func:`lobpcg`, Jacobi preconditioner, guard
    vectors) on ``Wop``'s products. Returns (z, converged); not converged: the best
    vector when the budget was spent or the solver stalled.
    """
    product = _scaled_product(Wop, 1.0 / np.sqrt(d))
    Z, converged = _block_vectors(lambda X: X - product(X), d, diagonal(W), [start], budget)
    return Z[:, 0], converged


def _lanczos_fiedler(
    Wop,
    d: np.ndarray,
    start: np.ndarray | None,
    tol: float,
    budget: Budget,
    stop: int | None = None,
) -> np.ndarray:
    """Second eigenvector z of D^−½ W D^−½ by Lanczos, its products charged to ``budget``
    (up to ``stop`` of them); raises ArpackNoConvergence or :class:`OutOfProducts`."""
    from scipy.sparse.linalg import eigsh  # start-up cost when used

    n = Wop.shape[0]
    product = _scaled_product(Wop, 1.0 / np.sqrt(d))
    op = budget.operator(n, product, stop)
    vals, vecs = eigsh(op, k=2, which="LA", v0=_start_vector(n, d, start), tol=tol)
    return vecs[:, np.argsort(vals)[0]]


def _sparse_fiedler(W, d: np.ndarray, start: np.ndarray | None, budget: Budget) -> np.ndarray:
    """Smallest eigenvector z of N orthogonal to u for a graph solved iteratively as a
    whole (sparse W, or a dense one given to :func:`fiedler_vector` directly).

    Lanczos first, with :data:`LANCZOS_SHARE` of the budget, then the block LOBPCG;
    the block LOBPCG first on a graph that has fallen apart (:data:`FALLEN_APART`).
    The best vector of the block solver when the budget is spent; a dense solve when no
    solver gave any vector.
    """
    from scipy.sparse.linalg import ArpackNoConvergence  # start-up cost when used

    Wop = operator_matrix(W)
    fallen = float(np.min(1.0 - diagonal(W) / d)) < FALLEN_APART
    best = None

    def block() -> np.ndarray | None:
        nonlocal best
        try:
            z, converged = _block_fiedler(Wop, W, d, start, budget)
        except (OutOfProducts, np.linalg.LinAlgError):
            return None
        best = z
        return z if converged or budget.capped else None

    def lanczos() -> np.ndarray | None:
        stop = None if fallen else budget.used + int(LANCZOS_SHARE * budget.limit)
        try:
            return _lanczos_fiedler(Wop, d, start, EIG_TOL / 10, budget, stop)
        except (OutOfProducts, ArpackNoConvergence, np.linalg.LinAlgError, ValueError):
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


def fix_sign(y: np.ndarray) -> np.ndarray:
    """Sign of y (or of each column) such that the entry of largest magnitude is positive."""
    if y.ndim == 1:
        return y if y[np.argmax(np.abs(y))] >= 0 else -y
    pivots = y[np.argmax(np.abs(y), axis=0), np.arange(y.shape[1])]
    return y * np.where(pivots >= 0, 1.0, -1.0)


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
    budget = Budget(check_products(max_products), cancel)
    return solve_fiedler(W, start, budget)


def solve_fiedler(W, start: np.ndarray | None, budget: Budget) -> np.ndarray:
    n = W.shape[0]
    if n > DENSE_EIGH_MAX and not sps.issparse(W):
        seg = DenseGraph(W).segment(np.arange(n))
        return fix_sign(segment_vectors(seg, [start], budget)[:, 0])
    d = degrees(W)
    z = _sparse_fiedler(W, d, start, budget) if n > DENSE_EIGH_MAX else _dense_fiedler(W, d)
    return fix_sign(z / np.sqrt(d))
