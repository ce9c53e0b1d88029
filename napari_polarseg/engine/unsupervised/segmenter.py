"""Unsupervised segmentation on a graph of superpixels.

The thesis pipeline cuts a graph of square w × w blocks, which straddle the material
boundaries and, at the thesis scale, falls apart into single blocks on real frames
(issue 13). Here the nodes are superpixels that follow the edges of the polarisation
image, each described by a few statistics of its pixels, and the clustering works on
those few hundred to few thousand nodes:

1. **Superpixels** (:func:`polarisation_superpixels`): a compact watershed (as
   :func:`.superpixels.superpixels`) over the sum of the gradient magnitudes of the
   smoothed log Î and of the smoothed normalised Stokes components s1 = S1/S0,
   s2 = S2/S0 (so a region border sits on an intensity *or* a polarisation edge).
2. **Node features** (:func:`node_features`), from region sums (``np.bincount``) of
   per-pixel products, each named once in :data:`NODE_FEATURES`: the region's mean
   log Î, its spread, mean ρ and its spread, the region's DoLP
   |(ΣS1, ΣS2)| / ΣS0, the AoLP coherence |mean e^{2iφ}|, DoLP / mean ρ and, as the
   physical material cue (thesis section 6.2), the slope and correlation of ρ against
   log Î inside the region: within one material the shading and ρ both follow the
   zenith, their relation depends on n and the depolarisation, not on the tilt; and
   the same cue taken image-wide, log ρ̄ less a cubic in log Î fitted over all regions
   (:func:`dop_given_intensity`).
   Optionally the per-pixel feature stack of :mod:`.pixel_features` averaged per region.
   The features are standardised (weighted by region area), may be diffused over the
   region graph but not across its edges (``UnsupervisedParams.diffusion``) and are
   reduced by PCA to the
   components that explain ``variance`` of the total (:func:`.features.pca_features`).
3. **Clustering** (``UnsupervisedParams.clustering``): a Gaussian mixture (scikit-learn
   ``GaussianMixture``, full covariances, seeded) or k-means weighted by region area
   (:func:`.kmeans.weighted_kmeans`) on the node features, with an
   optional smoothing of the posteriors over the region adjacency (a few iterations of
   P ← (1 − λ) P + λ A P, A the row-normalised shared-border lengths), or the thesis's
   Mahalanobis affinity exp(−D / s) (:func:`.features.whiten`, s = ``scale`` × the
   median D over the graph's edges) restricted to neighbouring regions, cut by recursive
   normalized cuts (:func:`.ncut.recursive_ncut`) or k-way spectral clustering
   (:class:`.spectral.SpectralClustering`).

**Close-ups of one smooth surface** (:mod:`.shape_trend`): when the square of one
linear field explains more than ``close_up_share`` of the superpixels' complex
polarisation ρ e^{2iφ} — one curved surface fills the frame, as in a fruit inspection
crop — mean ρ and shading follow the tilt, not the material, so the node feature is the
departure of the polarisation from that surface's trend alone
(``dop_over_shape_trend``, :meth:`.params.UnsupervisedParams.close_up_params`). The
result says so (``UnsupervisedResult.close_up``, ``surface_share``).

Every pixel takes its region's label; then the pixels on a segment border move to the
neighbouring segment whose mean (log Î, ρ) they resemble most (:func:`refine_boundaries`,
:data:`REFINE_PASSES` one-pixel passes: a watershed border on a straight edge can sit
a few pixels off).
Deterministic: every random step is seeded.

Defaults (``UnsupervisedParams()``), measured with ``benchmarks/evaluate_unsupervised.py``
on the rendered scenes and the hand-labelled real frames together: superpixels on log Î
and Stokes edges; node features mean log Î, mean ρ, spread of ρ (a material that
depolarises more, or is rougher, polarises less and less evenly at every tilt) and the
material cue's slope of ρ against log Î (how polarisation follows the shading, set by n
and the depolarisation rather than the tilt); standardised, winsorised at ± 2 standard
deviations (a superpixel straddling two materials has an outlying spread and slope),
then diffused over the region graph but not across its edges (:mod:`.region_diffusion`,
λ = 0.5, reach 7 % of the image side, τ = 0.75 × the median border strength), so that
each superpixel carries the features of the surface it lies on rather than of its own
small patch of tilt; k-means (10 restarts, area-weighted); posterior smoothing λ = 0.3
over 5 iterations. Without the diffusion a real fruit falls apart by its shading into
as many segments as it has tones of ρ, and mean log Î merged the camouflage net with
the foliage whose shading it follows; with it, both help. The correlation of ρ and
log Î (the other half of the cue) and the AoLP coherence split the real camera's mat;
the cue taken image-wide (:func:`dop_given_intensity`) helps some renders and hurts
others; a Gaussian mixture sometimes fits one tiny component; the multi-scale pixel
stack splits the camera's mat by shading; the graph cuts on neighbouring regions peel
off single regions. The benchmark prints every variant.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sps
from scipy import ndimage

from ..analysis.degenerate import degenerate_result
from ..errors import PolarsegError
from ..features.pca import pca_features, whiten
from ..features.pixel_features import EPS_DOP, EPS_INTENSITY, check_maps
from .kmeans import squared_distances, weighted_kmeans
from .params import NODE_FEATURES, TREND, UnsupervisedParams, UnsupervisedResult
from .region_diffusion import diffuse, diffusion_steps, edge_aware_adjacency
from .shape_trend import (
    polarisation_over_trend,
    region_centroids,
    region_polarisation,
    surface_trend_share,
)
from .superpixels import COMPACTNESS

#: σ (pixels) of the smoothing before the edge maps of the superpixels are taken.
EDGE_SIGMA = 1.5
#: Most passes of :func:`refine_boundaries` (each moves a border by at most one pixel;
#: the passes stop when one moves nothing).
REFINE_PASSES = 5
#: Seedings of the k-means (:func:`.kmeans.weighted_kmeans`; the lowest inertia wins).
KMEANS_RESTARTS = 10
#: Degree of the image-wide polynomial of :func:`dop_given_intensity`.
RESIDUAL_DEGREE = 3


def superpixel_edges(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    polarisation_edge_weight: float = 1.0,
) -> np.ndarray:
    """Edge map (H, W), dimensionless: |∇(G * log Î)| / m_log + w · |∇(G * (s1, s2))| / m_s.

    s1 = ρ cos 2φ and s2 = ρ sin 2φ are the Stokes components normalised by S0, G a
    Gaussian of :data:`EDGE_SIGMA` px, each gradient divided by its median m over the
    image (so the two edge maps weigh alike whatever the units) and
    w = ``polarisation_edge_weight`` (0: log Î alone).
    """
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY))
    edges = ndimage.gaussian_gradient_magnitude(log_i, EDGE_SIGMA)
    edges /= max(float(np.median(edges)), 1e-12)
    if polarisation_edge_weight > 0:
        pol = np.hypot(
            ndimage.gaussian_gradient_magnitude(dop * np.cos(2 * phase), EDGE_SIGMA),
            ndimage.gaussian_gradient_magnitude(dop * np.sin(2 * phase), EDGE_SIGMA),
        )
        edges += polarisation_edge_weight * pol / max(float(np.median(pol)), 1e-12)
    return edges


def polarisation_superpixels(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    region_area: int,
    polarisation_edge_weight: float = 1.0,
    edges: np.ndarray | None = None,
) -> np.ndarray:
    """Superpixels (H, W) int32, 0 … n − 1, following intensity and polarisation edges.

    A compact watershed from a grid of ``H·W / region_area`` seeds over the edge map of
    :func:`superpixel_edges` (``edges``, computed when not given).
    """
    from skimage.segmentation import watershed

    if edges is None:
        edges = superpixel_edges(intensity, dop, phase, polarisation_edge_weight)
    n = max(2, int(round(intensity.size / region_area)))
    labels = watershed(edges, markers=n, compactness=COMPACTNESS)
    return _relabel(labels)


def _relabel(labels: np.ndarray) -> np.ndarray:
    """Labels renumbered 0 … n − 1 (ascending, no gaps)."""
    _, inverse = np.unique(labels.ravel(), return_inverse=True)
    return inverse.reshape(labels.shape).astype(np.int32)


def region_adjacency(regions: np.ndarray) -> sps.csr_matrix:
    """Shared border length (4-neighbour pixel pairs) between every two regions, (n, n)."""
    n = int(regions.max()) + 1
    pairs = []
    for a, b in ((regions[:, :-1], regions[:, 1:]), (regions[:-1], regions[1:])):
        differ = a != b
        pairs.append((a[differ], b[differ]))
    rows = np.concatenate([p[0] for p in pairs])
    cols = np.concatenate([p[1] for p in pairs])
    m = sps.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
    return (m + m.T).tocsr()


def _region_sums(flat: np.ndarray, n: int, maps: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: np.bincount(flat, weights=v.ravel(), minlength=n) for k, v in maps.items()}


def node_features(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    regions: np.ndarray,
    names: tuple[str, ...] = NODE_FEATURES,
    trend: tuple[int, float, int] = TREND,
) -> np.ndarray:
    """Per-region features (n, len(names)) float64, each of :data:`NODE_FEATURES`;
    ``trend`` = (degree, reach, iterations) of ``dop_over_shape_trend``
    (:func:`.shape_trend.polarisation_over_trend`).

    Computed from region sums of Î, S1, S2, log Î, (log Î)², ρ, ρ², ρ log Î, cos 2φ and
    sin 2φ (one ``np.bincount`` each); variances and covariances are differences of
    means of log Î centred on its median.
    """
    flat = regions.ravel()
    n = int(flat.max()) + 1
    count = np.maximum(np.bincount(flat, minlength=n), 1).astype(float)
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY)).astype(np.float64)
    log_i -= np.median(log_i)
    d = dop.astype(np.float64)
    c, s = np.cos(2 * phase.astype(np.float64)), np.sin(2 * phase.astype(np.float64))
    sums = _region_sums(
        flat,
        n,
        {
            "s0": intensity.astype(np.float64),
            "s1": intensity * d * c,
            "s2": intensity * d * s,
            "l": log_i,
            "ll": log_i * log_i,
            "d": d,
            "dd": d * d,
            "ld": log_i * d,
            "c": c,
            "s": s,
        },
    )
    m = {k: v / count for k, v in sums.items()}
    var_l = np.maximum(m["ll"] - m["l"] ** 2, 0)
    var_d = np.maximum(m["dd"] - m["d"] ** 2, 0)
    cov = m["ld"] - m["l"] * m["d"]
    dolp = np.hypot(sums["s1"], sums["s2"]) / np.maximum(sums["s0"], EPS_INTENSITY)
    make = {
        "log_intensity": lambda: m["l"],
        "intensity_spread": lambda: np.sqrt(var_l),
        "dop": lambda: m["d"],
        "dop_spread": lambda: np.sqrt(var_d),
        "dolp": lambda: dolp,
        "aolp_coherence": lambda: np.hypot(m["c"], m["s"]),
        "dolp_over_dop": lambda: dolp / (m["d"] + EPS_DOP),
        "dop_vs_log_intensity_slope": lambda: cov / (var_l + 1e-6),
        "dop_vs_log_intensity_corr": lambda: cov / np.sqrt(var_l * var_d + 1e-12),
        "log_dop_given_intensity": lambda: dop_given_intensity(m["l"], m["d"], count),
        "dop_over_shape_trend": lambda: _over_trend(regions, sums, count, trend),
    }
    return np.stack([make[k]() for k in names], axis=1)


def _over_trend(
    regions: np.ndarray, sums: dict[str, np.ndarray], count: np.ndarray, trend: tuple
) -> np.ndarray:
    """:func:`.shape_trend.polarisation_over_trend` from the region sums; ``trend`` =
    (degree, reach, iterations)."""
    z = (sums["s1"] + 1j * sums["s2"]) / np.maximum(sums["s0"], EPS_INTENSITY)
    centroid = region_centroids(regions, count)
    return polarisation_over_trend(z, count, centroid, regions.shape, *trend)


def dop_given_intensity(
    log_intensity: np.ndarray, dop: np.ndarray, weight: np.ndarray, degree: int = RESIDUAL_DEGREE
) -> np.ndarray:
    """log ρ̄ − f(log Î), f the polynomial of ``degree`` fitted over all regions
    (least squares weighted by ``weight``, the regions' areas): the material cue taken
    image-wide. Where one material covers most of the image, f is its ρ–shading
    relation, and a region of another material (other n, other depolarisation) lies off
    it at whatever tilt; ρ̄ and log Î are the regions' means.
    """
    y = np.log(dop + EPS_DOP)
    x = log_intensity - np.average(log_intensity, weights=weight)
    scale = max(float(np.sqrt(np.average(x * x, weights=weight))), 1e-12)
    coef = np.polynomial.polynomial.polyfit(x / scale, y, degree, w=np.sqrt(weight))
    return y - np.polynomial.polynomial.polyval(x / scale, coef)


def _standardise(x: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Columns centred and scaled to unit spread (weighted by ``weight``)."""
    w = weight / weight.sum()
    mean = w @ x
    std = np.sqrt(w @ (x - mean) ** 2)
    return (x - mean) / np.where(std > 1e-12, std, 1.0)


def maf_features(
    x: np.ndarray,
    adjacency: sps.csr_matrix,
    weight: np.ndarray,
    variance: float = 0.95,
    components: int = 4,
) -> np.ndarray:
    """Maximum autocorrelation factors (Switzer & Green 1984) of node features (n, c).

    After a PCA keeping ``variance`` (dropping the directions without variance), the
    directions v that minimise vᵀ C_d v / vᵀ C v, C the covariance of the nodes and C_d
    the covariance of the differences between neighbouring nodes (weighted by their
    shared border): the combinations of features that vary least between neighbours
    for their total spread — what is coherent over whole surfaces (material) rather
    than noise. The first ``components`` factors, each with unit variance.
    """
    z = pca_features(x, variance).features
    z = z / np.maximum(z.std(axis=0), 1e-12)
    coo = sps.triu(adjacency, 1).tocoo()
    diff = z[coo.row] - z[coo.col]
    cd = (diff * coo.data[:, None]).T @ diff / max(float(coo.data.sum()), 1e-12)
    c = np.cov(z, rowvar=False, aweights=weight).reshape(z.shape[1], z.shape[1])
    import scipy.linalg

    vals, vecs = scipy.linalg.eigh(cd, c + 1e-9 * np.eye(c.shape[0]))
    f = (z - z.mean(axis=0)) @ vecs[:, : min(components, z.shape[1])]
    return f / np.maximum(f.std(axis=0), 1e-12)


def _cluster_mixture(
    z: np.ndarray, k: int, weight: np.ndarray, adjacency: sps.csr_matrix, p: UnsupervisedParams
) -> np.ndarray:
    """Node labels of a Gaussian mixture or k-means, posteriors smoothed over adjacency."""
    if p.clustering == "gmm":
        from sklearn.mixture import GaussianMixture
        from threadpoolctl import threadpool_limits

        # a few thousand nodes in a few dimensions: threaded BLAS on tiny matrices
        # only spins (18 ms per 3 × 3 triangular solve on a loaded 2-core machine)
        with threadpool_limits(1):
            gm = GaussianMixture(
                k, covariance_type=p.covariance, n_init=3, random_state=p.seed, reg_covar=1e-4
            ).fit(z)
            post = gm.predict_proba(z)
    else:
        fit = weighted_kmeans(z, k, weight, n_init=KMEANS_RESTARTS, seed=p.seed)
        d = squared_distances(z, fit.centres)
        post = np.exp(-(d - d.min(axis=1, keepdims=True)) / 2)
        post /= post.sum(axis=1, keepdims=True)
    # the posteriors smoothed by the same lazy walk as the features (module docstring)
    post = diffuse(post, adjacency, p.smoothing, p.smoothing_iterations)
    return np.argmax(post, axis=1)


def _cluster_graph(
    z: np.ndarray, k: int, adjacency: sps.csr_matrix, p: UnsupervisedParams
) -> np.ndarray:
    """Node labels of a normalized cut of the Mahalanobis affinity on neighbouring regions."""
    from ..graph.ncut import recursive_ncut
    from ..graph.spectral import SpectralClustering

    n = z.shape[0]
    w = whiten(z)
    coo = sps.triu(adjacency, 1).tocoo()
    i, j = coo.row, coo.col
    dist = ((w[i] - w[j]) ** 2).sum(axis=1)
    med = float(np.median(dist)) if dist.size else 1.0
    vals = np.exp(-dist / (p.scale * (med if med > 0 else 1.0)))
    off = sps.coo_matrix((vals, (i, j)), shape=(n, n)).tocsr()
    W = (off + off.T + sps.identity(n, format="csr")).tocsr()
    if p.clustering == "ncut":
        return recursive_ncut(W, k)
    return SpectralClustering(W).labels(k)


def refine_boundaries(
    labels: np.ndarray,
    intensity: np.ndarray,
    dop: np.ndarray,
    n_labels: int,
    spread: np.ndarray | None = None,
) -> np.ndarray:
    """Pixels on a segment border moved to the neighbouring segment they resemble most.

    For every pixel with a different label in its 3 × 3 neighbourhood: the label, among
    those of the neighbourhood, whose segment mean of (log Î, ρ) is nearest in units of
    ``spread``, the pooled within-segment spread of each (computed from ``labels`` when
    not given). One pass (each moves a border by at most a pixel), vectorised over the
    border pixels only.
    """
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY)).astype(np.float64)
    maps = np.stack([log_i, dop.astype(np.float64)])
    flat = labels.ravel()
    count = np.maximum(np.bincount(flat, minlength=n_labels), 1)
    means = np.stack([np.bincount(flat, m.ravel(), n_labels) / count for m in maps])
    if spread is None:
        resid = maps - means[:, labels]
        spread = np.sqrt((resid.reshape(2, -1) ** 2).mean(axis=1)) + 1e-12
    # the labels of the 3 × 3 neighbourhood of every pixel (edge-padded), as 9 planes
    pad = np.pad(labels, 1, mode="edge")
    h, w = labels.shape
    near = np.stack([pad[r : r + h, c : c + w] for r in range(3) for c in range(3)])
    border = (near != labels).any(axis=0)
    if not border.any():
        return labels
    cand = near[:, border]  # (9, b) candidate labels of each border pixel
    x = maps[:, border] / spread[:, None]  # (2, b)
    mu = means / spread[:, None]  # (2, k)
    d = ((x[:, None, :] - mu[:, cand]) ** 2).sum(axis=0)  # (9, b)
    out = labels.copy()
    out[border] = cand[np.argmin(d, axis=0), np.arange(cand.shape[1])]
    return out


