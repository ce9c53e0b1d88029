"""Feature selection: block feature vectors, PCA, whitening and Mahalanobis distances.

Thesis sections 4.3.3–4.3.4 (feature vectors and PCA) and eq. 4.27 (the Mahalanobis
distance the affinity of :mod:`..graph.affinity` is built on).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..chunks import chunk_bounds, run_chunks
from ..errors import PolarsegError
from .harmonics import degree_order

FEATURE_KINDS = ("thesis", "zonal", "energy")


@dataclass(frozen=True)
class PCAResult:
    """Block features after PCA.

    Attributes
    ----------
    features : ndarray (n_blocks, n_components)
        Coefficient vectors projected on the principal axes.
    explained_variance_ratio : ndarray (n_components,)
        Share of the total variance each kept component explains.
    components : ndarray (n_components, n_coefficients)
        Principal axes in coefficient space.
    """

    features: np.ndarray
    explained_variance_ratio: np.ndarray
    components: np.ndarray

    @property
    def n_components(self) -> int:
        return int(self.features.shape[1])

    @property
    def explained_variance(self) -> float:
        """Total share of variance kept."""
        return float(self.explained_variance_ratio.sum())


def harmonic_features(coefficients: np.ndarray, kind: str = "thesis") -> np.ndarray:
    """Block feature vectors from spherical-harmonic coefficients.

    Parameters
    ----------
    coefficients : array (..., (L+1)²)
        Block coefficients in thesis order (eq. 4.21).
    kind : {"thesis", "zonal", "energy"}
        ``"thesis"``: every coefficient a_lm (thesis section 4.5).
        ``"zonal"``: the m = 0 coefficients a_l0 = mean(Î Y_l0(θ)) only. They depend on
        how Î is distributed over the zenith alone, not on the surface azimuth, whose
        block-to-block variation otherwise dominates the PCA while saying nothing about
        the material (the 180° azimuth ambiguity makes it noisier still).
        ``"energy"``: rotation-invariant energy per degree, √(Σ_m a_lm²).

    Returns
    -------
    ndarray (n_blocks, n_features)
    """
    c = np.asarray(coefficients, dtype=float)
    c = c.reshape(-1, c.shape[-1])
    degree = int(round(np.sqrt(c.shape[1]))) - 1
    if (degree + 1) ** 2 != c.shape[1]:
        raise PolarsegError(f"{c.shape[1]} coefficients is not (L+1)² for any degree L")
    if kind == "thesis":
        return c
    ls, ms = degree_order(degree)
    if kind == "zonal":
        return c[:, ms == 0]
    if kind == "energy":
        sq = c * c
        return np.sqrt(np.stack([sq[:, ls == l].sum(axis=1) for l in range(degree + 1)], 1))  # noqa: E741
    raise PolarsegError(f"feature kind must be one of {', '.join(FEATURE_KINDS)}; got {kind!r}")


def pca_features(vectors: np.ndarray, variance: float = 0.95) -> PCAResult:
    """PCA of block vectors keeping the components that explain ``variance`` of the total.

    Thesis section 4.3.3 (Karhunen–Loève transform); the thesis keeps 95 %, typically 4–5
    components out of (L+1)² coefficients.

    Parameters
    ----------
    vectors : array (n_blocks, n_coefficients)
        One coefficient vector per block (any leading shape is flattened).
    variance : float in (0, 1]
        Share of variance to keep; 1 keeps every component with non-zero variance.
    """
    x = np.asarray(vectors, dtype=float)
    x = x.reshape(-1, x.shape[-1])
    if x.shape[0] < 2:
        raise PolarsegError(f"need at least 2 blocks for PCA, got {x.shape[0]}")
    if not np.all(np.isfinite(x)):
        raise PolarsegError("block feature vectors contain NaN or infinite values")
    if not (0 < variance <= 1):
        raise PolarsegError(f"variance share must be in (0, 1], got {variance!r}")
    total = x.var(axis=0).sum()
    if not total > 1e-300:
        raise PolarsegError("all blocks have identical features: nothing to segment")
    # Eigendecomposition of the covariance (what scikit-learn's "covariance_eigh" solver
    # does): (L+1)² × (L+1)² instead of an SVD of the n_blocks × (L+1)² data, ~10 times
    # faster here, and no 1 s scikit-learn import on the first run.
    centred = x - x.mean(axis=0)
    evals, evecs = np.linalg.eigh(centred.T @ centred)
    evals, evecs = np.clip(evals[::-1], 0.0, None), evecs[:, ::-1]
    # scikit-learn's sign convention: the largest |entry| of each component is positive
    pivot = np.argmax(np.abs(evecs), axis=0)
    evecs = evecs * np.sign(evecs[pivot, np.arange(evecs.shape[1])])
    n_max = min(x.shape)
    evals, evecs = evals[:n_max], evecs[:, :n_max]
    ratio = evals / evals.sum()
    # keep the fewest components whose cumulative share reaches the target; shares at
    # the round-off level of the eigensolver count as zero variance
    keep = int(np.searchsorted(np.cumsum(ratio), variance - 1e-12) + 1)
    keep = max(1, min(keep, int(np.count_nonzero(ratio > 1e-12)) or 1))
    return PCAResult(
        features=centred @ evecs[:, :keep],
        explained_variance_ratio=ratio[:keep],
        components=evecs[:, :keep].T,
    )


def whiten(features: np.ndarray) -> np.ndarray:
    """Map features so that Euclidean distance equals Mahalanobis distance (eq. 4.24).

    Uses the covariance over all blocks with the 1/L normalisation of eq. 4.26 and its
    (pseudo-)inverse Σ⁻¹ — eq. 4.27 as printed writes Σ where Σ⁻¹ is meant.
    Returns (X − mean) Σ^(−1/2).
    """
    x = np.asarray(features, dtype=float)
    x = x.reshape(-1, x.shape[-1])
    centred = x - x.mean(axis=0)
    cov = centred.T @ centred / x.shape[0]  # eq. 4.26
    evals, evecs = np.linalg.eigh(cov)
    tol = evals.max(initial=0.0) * 1e-12
    inv_sqrt = np.where(evals > tol, 1.0 / np.sqrt(np.where(evals > tol, evals, 1.0)), 0.0)
    return centred @ (evecs * inv_sqrt)


def sq_distances(
    z: np.ndarray,
    scale: float | None = None,
    dtype: np.dtype | type = np.float64,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """‖z_i − z_j‖² for all pairs (n × n), optionally turned into exp(−D / s).

    One fused pass per chunk of rows (matrix product, then in-place additions, clipping
    and exponential while the chunk is in cache), chunks spread over the cores. Each
    chunk is computed in float64 and stored as ``dtype`` (into ``out`` when given).
    """
    n = z.shape[0]
    sq = np.einsum("ij,ij->i", z, z)
    if out is None:
        out = np.empty((n, n), dtype=dtype)
    elif out.shape != (n, n) or out.dtype != np.dtype(dtype):
        raise ValueError(f"out must be a ({n}, {n}) {np.dtype(dtype)} array")
    direct = out.dtype == np.float64

    def work(a: int, b: int) -> None:
        blk = out[a:b] if direct else np.empty((b - a, n))
        np.matmul(z[a:b], z.T, out=blk)
        blk *= -2.0
        blk += sq[a:b, None]
        blk += sq[None, :]
        np.maximum(blk, 0.0, out=blk)
        blk[np.arange(b - a), np.arange(a, b)] = 0.0
        if scale is not None:
            blk *= -1.0 / scale
            np.exp(blk, out=blk)
        if not direct:
            out[a:b] = blk

    step = max(1, 2**16 // max(n, 1))
    run_chunks(chunk_bounds(n, step), work, n * n // 8)
    return out


def mahalanobis_sq(
    features: np.ndarray, dtype: np.dtype | type = np.float64, out: np.ndarray | None = None
) -> np.ndarray:
    """Dense matrix of squared Mahalanobis distances D_k1k2 between blocks (eq. 4.27, Σ⁻¹).

    D = (A_k1 − A_k2)ᵀ Σ⁻¹ (A_k1 − A_k2), computed as ‖z_i‖² + ‖z_j‖² − 2 z_i·z_j on the
    whitened features z (a matrix product instead of a pairwise loop), in float64 and
    stored as ``dtype`` (float32 halves the memory of a large graph), into ``out`` when
    given. Dimensionless.
    """
    return sq_distances(whiten(features), dtype=dtype, out=out)
