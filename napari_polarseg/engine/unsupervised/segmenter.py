"""Unsupervised segmentation on a graph of superpixels.

The thesis pipeline cuts a graph of square w × w blocks, which straddle the material
boundaries and, at the thesis scale, falls apart into single blocks on real frames
(issue 13). Here the nodes are superpixels that follow the edges of the polarisation
image, each described by a few statistics of its pixels, and the clustering works on
those few hundred to few thousand nodes:

1. **Superpixels** (:func:`polarisation_superpixels`): a compact watershed (as
   :func:`~napari_polarseg.engine.features.superpixels.superpixels`) over the sum of
   the gradient magnitudes of the smoothed log Î and of the smoothed normalised
   Stokes components s1 = S1/S0, s2 = S2/S0 (so a region border sits on an intensity
   *or* a polarisation edge).
2. **Node features** (:func:`node_features`), from region sums (``np.bincount``) of
   per-pixel products, each named once in :data:`~.params.NODE_FEATURES`: the region's mean
   log Î, its spread, mean ρ and its spread, the region's DoLP
   |(ΣS1, ΣS2)| / ΣS0, the AoLP coherence |mean e^{2iφ}|, DoLP / mean ρ and, as the
   physical material cue (thesis section 6.2), the slope and correlation of ρ against
   log Î inside the region: within one material the shading and ρ both follow the
   zenith, their relation depends on n and the depolarisation, not on the tilt; and
   the same cue taken image-wide, log ρ̄ less a cubic in log Î fitted over all regions
   (:func:`~.region_features.dop_given_intensity`).
   Optionally the per-pixel feature stack of :mod:`.pixel_features` averaged per region.
   The features are standardised (weighted by region area), may be diffused over the
   region graph but not across its edges (``UnsupervisedParams.diffusion``) and are
   reduced by PCA to the
   components that explain ``variance`` of the total
   (:func:`~napari_polarseg.engine.features.pca.pca_features`).
3. **Clustering** (``UnsupervisedParams.clustering``): a Gaussian mixture (scikit-learn
   ``GaussianMixture``, full covariances, seeded) or k-means weighted by region area
   (:func:`.kmeans.weighted_kmeans`) on the node features, with an
   optional smoothing of the posteriors over the region adjacency (a few iterations of
   P ← (1 − λ) P + λ A P, A the row-normalised shared-border lengths), or the thesis's
   Mahalanobis affinity exp(−D / s) (:func:`~napari_polarseg.engine.features.pca.whiten`, s =
   ``scale`` × the
   median D over the graph's edges) restricted to neighbouring regions, cut by recursive
   normalized cuts (:func:`~napari_polarseg.engine.graph.ncut.recursive_ncut`) or k-way spectral
   clustering
   (:class:`~napari_polarseg.engine.graph.spectral.SpectralClustering`).

**Close-ups of one smooth surface** (:mod:`.shape_trend`): when the square of one
linear field explains more than ``close_up_share`` of the superpixels' complex
polarisation ρ e^{2iφ} — one curved surface fills the frame, as in a fruit inspection
crop — mean ρ and shading follow the tilt, not the material, so the node feature is the
departure of the polarisation from that surface's trend alone
(``dop_over_shape_trend``, :meth:`.params.UnsupervisedParams.close_up_params`). The
result says so (``UnsupervisedResult.close_up``, ``surface_share``).

Every pixel takes its region's label; then the pixels on a segment border move to the
neighbouring segment whose mean (log Î, ρ) they resemble most
(:func:`.boundaries.refine_boundaries`,
:data:`.boundaries.REFINE_PASSES` one-pixel passes: a watershed border on a straight edge can sit
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
the cue taken image-wide (:func:`~.region_features.dop_given_intensity`) helps some
renders and hurts others; a Gaussian mixture sometimes fits one tiny component; the
multi-scale pixel stack splits the camera's mat by shading; the graph cuts on
neighbouring regions peel off single regions. The benchmark prints every variant.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sps

from .. import disk_arrays
from ..chunks import call_stoppable
from ..degenerate import degenerate_result
from ..errors import PolarsegError
from ..features.pca import pca_features, whiten
from ..features.superpixels import (
    edge_terms,
    polarisation_superpixels,
    relabel,
    seed_count,
    watershed_on_grid,
)
from .boundaries import refine_maps, refined_labels
from .kmeans import squared_distances, weighted_kmeans
from .params import UnsupervisedParams, UnsupervisedResult
from .pixel_maps import PixelMaps, border_graph, edge_weight, pixel_maps
from .region_diffusion import diffuse, diffusion_steps
from .region_features import node_features
from .region_graph import region_adjacency
from .shape_trend import (
    region_polarisation,
    surface_trend_share,
)
from .spatial_weights import coherence_weights
from .tiled_region_tasks import Seeds

#: Seedings of the k-means (:func:`.kmeans.weighted_kmeans`; the lowest inertia wins).
KMEANS_RESTARTS = 10


def standardise_columns(x: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Columns of ``x`` (n, c) centred and scaled to unit spread (weighted by ``weight``,
    (n,)); a constant column is only centred."""
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