def within_spread(labels: np.ndarray, intensity: np.ndarray, dop: np.ndarray) -> np.ndarray:
    """Pooled within-segment standard deviation of log Î and of ρ, (2,): the units of
    :func:`refine_boundaries`."""
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY)).astype(np.float64)
    flat = labels.ravel()
    n = int(flat.max()) + 1
    count = np.maximum(np.bincount(flat, minlength=n), 1)
    out = []
    for m in (log_i.ravel(), dop.astype(np.float64).ravel()):
        mean = np.bincount(flat, m, n) / count
        out.append(np.sqrt(np.mean((m - mean[flat]) ** 2)) + 1e-12)
    return np.array(out)


def _first_appearance(labels: np.ndarray, node_labels: np.ndarray) -> tuple[np.ndarray, ...]:
    """Segments renumbered in order of first appearance in ``labels`` (row-major)."""
    flat = labels.ravel()
    _, first = np.unique(flat, return_index=True)
    values = flat[np.sort(first)]
    order = np.zeros(int(max(flat.max(), node_labels.max())) + 1, dtype=np.int32)
    order[values] = np.arange(values.size, dtype=np.int32)
    return order[labels], order[node_labels]


def _region_features(
    i: np.ndarray, d: np.ndarray, ph: np.ndarray, regions: np.ndarray, p: UnsupervisedParams
) -> tuple[np.ndarray, list[str]]:
    """Node features (n, c) of the superpixels, non-finite values 0, and their names: the
    region features of :func:`node_features`, then the region means of pixel features."""
    names = list(p.features)
    trend = (p.trend_degree, p.trend_reach, p.trend_iterations)
    cols = [node_features(i, d, ph, regions, p.features, trend)] if p.features else []
    if p.pixel_scales:
        from ..features.pixel_features import PixelFeatureParams, pixel_features
        from .superpixels import region_means

        stack = pixel_features(
            i,
            d,
            ph,
            PixelFeatureParams(scales=p.pixel_scales, groups=p.pixel_groups),
        )
        cols.append(region_means(stack.planes, regions).T.astype(np.float64))
        names += [f"pixel:{nm}" for nm in stack.names]
    x = np.concatenate(cols, axis=1)
    return np.where(np.isfinite(x), x, 0.0), names


