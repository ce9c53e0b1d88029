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
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sps
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh

from .errors import PolarsegError
from .ncut import _degrees, _first_appearance_order

#: Graphs up to this many nodes are decomposed densely.
DENSE_MAX = 1_500
#: Eigenvectors computed beyond the k first asked for (cheap re-use when k grows).
EXTRA_VECTORS = 3
#: k-means restarts and seed (fixed, so a run is reproducible).
KMEANS_INIT = 10
KMEANS_SEED = 0


def normalized_eigenvectors(W, k: int) -> np.ndarray:
    """The k largest eigenvectors of D^−½ W D^−½ as columns (n, k), largest first.

    Dense ``eigh`` up to :data:`DENSE_MAX` nodes, Lanczos (``eigsh``) on a product
    operator above (W is never normalised in memory), dense again if Lanczos fails.
    """
    n = W.shape[0]
    k = int(min(k, n))
    d_is = 1.0 / np.sqrt(_degrees(W))  # checks for isolated nodes
    if n > DENSE_MAX and k < n - 1:
        Wm = W.tocsr() if sps.issparse(W) else np.asarray(W, dtype=np.float64)

        def product(x: np.ndarray) -> np.ndarray:
            x = np.asarray(x)
            scale = d_is if x.ndim == 1 else d_is[:, None]
            return scale * (Wm @ (scale * x))

        op = LinearOperator((n, n), matvec=product, matmat=product, dtype=float)
        v0 = np.sqrt(1.0 / d_is)  # the known top eigenvector D^½ 1 is a good start
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                vals, vecs = eigsh(op, k=k, which="LA", v0=v0, tol=1e-8)
            return vecs[:, np.argsort(vals)[::-1]]
        except ArpackNoConvergence:
            pass  # a graph fallen apart into isolated blocks: dense is robust there
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

    Same interface as :class:`~napari_polarseg.engine.ncut.CutTree` where the pipeline
    uses it: ``labels(k)`` and ``ncut_values`` (here the two-way Ncut value of every
    segment of the last partition against the rest, :func:`kway_ncut`).
    """

    W: np.ndarray | sps.spmatrix
    min_size: int = 1
    _vectors: np.ndarray | None = field(default=None, init=False)
    _labels: dict[int, np.ndarray] = field(default_factory=dict, init=False)
    _ncut: list[float] = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        n = self.W.shape[0]
        if self.W.shape != (n, n):
            raise PolarsegError(f"affinity must be square, got shape {self.W.shape}")
        if n < 1:
            raise PolarsegError("affinity has no nodes")

    @property
    def ncut_values(self) -> list[float]:
        """Two-way Ncut of each segment of the last partition returned."""
        return list(self._ncut)

    def embedding(self, k: int) -> np.ndarray:
        """Row-normalised first k eigenvectors (n, k): the points k-means clusters."""
        n = self.W.shape[0]
        k = min(k, n)
        if self._vectors is None or self._vectors.shape[1] < k:
            self._vectors = normalized_eigenvectors(self.W, min(n, k + EXTRA_VECTORS))
        z = self._vectors[:, :k]
        norm = np.linalg.norm(z, axis=1, keepdims=True)
        return z / np.where(norm > 0, norm, 1.0)

    def labels(self, k: int) -> np.ndarray:
        """Node labels 0..k'−1 (k' <= k after merging segments below the minimum size)."""
        from sklearn.cluster import KMeans

        if k < 1:
            raise PolarsegError(f"number of segments must be >= 1, got {k}")
        n = self.W.shape[0]
        k = min(k, n, max(1, n // self.min_size))
        if k not in self._labels:
            if k == 1:
                lab = np.zeros(n, dtype=np.int32)
            else:
                x = self.embedding(k)
                km = KMeans(k, n_init=KMEANS_INIT, random_state=KMEANS_SEED).fit(x)
                lab = self._merge_small(km.labels_, x, km.cluster_centers_)
            self._labels[k] = _first_appearance_order(lab)
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