def first_appearance(
    labels: np.ndarray, node_labels: np.ndarray, table: np.ndarray | None = None
) -> tuple[np.ndarray, ...]:
    """Segments renumbered in order of first appearance in ``labels`` (row-major), after
    the lookup ``table`` (segment → segment, e.g. a merge's; None: none): the labels of
    ``table[labels]`` renumbered, and of ``table[node_labels]``.

    The lookup is composed with the renumbering on the few segments, so the only
    full-size array made is the int32 result, placed by :func:`~..disk_arrays.empty`
    (in a temporary file when a large image's full-size arrays do not fit).
    """
    flat = labels.ravel()
    # the first index of each of the few labels: one comparison pass per label is
    # several times faster than sorting every pixel (np.unique)
    present = np.flatnonzero(np.bincount(flat))
    first = np.array([np.argmax(flat == v) for v in present], dtype=np.int64)
    if table is None:
        table = np.arange(int(max(flat.max(), node_labels.max())) + 1, dtype=np.int64)
    table = np.asarray(table, dtype=np.int64)
    # each looked-up segment first appears where the first of its labels does
    mapped = table[present]
    firsts = np.full(int(table.max()) + 1, flat.size, dtype=np.int64)
    np.minimum.at(firsts, mapped, first)
    values = np.unique(mapped)
    values = values[np.argsort(firsts[values], kind="stable")]
    order = np.zeros(int(table.max()) + 1, dtype=np.int32)
    order[values] = np.arange(values.size, dtype=np.int32)
    lookup = order[table]
    out = disk_arrays.empty(labels.shape, dtype=np.int32)
    np.take(lookup, labels, out=out, mode="clip")  # "raise" would buffer a copy
    return out, lookup[node_labels]


def _region_features(
    i: np.ndarray,
    d: np.ndarray,
    ph: np.ndarray,
    regions: np.ndarray,
    p: UnsupervisedParams,
    terms: dict[str, np.ndarray] | None = None,
) -> tuple[np.ndarray, list[str]]:
    """Node features (n, c) of the superpixels, non-finite values 0, and their names: the
    region features of :func:`node_features` (from ``terms``,
    :func:`.region_features.pixel_terms`, when made), then the region means of pixel
    features."""
    names = list(p.features + p.texture)
    trend = (p.trend_degree, p.trend_reach, p.trend_iterations)
    cols = [node_features(i, d, ph, regions, tuple(names), trend, terms)] if names else []
    if p.pixel_scales:
        from ..features.pixel_features import PixelFeatureParams, pixel_features

        stack = pixel_features(
            i,
            d,
            ph,
            PixelFeatureParams(scales=p.pixel_scales, groups=p.pixel_groups),
        )
        cols.append(stack.region_means(regions).T.astype(np.float64))
        names += [f"pixel:{nm}" for nm in stack.names]
    x = np.concatenate(cols, axis=1)
    return np.where(np.isfinite(x), x, 0.0), names


