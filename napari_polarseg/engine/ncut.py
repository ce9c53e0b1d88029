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
  Fiedler vectors live there. On the 4,752-block reference image plain Lanczos
  (``eigsh``) needs ~400 products per cut, LOBPCG 30–60 (~100 from a cold start on
  the n = 1.6 affinity). A cold solve starts from random vectors and the indicators of
  the blocks with the smallest diag(N).
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
  half the memory traffic of ``gemv``; 1.4 ms against 2.8 ms at 4,752 nodes). A segment
  with more than :data:`COPY_MAX_FRACTION` of the nodes is multiplied through the whole
  matrix (scatter into zeros, product, gather: W[s][:, s] x = (W x̃)[s]); a smaller one
  gets its own float32 copy. Float32 round-off (~1e-7 relative per product) is ten
  times below :data:`EIG_TOL`; degrees, the split search and the Ncut values are
  summed in float64.
- Sparse W (k nearest neighbours, spatial neighbourhoods): Lanczos (``eigsh``, two
  eigenpairs of D^−½ W D^−½, tolerance EIG_TOL / 10). Products are cheap there and
  LOBPCG's per-iteration overhead dominates (4 s against 0.5 s on a 19,584-block
  camera frame). pyamg is not used: Lanczos already takes well under a second.
- Each falls back on the other, and finally on a dense solve (up to
  :data:`DENSE_FALLBACK_MAX` nodes).
- A :class:`CutTree` can be warm-started from the eigenvectors of an earlier tree on
  the same blocks (the pipeline does this when the affinity changed but not the block
  grid, e.g. its scale or the refractive index): each segment's solve also starts from
  the vectors of the smallest old segment containing it, restricted to it (reference
  image, s = 1 → 2: 85 instead of 101 products for the first two cuts).

The splitting point along y is the one with the lowest Ncut value (eq. 4.29) over *all*
thresholds between distinct values of y, found in one pass with cumulative sums.

Segments are split greedily: at each step the segment whose best bipartition has the
lowest Ncut is split, until the requested number of segments, an Ncut threshold, or the
minimum segment size stops it. The sequence of splits is cached, so asking for fewer or
more segments later costs nothing or only the extra splits; :meth:`CutTree.prefetch`
solves the next split's candidates ahead (the plugin does it in idle time).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sps
from scipy.linalg.blas import get_blas_funcs
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh, lobpcg

from .errors import PolarsegError

