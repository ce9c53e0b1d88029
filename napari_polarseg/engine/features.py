"""Feature selection and affinity: PCA of block coefficient vectors, Mahalanobis distance.

Thesis sections 4.3.3–4.3.4 and 4.5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import PolarsegError
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
    from sklearn.decomposition import PCA  # imported here: it costs ~1 s at start-up

    n_max = min(x.shape)
    pca = PCA(n_components=n_max, svd_solver="full")
    scores = pca.fit_transform(x)
    ratio = pca.explained_variance_ratio_
    # keep the fewest components whose cumulative share reaches the target
    keep = int(np.searchsorted(np.cumsum(ratio), variance - 1e-12) + 1)
    keep = max(1, min(keep, int(np.count_nonzero(ratio > 1e-15)) or 1))
    return PCAResult(
        features=scores[:, :keep],
        explained_variance_ratio=ratio[:keep],
        components=pca.components_[:keep],
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


def mahalanobis_sq(features: np.ndarray) -> np.ndarray:
    """Dense matrix of squared Mahalanobis distances D_k1k2 between blocks (eq. 4.27, Σ⁻¹).

    D = (A_k1 − A_k2)ᵀ Σ⁻¹ (A_k1 − A_k2), computed as ‖z_i‖² + ‖z_j‖² − 2 z_i·z_j on the
    whitened features z (a matrix product instead of a pairwise loop).
    """
    z = whiten(features)
    sq = np.einsum("ij,ij->i", z, z)
    d = sq[:, None] + sq[None, :] - 2.0 * (z @ z.T)
    np.maximum(d, 0.0, out=d)
    np.fill_diagonal(d, 0.0)
    return d


SCALE_MODES = ("absolute", "median")


def affinity_matrix(
    features: np.ndarray, scale: float = 1.0, scale_mode: str = "absolute"
) -> np.ndarray:
    """Block affinity S(k1, k2) = exp(−D_k1k2 / s) (thesis section 4.5; s = 1 there).

    D is the squared Mahalanobis distance of eq. 4.27 (a quadratic form, as printed).

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
    """
    if not scale > 0:
        raise PolarsegError(f"affinity scale must be positive, got {scale!r}")
    if scale_mode not in SCALE_MODES:
        raise PolarsegError(f"scale mode must be one of {SCALE_MODES}, got {scale_mode!r}")
    d = mahalanobis_sq(features)
    if scale_mode == "median" and d.shape[0] > 1:
        off = d[~np.eye(d.shape[0], dtype=bool)]
        med = float(np.median(off))
        scale = scale * (med if med > 0 else 1.0)
    d /= -scale
    return np.exp(d, out=d)


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