def project_features(
    x: np.ndarray,
    weight: np.ndarray,
    graph: sps.csr_matrix,
    adjacency: sps.csr_matrix,
    p: UnsupervisedParams,
) -> np.ndarray:
    """Projected node features z (n, c): standardised and clipped features, diffused over
    the edge-aware region ``graph`` but for the texture group (``p.texture``, the
    columns after ``p.features``), which is scaled by ``p.texture_weight``, each column
    weighed by its spatial coherence in the scene when ``p.coherence_power`` > 0
    (:func:`.spatial_weights.coherence_weights`, read before the diffusion), projected
    (PCA or MAF). Independent of k."""
    xs = standardise_columns(x, weight)
    if p.clip > 0:
        xs = np.clip(xs, -p.clip, p.clip)
    texture = np.zeros(xs.shape[1], dtype=bool)  # the columns of _region_features' order
    texture[len(p.features) : len(p.features) + len(p.texture)] = True
    coherence = coherence_weights(xs, adjacency, p.coherence_power)
    steps = diffusion_steps(p.diffusion_range, x.shape[0], p.diffusion)
    if steps:  # after the standardising: a column of mere noise shrinks, not rescaled
        xs[:, ~texture] = diffuse(xs[:, ~texture], graph, p.diffusion, steps)
    xs[:, texture] *= p.texture_weight
    xs *= coherence
    if p.projection == "maf":
        return maf_features(xs, adjacency, weight, p.variance, p.components)
    return pca_features(xs, p.variance).features