#: Graphs up to this many nodes use a dense eigensolver; larger ones are iterative.
DENSE_EIGH_MAX = 300
#: Residual tolerance ‖N z − λ z‖ (unit z) of the iterative eigensolver.
EIG_TOL = 1e-6
#: Iteration cap of LOBPCG before falling back to Lanczos.
LOBPCG_MAXITER = 400
#: Vectors iterated along with the Fiedler vector by the dense LOBPCG (see module doc).
#: Products for the cuts of the reference image's interactive changes (k = 3, the 4th
#: cut, s = 2, n = 1.6, and the same with the recommended preset), summed: 1 guard at
#: tolerance 1e-2 480, 2 at 1e-2 452, 2 at 3e-2 410, 3 at 5e-2 398, 4 at 5e-2 407.
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
    here OpenBLAS's gemm was slower than the symv calls (6 columns: ~10 ms against
    ~9 ms), and after a gemm or a gemv on a large matrix the next few dozen symv calls
    ran 3–5 times slower on the reference machine (so the tree uses no gemv either).
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
        from .harmonics import run_chunks

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
            run_chunks([(a, min(n, a + step)) for a in range(0, n, step)], work, n * n // 8)
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


def _lobpcg(
    apply: Callable[[np.ndarray], np.ndarray],
    precond: np.ndarray,
    u: np.ndarray,
    X0: np.ndarray,
    size: int,
    tol: float,
    guard_tol: float,
    maxiter: int,
) -> tuple[np.ndarray, np.ndarray, float]:
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

    Returns (eigenvalues (b,), vectors (n, b) ascending, residual of the first); raises
    ArpackNoConvergence after ``maxiter`` iterations.
    """
    n, b = X0.shape[0], size
    rng = np.random.default_rng(0)
    X = _orthonormalize(X0 - u @ (u.T @ X0), u)
    while X.shape[1] < b:
        extra = rng.standard_normal((n, b - X.shape[1]))
        X = np.hstack([X, _orthonormalize(extra, np.hstack([u, X]))])
    AX = apply(X)
    lam, C = np.linalg.eigh(_sym(X.T @ AX))
    X, AX, lam = X @ C[:, :b], AX @ C[:, :b], lam[:b]
    P = AP = None
    tols = np.full(b, guard_tol)
    tols[0] = tol
    for _ in range(maxiter):
        R = AX - X * lam
        resid = _column_norms(R)
        active = resid > tols
        if not active.any():
            return lam, X, float(resid[0])
        ub = np.hstack([u, X] if P is None else [u, X, P])
        Wk = _orthonormalize(precond[:, None] * R[:, active], ub)
        if Wk.shape[1] == 0:  # residuals inside the basis: nothing new to add
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
    raise ArpackNoConvergence("LOBPCG did not converge", lam, X)


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


def _segment_vectors(seg: _Segment, starts: list[np.ndarray]) -> np.ndarray:
    """Generalized eigenvectors y (m, b) of a large dense segment: Fiedler, then guards.

    Block LOBPCG first (module docstring); then Lanczos and a dense solve for the Fiedler
    vector alone. Raises PolarsegError if all fail.
    """
    m = seg.idx.size
    d = seg.d
    d_is = 1.0 / np.sqrt(d)
    u = np.sqrt(d)[:, None] / np.sqrt(d.sum())

    def laplacian(X: np.ndarray) -> np.ndarray:
        return X - d_is[:, None] * seg.product(d_is[:, None] * X)

    precond = 1.0 / np.maximum(1.0 - seg.diag / d, 1e-8)
    size = min(1 + GUARD_VECTORS, m - 1)
    try:
        _, Z, _ = _lobpcg(
            laplacian,
            precond,
            u,
            _start_candidates(d, precond, starts, size),
            size,
            EIG_TOL,
            GUARD_TOL,
            LOBPCG_MAXITER,
        )
        return Z * d_is[:, None]
    except (ArpackNoConvergence, np.linalg.LinAlgError):
        pass
    start = next((s for s in starts if s is not None), None)
    op = LinearOperator(
        (m, m), matvec=lambda x: d_is * seg.product((d_is * np.ravel(x))[:, None])[:, 0]
    )
    try:
        vals, vecs = eigsh(op, k=2, which="LA", v0=_start_vector(m, d, start), tol=1e-8)
        z = vecs[:, np.argsort(vals)[0]]
    except (ArpackNoConvergence, np.linalg.LinAlgError, ValueError):
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
        z0 = np.asarray(start, dtype=float).reshape(n, -1)[:, 0] * np.sqrt(d)
        # a little noise keeps it from lying in the constraint space
        x = z0 + 1e-3 * np.linalg.norm(z0) / np.sqrt(n) * x
    return x


def _lobpcg_fiedler(Wop, W, d: np.ndarray, start: np.ndarray | None) -> np.ndarray:
    """Smallest eigenvector z of N orthogonal to u = D^½ 1 by scipy's LOBPCG (sparse W)."""
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
    """Sign of y (or of each column) such that the entry of largest magnitude is positive."""
    if y.ndim == 1:
        return y if y[np.argmax(np.abs(y))] >= 0 else -y
    pivots = y[np.argmax(np.abs(y), axis=0), np.arange(y.shape[1])]
    return y * np.where(pivots >= 0, 1.0, -1.0)


def fiedler_vector(W, start: np.ndarray | None = None) -> np.ndarray:
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
    """
    n = W.shape[0]
    if n > DENSE_EIGH_MAX and not sps.issparse(W):
        seg = _DenseGraph(W).segment(np.arange(n))
        return _fix_sign(_segment_vectors(seg, [start])[:, 0])
    d = _degrees(W)
    z = None
    if n > DENSE_EIGH_MAX:
        Wop = _operator_matrix(W)
        solvers = (
            lambda: _lanczos_fiedler(Wop, d, start, EIG_TOL / 10),
            lambda: _lobpcg_fiedler(Wop, W, d, start),
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
    from .harmonics import run_chunks

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
    bounds = [(a, min(rows.size, a + step)) for a in range(0, rows.size, step)]
    run_chunks(bounds, work, rows.size * n // 8)
    if rows.size != m:
        sums = sums[nodes]
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

    A large dense W is kept once (plus one float32 copy for the products) for the whole
    tree; each segment's eigensolve starts from its parent's eigenvectors restricted to
    it (module docstring).
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
                    starts = [self._warm_start(idx), self._starts.get(sid)]
                    block = _fix_sign(_segment_vectors(seg, starts))
                    self._blocks[sid] = block
                    self._vectors[idx.tobytes()] = block
                    result = (*_segment_split(seg, block[:, 0], self.min_size), block[:, 0])
            else:
                sub = self.W if idx.size == self.W.shape[0] else _subgraph(self.W, idx)
                if not sps.issparse(sub):
                    sub = np.asarray(sub, dtype=float)  # small: solved and split in float64
                warm = None if self.warm is None else self.warm.get(idx.tobytes())
                result = _bipartition(sub, self.min_size, warm)
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
        self._ncut_values.append(best_val)
        return True

    def prefetch(self) -> Iterator[int]:
        """Solve the candidate split of every current segment not solved yet.

        What the next split (``labels(k + 1)`` after ``labels(k)`` reached the tree's
        current k segments) computes first, so that afterwards it only compares the
        candidates: an idle-time precomputation (the plugin runs it after showing a
        result). Yields the position of each segment solved, so that a caller can stop
        between two solves; the results are exactly those ``labels`` would compute.
        """
        if self._exhausted:
            return
        for pos in range(len(self._segments)):
            if self._ids[pos] not in self._candidates:
                self._candidate(pos)
                yield pos

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