def _cluster_regions(
    x: np.ndarray,
    weight: np.ndarray,
    regions: np.ndarray,
    edges: np.ndarray,
    adjacency: sps.csr_matrix,
    k: int,
    p: UnsupervisedParams,
) -> tuple[np.ndarray, np.ndarray]:
    """(projected node features z, node labels) for k >= 2 segments: standardised and
    clipped features, diffused over the region graph, projected (PCA or MAF), clustered."""
    xs = _standardise(x, weight)
    if p.clip > 0:
        xs = np.clip(xs, -p.clip, p.clip)
    steps = diffusion_steps(p.diffusion_range, x.shape[0], p.diffusion)
    if steps:  # after the standardising: a column of mere noise shrinks, not rescaled
        graph = edge_aware_adjacency(regions, edges, p.diffusion_tau)
        xs = diffuse(xs, graph, p.diffusion, steps)
    if p.projection == "maf":
        z = maf_features(xs, adjacency, weight, p.variance, p.components)
    else:
        z = pca_features(xs, p.variance).features
    if p.clustering in ("gmm", "kmeans"):
        return z, _cluster_mixture(z, k, weight, adjacency, p)
    return z, _cluster_graph(z, k, adjacency, p)


def _refined(labels: np.ndarray, i: np.ndarray, d: np.ndarray, k: int) -> np.ndarray:
    """Labels after up to :data:`REFINE_PASSES` passes of :func:`refine_boundaries`."""
    spread = within_spread(labels, i, d)
    for _ in range(REFINE_PASSES):
        moved = refine_boundaries(labels, i, d, k, spread)
        if np.array_equal(moved, labels):
            break  # converged: no border pixel moved
        labels = moved
    return labels.astype(np.int32)