def _cluster(
    z: np.ndarray, k: int, weight: np.ndarray, adjacency: sps.csr_matrix, p: UnsupervisedParams
) -> np.ndarray:
    """Node labels for k >= 2 segments of the projected features (``p.clustering``)."""
    if p.clustering in ("gmm", "kmeans"):
        return _cluster_mixture(z, k, weight, adjacency, p)
    return _cluster_graph(z, k, adjacency, p)


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
    i: np.ndarray,
    d: np.ndarray,
    ph: np.ndarray,
    p: UnsupervisedParams,
    progress: Callable[[float], None] | None = None,
    terms: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(superpixels, the terms of their edge map) of ``p.boundary`` (module docstring,
    step 1); the terms (:func:`edge_terms`) are made unless given.

    ``progress`` is called with 0.25 after the edge map and then every
    :data:`~napari_polarseg.engine.chunks.STOP_POLL_S` during the watershed (one
    library call with no stop hook of its own): when it raises, the
    run stops at once (:func:`~napari_polarseg.engine.chunks.call_stoppable`).
    """
    area = p.area_of(i.shape)
    if terms is None:
        terms = edge_terms((i, d, ph), edge_weight(p))
    if p.boundary == "polarisation":
        grid = p.watershed_grid_of(i.shape)
        edges = terms.sum(axis=0)

        def work() -> np.ndarray:
            if grid == 1:
                return polarisation_superpixels(i, d, ph, area, edges=edges)
            # the tiled pass's seeds (.tiled_region_tasks), so both give the same blocks
            whole = (slice(0, i.shape[0]), slice(0, i.shape[1]))
            seeds = Seeds.of(i.shape, seed_count(i.shape, area)).markers(whole)
            return relabel(watershed_on_grid(edges, seeds, grid))
    else:
        from ..features.superpixels import superpixels

        def work() -> np.ndarray:
            return relabel(superpixels(i, area))

    if progress is None:
        return work(), terms
    progress(0.25)
    return call_stoppable(work, lambda: progress(0.25)), terms


@dataclass(frozen=True)
class RegionModel:
    """What the superpixel clustering computes before it knows k (steps 1 and 2 of the
    module docstring): :func:`prepare_regions` makes it, :func:`cluster_regions` labels
    it for any k in milliseconds.

    Attributes
    ----------
    maps : tuple of ndarray (H, W)
        Î, ρ, φ as read (outside the mask: the nearest valid pixel's values).
    valid : ndarray (H, W) of bool or None
        The pixels the clustering reads (None: every pixel).
    regions : ndarray (H, W) int32
        Superpixel of every pixel, 0 … n − 1; with a mask, pixels outside it form the
        extra region n, which takes no part in the clustering.
    n : int
        Number of superpixels clustered.
    weight : ndarray (n,)
        Valid pixels per superpixel.
    adjacency : scipy.sparse.csr_matrix (n, n)
        Shared-border lengths between superpixels.
    z : ndarray (n, c)
        Projected node features (:func:`project_features`).
    feature_names : tuple of str
    surface_share : float
    close_up : bool
    params : UnsupervisedParams
        The parameters asked for (``close_up_params()`` of them were used when
        ``close_up``).
    refine_maps : ndarray (2, H, W) or None
        log Î and ρ for the border refinement (:func:`.boundaries.refine_maps`), made once.
    nearest : ndarray (H, W) of int or None
        With a mask, the flat index of the nearest valid pixel of every pixel
        (:func:`~napari_polarseg.engine.physics.pixel_mask.nearest_valid`), made once.
    borders : scipy.sparse.csr_matrix (n, n) or None
        Edge-aware border weights L_ab · exp(−(e_ab / τ)²) between superpixels
        (:func:`.pixel_maps.border_graph`, τ = ``diffusion_tau``): the
        diffusion's graph and the merge's (:func:`.merge.weakest_border`); None below
        two superpixels.
    labeller : callable (model, node labels) -> (labels, node labels), or None
        What :func:`pixel_labels` hands the model to when it was made tile by tile
        (:mod:`.tiled_regions`): its maps are then the unfilled ones, and
        ``refine_maps`` and ``nearest`` None.
    """

    maps: tuple[np.ndarray, np.ndarray, np.ndarray]
    valid: np.ndarray | None
    regions: np.ndarray
    n: int
    weight: np.ndarray
    adjacency: sps.csr_matrix
    z: np.ndarray
    feature_names: tuple[str, ...]
    surface_share: float
    close_up: bool
    params: UnsupervisedParams
    refine_maps: np.ndarray | None = None
    nearest: np.ndarray | None = None
    borders: sps.csr_matrix | None = None
    labeller: Callable[[RegionModel, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None

    @property
    def used_params(self) -> UnsupervisedParams:
        """The parameters the clustering uses (the close-up ones on a close-up)."""
        return self.params.close_up_params() if self.close_up else self.params


def _masked_regions(regions: np.ndarray, valid: np.ndarray | None) -> tuple[np.ndarray, int]:
    """(regions, n): with a mask, the pixels outside it become region n (last) and the
    superpixels with no valid pixel disappear."""
    if valid is None:
        return regions, int(regions.max()) + 1
    marked = np.where(valid, regions, int(regions.max()) + 1)
    marked = relabel(marked)
    return marked, int(marked.max())  # the outside region is the last one


def prepare_regions(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    params: UnsupervisedParams | None = None,
    valid: np.ndarray | None = None,
    progress: Callable[[float], None] | None = None,
    pixels: PixelMaps | None = None,
) -> RegionModel:
    """Superpixels, node features and their projection: everything but the clustering.

    ``valid`` (H, W bool, True = segment here) restricts the clustering to a region: the
    maps outside it are filled from the nearest valid pixel
    (:func:`~napari_polarseg.engine.physics.pixel_mask.fill_from_nearest`) before the
    superpixels are drawn, and the pixels outside form one extra region that takes no
    part in the features' statistics, the projection or the clustering; so the labels
    inside the region do not depend on anything outside it. ``progress`` is called with
    the share done after each step (it may raise to stop there). ``pixels``
    (:func:`.pixel_maps.pixel_maps` of the same maps and ``valid``, made here when not
    given) saves making what does not depend on the superpixels' size again;
    ``intensity``, ``dop``, ``phase`` and ``valid`` are then not read.
    """
    step = progress or (lambda share: None)
    p = params or UnsupervisedParams()
    if pixels is None:
        pixels = pixel_maps(intensity, dop, phase, p, valid)
    step(0.05)
    (i, d, ph), valid, nearest = pixels.maps, pixels.valid, pixels.nearest
    terms = pixels.edge_terms if pixels.edge_weight == edge_weight(p) else None
    regions, terms = _superpixels(i, d, ph, p, progress, terms)
    step(0.5)
    regions, n = _masked_regions(regions, valid)
    keep = slice(0, n)
    maps = pixels.terms
    stokes = (maps["s0"], maps["s1"], maps["s2"])
    z_region, count, centroid = region_polarisation(i, d, ph, regions, stokes)
    step(0.6)
    share = surface_trend_share(z_region[keep], count[keep], centroid[keep], i.shape)
    close_up = share > p.close_up_share
    q = p.close_up_params() if close_up else p
    x, names = _region_features(i, d, ph, regions, q, maps)
    step(0.8)
    weight = np.bincount(regions.ravel(), minlength=n).astype(float)[keep]
    adjacency = region_adjacency(regions)[keep][:, keep].tocsr()
    borders = None
    if n < 2:
        z = np.zeros((n, 0))
    else:  # the border weights serve the diffusion and the merge by weakest border
        borders = border_graph(q, terms, regions, z_region)[keep][:, keep].tocsr()
        z = project_features(x[keep], weight, borders, adjacency, q)
    maps = refine_maps(i, d) if q.refine_boundaries else None
    return RegionModel(
        (i, d, ph),
        valid,
        regions,
        n,
        weight,
        adjacency,
        z,
        tuple(names),
        share,
        close_up,
        p,
        maps,
        nearest,
        borders,
    )


def pixel_labels(model: RegionModel, node_labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(labels (H, W), node labels (n,)) of a :class:`RegionModel` whose n superpixels are
    labelled ``node_labels``: every pixel takes its superpixel's label (outside a mask,
    the nearest valid pixel's), the pixels on a segment border move to the neighbouring
    segment they resemble most when the parameters ask for it
    (:func:`.boundaries.refined_labels`), and the segments are renumbered in order of
    first appearance (:func:`first_appearance`); a model made tile by tile writes them
    tile by tile (``RegionModel.labeller``)."""
    if model.labeller is not None:
        return model.labeller(model, np.asarray(node_labels, dtype=np.int32))
    i, d, _ = model.maps
    node_labels = np.asarray(node_labels, dtype=np.int32)
    m = int(node_labels.max()) + 1 if node_labels.size else 1
    if model.valid is not None:  # the outside region: relabelled from inside below
        node_labels = np.append(node_labels, 0).astype(np.int32)
    labels = node_labels[model.regions]
    if model.nearest is not None:
        labels = labels.ravel()[model.nearest]
    if model.used_params.refine_boundaries and m > 1:
        labels = refined_labels(labels, i, d, m, model.refine_maps)
        if model.nearest is not None:
            labels = labels.ravel()[model.nearest]
    labels, node_labels = first_appearance(labels, node_labels)
    return labels, node_labels[: model.n]


def without_refinement(model: RegionModel) -> RegionModel:
    """``model`` whose labels keep each pixel's superpixel label (no border refinement):
    for what reads only the superpixels' labels."""
    return replace(model, params=model.params.replace(refine_boundaries=False))


def cluster_regions(model: RegionModel, n_segments: int) -> UnsupervisedResult:
    """The labels of a :class:`RegionModel` for k = ``n_segments`` (step 3 of the module
    docstring, then the border refinement); outside a mask, every pixel takes the label
    of the nearest valid pixel."""
    t0 = time.perf_counter()
    i = model.maps[0]
    k = _checked_k(i.shape, n_segments)
    n, q = model.n, model.used_params
    if n < k:
        raise PolarsegError(f"only {n} superpixels for {k} segments: ask for at most {n} segments")
    if k == 1:
        node_labels = np.zeros(n, dtype=np.int32)
    else:
        node_labels = _cluster(model.z, k, model.weight, model.adjacency, q)
    labels, node_labels = pixel_labels(model, node_labels)
    return UnsupervisedResult(
        labels=labels,
        node_labels=node_labels,
        regions=model.regions,
        node_features=model.z,
        feature_names=model.feature_names,
        seconds=time.perf_counter() - t0,
        degenerate=bool(degenerate_result(labels, requested=k).degenerate),
        params=model.params,
        surface_share=model.surface_share,
        close_up=model.close_up,
    )


def segment_unsupervised(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    n_segments: int,
    params: UnsupervisedParams | None = None,
    valid: np.ndarray | None = None,
) -> UnsupervisedResult:
    """Segment a polarisation image into materials without training (module docstring):
    :func:`prepare_regions`, then :func:`cluster_regions`.

    Parameters
    ----------
    intensity, dop, phase : array (H, W)
        Î (units of the input), ρ in [0, 1], φ radians (thesis eq. 3.14).
    n_segments : int
        Number of segments k (≥ 1).
    params : UnsupervisedParams, optional
        Superpixels, node features and clustering (default ``UnsupervisedParams()``).
    valid : array (H, W) of bool, optional
        Segment only these pixels (:func:`prepare_regions`); the others take the label
        of the nearest one.

    Returns
    -------
    UnsupervisedResult
        Pixel labels (each pixel its superpixel's), node labels, the superpixels;
        ``seconds`` is the whole segmentation's.

    Raises
    ------
    PolarsegError
        Maps of different shapes or not 2-D, k < 1, or fewer superpixels than k.
    """
    t0 = time.perf_counter()
    model = prepare_regions(intensity, dop, phase, params, valid)
    result = cluster_regions(model, n_segments)
    return replace(result, seconds=time.perf_counter() - t0)
