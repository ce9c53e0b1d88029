"""Block affinities S = exp(−D / s) of the graph the normalized cut partitions.

Thesis section 4.5: dense (all pairs), sparse k nearest neighbours in feature space, or
sparse spatial neighbourhoods (Shi & Malik eq. 11), D the squared Mahalanobis distance of
eq. 4.27 (:func:`~napari_polarseg.engine.features.pca.mahalanobis_sq`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..chunks import chunk_bounds, run_chunks
from ..errors import PolarsegError
from ..features.pca import sq_distances, whiten


def median_offdiagonal(d: np.ndarray) -> float:
    """Median of the off-diagonal entries of a symmetric matrix, from its upper triangle.

    Every off-diagonal value appears twice, so the median of the strict upper triangle is
    the median of all off-diagonal entries; it is gathered row by row (no n × n mask) into
    one copy that the median then partitions in place.
    """
    n = d.shape[0]
    if n < 2:
        raise PolarsegError("the median distance needs at least 2 blocks")
    upper = np.concatenate([d[i, i + 1 :] for i in range(n - 1)])
    return float(np.median(upper, overwrite_input=True))


SCALE_MODES = ("absolute", "median")


def _check_scale(scale: float, scale_mode: str) -> None:
    if not scale > 0:
        raise PolarsegError(f"affinity scale must be positive, got {scale!r}")
    if scale_mode not in SCALE_MODES:
        raise PolarsegError(f"scale mode must be one of {SCALE_MODES}, got {scale_mode!r}")


def effective_scale(scale: float, scale_mode: str, median: float | None) -> float:
    """The s of exp(−D / s): ``scale``, or ``scale`` times the median D in median mode."""
    _check_scale(scale, scale_mode)
    if scale_mode == "absolute":
        return scale
    if median is None:
        raise PolarsegError("the median scale mode needs the median distance")
    return scale * (median if median > 0 else 1.0)


def affinity_from_distances(
    d: np.ndarray, scale: float, out: np.ndarray | None = None
) -> np.ndarray:
    """exp(−D / s) for a dense D (:func:`mahalanobis_sq`), in D's dtype.

    Thesis section 4.5 with the effective s (:func:`effective_scale`). Lets a caller
    that keeps D (the pipeline does) change s with one pass over the matrix, in row
    chunks on the cores. ``out`` (may be ``d`` itself) receives it, else a new array.
    """
    if not scale > 0:
        raise PolarsegError(f"affinity scale must be positive, got {scale!r}")
    n = d.shape[0]
    out = np.empty_like(d) if out is None else out
    factor = np.asarray(-1.0 / scale, dtype=d.dtype)

    def work(a: int, b: int) -> None:
        np.multiply(d[a:b], factor, out=out[a:b])
        np.exp(out[a:b], out=out[a:b])

    step = max(1, 2**18 // max(n, 1))
    run_chunks(chunk_bounds(n, step), work, n * n // 8)
    return out


def affinity_matrix(
    features: np.ndarray,
    scale: float = 1.0,
    scale_mode: str = "absolute",
    dtype: np.dtype | type = np.float64,
) -> np.ndarray:
    """Block affinity S(k1, k2) = exp(−D_k1k2 / s) (thesis section 4.5; s = 1 there).

    D is the squared Mahalanobis distance of eq. 4.27 (a quadratic form, as printed).
    Dense: n_blocks² values of ``dtype`` (see :func:`knn_affinity` for large block
    counts).

    Parameters
    ----------
    features : array (n_blocks, n_features)
    scale : float
        s > 0.
    scale_mode : {"absolute", "median"}
        ``"absolute"`` uses s as given (the thesis). ``"median"`` divides by s times the
        median off-diagonal D: the squared Mahalanobis distance between two blocks grows
        like twice the number of kept components, so with 10–20 components an absolute
        s = 1 gives affinities of e^−30 and a graph that falls apart into single blocks;
        the median makes s dimensionless (s = 1: a typical pair has affinity 1/e).
    dtype : float64 or float32
        Precision of the stored matrix (every entry is computed in float64).
    """
    _check_scale(scale, scale_mode)
    z = whiten(features)
    if scale_mode == "absolute" or z.shape[0] < 2:
        return sq_distances(z, scale, dtype)
    d = sq_distances(z, dtype=dtype)
    s = effective_scale(scale, scale_mode, median_offdiagonal(d))
    return affinity_from_distances(d, s, out=d)


#: Neighbours per block of the sparse feature-space affinity (:func:`knn_affinity`).
#: 30 reproduces the dense cut (ARI 1.000) on the three 120 × 130 sample scenes at the
#: thesis scale, where 10–20 miss a few blocks on one of them; on a 19,584-block camera
#: frame it costs 1.1 s of Lanczos against 0.6 s for 15.
KNN_NEIGHBORS = 30
#: Block pairs sampled to estimate the median distance for a sparse affinity.
MEDIAN_SAMPLE_PAIRS = 200_000


def _sampled_median_sq(z: np.ndarray, seed: int = 0) -> float:
    """Median of ‖z_i − z_j‖² over i ≠ j, estimated from random pairs (seeded).

    With 200,000 pairs the estimate is within ~0.5 % of the exact median (its standard
    error is about 1.25 σ / √pairs relative to the density at the median); exact for
    graphs small enough to hold every pair.
    """
    n = z.shape[0]
    if n * (n - 1) // 2 <= MEDIAN_SAMPLE_PAIRS:
        i, j = np.triu_indices(n, 1)
    else:
        rng = np.random.default_rng(seed)
        i = rng.integers(0, n, MEDIAN_SAMPLE_PAIRS)
        j = (i + rng.integers(1, n, MEDIAN_SAMPLE_PAIRS)) % n  # never equal to i
    diff = z[i] - z[j]
    return float(np.median(np.einsum("ij,ij->i", diff, diff)))


def _sparse_from_pairs(n: int, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray):
    """Symmetric CSR matrix with unit diagonal from (i, j, value) pairs with i != j.

    A pair present in both directions keeps one value (the same value either way), so
    the result is the union of the neighbourhoods (max(W, Wᵀ) for k nearest neighbours).
    """
    import scipy.sparse as sps

    off = sps.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    off.sum_duplicates()
    off = off.maximum(off.T)
    return (off + sps.identity(n, format="csr")).tocsr()


#: Blocks per chunk of the nearest-neighbour search when it reports progress (a few
#: tenths of a second of brute-force distances each on a 2-core machine).
KNN_QUERY_ROWS = 2048


def knn_affinity(
    features: np.ndarray,
    scale: float = 1.0,
    scale_mode: str = "absolute",
    n_neighbors: int = KNN_NEIGHBORS,
    progress: Callable[[float], None] | None = None,
):
    """Sparse block affinity: exp(−D / s) between each block and its k nearest neighbours.

    The same affinity as :func:`affinity_matrix` (thesis section 4.5, D the squared
    Mahalanobis distance of eq. 4.27), kept only for the ``n_neighbors`` nearest blocks
    of each block in feature space (``sklearn.neighbors.NearestNeighbors`` on the
    whitened features, where Euclidean distance is Mahalanobis distance), symmetrised
    as the union of the neighbourhoods, with the unit self-affinity on the diagonal.
    Memory and time grow like n_blocks · k instead of n_blocks², which is what lets a
    polarisation-camera frame (≈ 20,000 blocks) be segmented.

    The pairs left out are the farther ones, whose affinities are the smallest; with the
    thesis scale (s = 1, 10–20 components) they are ~e^−30 anyway, and the normalized
    cut is the dense one. With a *wide* kernel (``scale_mode="median"``, or s of the order
    of the distances) every block is strongly tied to most others, which no k-nearest-
    neighbour graph represents: the cut then differs from the dense one (adjusted Rand
    index 0.2–0.5 between them on the sample scenes). Use a spatial term
    (:func:`spatial_affinity`, exact) or the dense affinity where that matters.
    ``scale_mode="median"`` uses the median distance of a seeded random sample of block
    pairs (:data:`MEDIAN_SAMPLE_PAIRS`) instead of all pairs. ``progress`` is called
    with the share of the blocks whose neighbours are found, after every
    :data:`KNN_QUERY_ROWS` of them (it may raise to stop the search there).

    Returns
    -------
    scipy.sparse.csr_matrix (n_blocks, n_blocks)
    """
    _check_scale(scale, scale_mode)
    from sklearn.neighbors import NearestNeighbors

    z = whiten(features)
    n = z.shape[0]
    k = int(min(max(n_neighbors, 1), n - 1))
    if scale_mode == "median":
        med = _sampled_median_sq(z)
        scale = scale * (med if med > 0 else 1.0)
    # brute force (BLAS distance blocks): 1.0 s for 19,584 blocks in 15 dimensions, where
    # the default k-d tree takes 1.8 s and a ball tree 2.8 s
    search = NearestNeighbors(n_neighbors=k + 1, algorithm="brute").fit(z)
    if progress is None:
        dist, ind = search.kneighbors(z)
    else:  # the same queries in row chunks, with a checkpoint before each
        progress(0.0)
        parts = []
        for top in range(0, n, KNN_QUERY_ROWS):
            parts.append(search.kneighbors(z[top : top + KNN_QUERY_ROWS]))
            progress(min(top + KNN_QUERY_ROWS, n) / n)
        dist = np.concatenate([d for d, _ in parts])
        ind = np.concatenate([i for _, i in parts])
    rows = np.repeat(np.arange(n), k + 1)
    cols = ind.ravel()
    keep = rows != cols
    vals = np.exp(-(dist.ravel()[keep] ** 2) / scale)
    return _sparse_from_pairs(n, rows[keep], cols[keep], vals)


def _grid_offsets(radius: float) -> list[tuple[int, int]]:
    r = int(np.floor(radius))
    return [
        (dr, dc)
        for dr in range(-r, r + 1)
        for dc in range(-r, r + 1)
        if (dr or dc) and dr * dr + dc * dc <= radius * radius
    ]


def spatial_affinity(
    features: np.ndarray,
    grid: tuple[int, int],
    radius: float,
    sigma: float,
    scale: float = 1.0,
    scale_mode: str = "absolute",
):
    """Sparse exp(−D / s) · exp(−‖X_i − X_j‖² / σ_X²) for blocks closer than ``radius``.

    Exactly :func:`affinity_matrix` times :func:`spatial_kernel` (Shi & Malik eq. 11;
    thesis section 4.5), stored only where the spatial term is non-zero: about π r²
    entries per block, so it needs neither the dense matrix nor any approximation.
    ``grid`` is the (rows, cols) block grid of the features (row-major); ``radius`` and
    ``sigma`` are in blocks. ``scale_mode="median"`` uses all pairs up to
    :data:`MEDIAN_SAMPLE_PAIRS`, else a seeded random sample of them.
    """
    _check_scale(scale, scale_mode)
    if not radius > 0 or not sigma > 0:
        raise PolarsegError(f"spatial radius and sigma must be positive, got {radius}, {sigma}")
    z = whiten(features)
    nr, nc = grid
    n = nr * nc
    if z.shape[0] != n:
        raise PolarsegError(f"{z.shape[0]} feature vectors do not fill a {nr} x {nc} grid")
    if scale_mode == "median":
        med = _sampled_median_sq(z)
        scale = scale * (med if med > 0 else 1.0)
    rr, cc = np.divmod(np.arange(n), nc)
    rows, cols, vals = [], [], []
    for dr, dc in _grid_offsets(radius):
        ok = (rr + dr >= 0) & (rr + dr < nr) & (cc + dc >= 0) & (cc + dc < nc)
        i = np.flatnonzero(ok)
        j = i + dr * nc + dc
        diff = z[i] - z[j]
        d2 = np.einsum("ij,ij->i", diff, diff)
        rows.append(i)
        cols.append(j)
        vals.append(np.exp(-d2 / scale - (dr * dr + dc * dc) / (sigma * sigma)))
    if not rows:
        import scipy.sparse as sps

        return sps.identity(n, format="csr")
    return _sparse_from_pairs(n, np.concatenate(rows), np.concatenate(cols), np.concatenate(vals))


def spatial_kernel(grid: tuple[int, int], radius: float, sigma: float) -> np.ndarray:
    """Shi & Malik's spatial term between blocks on a (rows, cols) grid.

    exp(−‖X_i − X_j‖² / σ_X²) for block centres closer than ``radius`` (both in block
    units), 0 beyond. Multiplying the feature affinity by it makes the cut compare each
    block with its neighbours only, so slow variations across the image (curvature,
    shading) matter less than local changes of material. Shi & Malik (2000), eq. 11.
    """
    if not radius > 0 or not sigma > 0:
        raise PolarsegError(f"spatial radius and sigma must be positive, got {radius}, {sigma}")
    rows, cols = np.indices(grid)
    pos = np.stack([rows.ravel(), cols.ravel()], axis=1).astype(float)
    d2 = ((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1)
    return np.where(d2 <= radius * radius, np.exp(-d2 / (sigma * sigma)), 0.0)