def _checked_k(shape: tuple[int, ...], n_segments: int) -> int:
    """``n_segments`` as an int >= 1, or :class:`PolarsegError` (also for a tiny image)."""
    if min(shape) < 2:
        raise PolarsegError(f"image too small to segment: {shape}")
    try:
        k = int(n_segments)
    except (TypeError, ValueError):
        raise PolarsegError(f"n_segments must be an integer >= 1, got {n_segments!r}") from None
    if k < 1 or k != n_segments:
        raise PolarsegError(f"n_segments must be an integer >= 1, got {n_segments!r}")
    return k


def _superpixels(
    i: np.ndarray, d: np.ndarray, ph: np.ndarray, p: UnsupervisedParams
) -> tuple[np.ndarray, np.ndarray]:
    """(superpixels, their edge map) of ``p.boundary`` (module docstring, step 1)."""
    area = p.area_of(i.shape)
    edge_weight = p.polarisation_edge_weight if p.boundary == "polarisation" else 0.0
    edges = superpixel_edges(i, d, ph, edge_weight)
    if p.boundary == "polarisation":
        return polarisation_superpixels(i, d, ph, area, edges=edges), edges
    from .superpixels import superpixels

    return _relabel(superpixels(i, area)), edges


def segment_unsupervised(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    n_segments: int,
    params: UnsupervisedParams | None = None,
) -> UnsupervisedResult:
    """Segment a polarisation image into materials without training (module docstring).

    Parameters
    ----------
    intensity, dop, phase : array (H, W)
        Î (units of the input), ρ in [0, 1], φ radians (thesis eq. 3.14).
    n_segments : int
        Number of segments k (≥ 1).
    params : UnsupervisedParams, optional
        Superpixels, node features and clustering (default ``UnsupervisedParams()``).

    Returns
    -------
    UnsupervisedResult
        Pixel labels (each pixel its superpixel's), node labels, the superpixels.

    Raises
    ------
    PolarsegError
        Maps of different shapes or not 2-D, k < 1, or fewer superpixels than k.
    """
    t0 = time.perf_counter()
    p = params or UnsupervisedParams()
    i, d, ph = check_maps(intensity, dop, phase)
    k = _checked_k(i.shape, n_segments)
    regions, edges = _superpixels(i, d, ph, p)
    n = int(regions.max()) + 1
    if n < k:
        area = p.area_of(i.shape)
        raise PolarsegError(
            f"only {n} superpixels for {k} segments: lower region_area (now {area} px)"
        )
    z_region, count, centroid = region_polarisation(i, d, ph, regions)
    share = surface_trend_share(z_region, count, centroid, i.shape)
    close_up = share > p.close_up_share
    q = p.close_up_params() if close_up else p
    x, names = _region_features(i, d, ph, regions, q)
    weight = np.bincount(regions.ravel(), minlength=n).astype(float)
    adjacency = region_adjacency(regions)
    if k == 1:
        node_labels = np.zeros(n, dtype=np.int32)
        z = np.zeros((n, 0))
    else:
        z, node_labels = _cluster_regions(x, weight, regions, edges, adjacency, k, q)
    node_labels = np.asarray(node_labels, dtype=np.int32)
    labels = node_labels[regions]
    if q.refine_boundaries and k > 1:
        labels = _refined(labels, i, d, int(node_labels.max()) + 1)
    labels, node_labels = _first_appearance(labels, node_labels)
    return UnsupervisedResult(
        labels=labels,
        node_labels=node_labels,
        regions=regions,
        node_features=z,
        feature_names=tuple(names),
        seconds=time.perf_counter() - t0,
        degenerate=bool(degenerate_result(labels, requested=k).degenerate),
        params=p,
        surface_share=share,
        close_up=close_up,
    )
