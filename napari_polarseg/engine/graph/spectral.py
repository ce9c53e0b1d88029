"""k-way spectral clustering: an alternative to the thesis's recursive two-way cuts.

The thesis (section 4.4.1) splits the block graph recursively, one Fiedler vector at a
time, which is greedy: an early split cannot be undone. Here the same affinity W is
partitioned into k segments at once (Ng, Jordan & Weiss 2002, "On spectral clustering";
Shi & Malik 2000, section 3.3's "simultaneous k-way cut"):

1. the k largest eigenvectors Z of the normalized affinity D^−½ W D^−½ (equivalently the
   k smallest generalized eigenvectors of (D − W) y = λ D y, with y = D^−½ z — thesis
   eq. 4.32 for k vectors instead of one);
2. every row of Z scaled to unit length (the spectral embedding of the blocks);
3. k-means (scikit-learn, 10 restarts, fixed seed) on those rows.

The eigenvectors are computed once for a few more than the k asked for
(:data:`EXTRA_VECTORS`), so changing the number of segments reuses them and only reruns
k-means. Segments smaller than the minimum size are merged into the segment whose
k-means centre is nearest; the labels are numbered in order of first appearance, as the
recursive cut's are.

The eigensolve's work is bounded as the recursive cut's is (:mod:`.ncut`, "Bounded
work"): Lanczos may make :data:`~napari_polarseg.engine.graph.eigensolver.LANCZOS_SHARE` of
``max_products`` products with the affinity, then the block LOBPCG (Jacobi
preconditioner, which copes with a graph that has fallen apart) the rest, after which
its best vectors are used and the decomposition is counted as capped
(:meth:`SpectralClustering.cut_limits`); normal inputs stay well below the cap
(docs/performance.md, "Measurements behind the code"). ``cancel``
(called before every product) stops it with
:class:`~napari_polarseg.engine.errors.Cancelled`.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sps
from scipy.sparse.linalg import ArpackNoConvergence, eigsh

from ..errors import PolarsegError
from .budget import MAX_CUT_PRODUCTS, Budget, OutOfProducts, check_products
from .dense_graph import degrees, diagonal
from .eigensolver import EIG_TOL, LANCZOS_SHARE, LOBPCG_MAXITER, lobpcg, start_candidates
from .ncut import first_appearance_order

#: Graphs up to this many nodes are decomposed densely.
DENSE_MAX = 1_500
#: Eigenvectors computed beyond the k first asked for (cheap re-use when k grows).
EXTRA_VECTORS = 3
#: k-means restarts and seed (fixed, so a run is reproducible).
KMEANS_INIT = 10
KMEANS_SEED = 0


def normalized_eigenvectors(
    W,
    k: int,
    max_products: int = MAX_CUT_PRODUCTS,
    cancel: Callable[[], bool] | None = None,
) -> np.ndarray:
    """The k largest eigenvectors of D^−½ W D^−½ as columns (n, k), largest first.

    Dense ``eigh`` up to :data:`DENSE_MAX` nodes; above, Lanczos (``eigsh``) on a product
    operator (W is never normalised in memory), then the block LOBPCG if Lanczos has not
    converged within its share of ``max_products`` products (module docstring); dense
    again if both fail outright. ``cancel`` is called before every product (True raises
    :class:`~napari_polarseg.engine.errors.Cancelled`).
    """
    return _eigenvectors(W, k, Budget(check_products(max_products), cancel))


def _eigenvectors(W, k: int, budget: Budget) -> np.ndarray:
    n = W.shape[0]
    k = int(min(k, n))
    d = degrees(W)  # checks for isolated nodes
    d_is = 1.0 / np.sqrt(d)
    if n > DENSE_MAX and k < n - 1:
        Wm = W.tocsr() if sps.issparse(W) else np.asarray(W, dtype=np.float64)

        def product(x: np.ndarray) -> np.ndarray:
            x = np.asarray(x)
            scale = d_is if x.ndim == 1 else d_is[:, None]
            return scale * (Wm @ (scale * x))

        op = budget.operator(n, product, int(LANCZOS_SHARE * budget.limit))
        v0 = np.sqrt(1.0 / d_is)  # the known top eigenvector D^½ 1 is a good start
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                vals, vecs = eigsh(op, k=k, which="LA", v0=v0, tol=1e-8)
            return vecs[:, np.argsort(vals)[::-1]]
        except (ArpackNoConvergence, OutOfProducts):
            pass  # a graph fallen apart into isolated blocks: the block solver copes
        # the k − 1 smallest eigenvectors of N = I − D^−½ W D^−½ orthogonal to its
        # known smallest one, u = D^½ 1 (the largest of D^−½ W D^−½)
        u = np.sqrt(d)[:, None] / np.sqrt(d.sum())
        precond = 1.0 / np.maximum(1.0 - diagonal(W) / d, 1e-8)
        try:
            _, Z, _, _ = lobpcg(
                lambda X: X - product(X),
                precond,
                u,
                start_candidates(d, precond, [], k - 1),
                k - 1,
                EIG_TOL,
                EIG_TOL,
                LOBPCG_MAXITER,
                budget,
            )
            return np.hstack([u, Z])
        except (OutOfProducts, np.linalg.LinAlgError):
            pass
    dense = W.toarray() if sps.issparse(W) else np.asarray(W, dtype=np.float64)
    vals, vecs = scipy.linalg.eigh(dense * d_is[:, None] * d_is[None, :])
    return vecs[:, ::-1][:, :k]


def kway_ncut(W, labels: np.ndarray) -> np.ndarray:
    """Two-way Ncut value of every segment against the rest (thesis eq. 4.29).

    ``cut(A, Ā) / assoc(A, V) + cut(A, Ā) / assoc(Ā, V)`` for each segment A; the
    k-way normalized cut of Shi & Malik is the sum of the first terms.
    """
    labels = np.asarray(labels)
    k = int(labels.max()) + 1
    onehot = sps.csr_matrix((np.ones(labels.size), (np.arange(labels.size), labels)))
    WA = (W @ onehot) if sps.issparse(W) else np.asarray(W) @ onehot.toarray()
    WA = np.asarray(WA.toarray() if sps.issparse(WA) else WA)
    within = np.array([WA[labels == a, a].sum() for a in range(k)])
    assoc = np.array([WA[labels == a].sum() for a in range(k)])
    total = assoc.sum()
    cut = assoc - within
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((assoc > 0) & (total - assoc > 0), cut / assoc + cut / (total - assoc), 0.0)


@dataclass
class SpectralClustering:
    """k-way spectral clustering of one affinity, eigenvectors cached across k.

    Same interface as :class:`~napari_polarseg.engine.graph.ncut.CutTree` where the pipeline
    uses it: ``labels(k)`` and ``ncut_values`` (here the two-way Ncut value of every
    segment of the last partition against the rest, :func:`kway_ncut`).
    """

    W: np.ndarray | sps.spmatrix
    min_size: int = 1
    _vectors: np.ndarray | None = field(default=None, init=False)
    _labels: dict[int, np.ndarray] = field(default_factory=dict, init=False)
    _ncut: list[float] = field(default_factory=list, init=False)
    #: products one eigendecomposition may make (module docstring)
    max_products: int = MAX_CUT_PRODUCTS
    _counts: dict[str, int] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        n = self.W.shape[0]
        if self.W.shape != (n, n):
            raise PolarsegError(f"affinity must be square, got shape {self.W.shape}")
        if n < 1:
            raise PolarsegError("affinity has no nodes")
        self.max_products = check_products(self.max_products)
        self._counts = {"eigensolver_capped": 0, "isolated_skipped": 0, "products": 0}

    def cut_limits(self, k: int | None = None) -> dict[str, int]:
        """How often the work limit acted, as :meth:`.ncut.CutTree.cut_limits` says it:
        ``eigensolver_capped`` (decompositions that spent ``max_products``),
        ``isolated_skipped`` (always 0 here), ``products``, ``max_products``; over the
        decompositions made so far (``k`` is accepted for the same interface)."""
        return {**self._counts, "max_products": self.max_products}

    @property
    def ncut_values(self) -> list[float]:
        """Two-way Ncut of each segment of the last partition returned."""
        return list(self._ncut)

    def embedding(self, k: int, cancel: Callable[[], bool] | None = None) -> np.ndarray:
        """Row-normalised first k eigenvectors (n, k): the points k-means clusters.

        ``cancel`` is called before every product of a decomposition (True raises
        :class:`~napari_polarseg.engine.errors.Cancelled`).
        """
        n = self.W.shape[0]
        k = min(k, n)
        if self._vectors is None or self._vectors.shape[1] < k:
            budget = Budget(self.max_products, cancel)
            try:
                self._vectors = _eigenvectors(self.W, min(n, k + EXTRA_VECTORS), budget)
            finally:
                self._counts["products"] += budget.used
                self._counts["eigensolver_capped"] += int(budget.capped)
        z = self._vectors[:, :k]
        norm = np.linalg.norm(z, axis=1, keepdims=True)
        return z / np.where(norm > 0, norm, 1.0)

    def labels(self, k: int, cancel: Callable[[], bool] | None = None) -> np.ndarray:
        """Node labels 0..k'−1 (k' <= k after merging segments below the minimum size).

        ``cancel``: see :meth:`embedding`.
        """
        from sklearn.cluster import KMeans

        if k < 1:
            raise PolarsegError(f"number of segments must be >= 1, got {k}")
        n = self.W.shape[0]
        k = min(k, n, max(1, n // self.min_size))
        if k not in self._labels:
            if k == 1:
                lab = np.zeros(n, dtype=np.int32)
            else:
                x = self.embedding(k, cancel)
                km = KMeans(k, n_init=KMEANS_INIT, random_state=KMEANS_SEED).fit(x)
                lab = self._merge_small(km.labels_, x, km.cluster_centers_)
            self._labels[k] = first_appearance_order(lab)
        lab = self._labels[k]
        self._ncut = [float(v) for v in kway_ncut(self.W, lab)] if lab.max() > 0 else []
        return lab.copy()

    def _merge_small(self, lab: np.ndarray, x: np.ndarray, centres: np.ndarray) -> np.ndarray:
        """Give the nodes of segments below ``min_size`` to the nearest larger segment."""
        lab = lab.copy()
        while True:
            sizes = np.bincount(lab, minlength=centres.shape[0])
            small = np.flatnonzero((sizes > 0) & (sizes < self.min_size))
            big = np.flatnonzero(sizes >= self.min_size)
            if small.size == 0 or big.size == 0:
                return lab
            s = small[np.argmin(sizes[small])]
            members = lab == s
            d = ((x[members][:, None, :] - centres[big][None]) ** 2).sum(-1)
            lab[members] = big[np.argmin(d, axis=1)]
