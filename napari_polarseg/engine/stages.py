"""The stages of the pipeline (thesis section 4.5): one function per stage, in a table.

Each stage function takes the :class:`~.pipeline.Pipeline` (the stack, the mask, the
cache of the other stages) and the :class:`StageRun` of the call (the parameters of THIS
run, its cancel and progress callbacks) and returns the stage's value; upstream values
come from :meth:`~.pipeline.Pipeline.stage_value` with the same run, so every stage of a
call sees the same parameters. :func:`own_key` is the part of a stage's cache key made
of its own parameters.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
from scipy import ndimage

from . import disk_arrays
from .chunks import chunk_bounds, run_chunks
from .errors import PolarsegError
from .features import harmonics, polstats
from .features import pca as feat
from .graph import affinity, dense_graph, ncut, spectral
from .matrix_pool import DenseDistances, MatrixPool
from .params import SegmentParams
from .physics import fresnel, polarimage
from .physics.pixel_mask import PixelMask
from .result import Normals, Reconstruction

#: Stage names in execution order.
STAGES = (
    "polarisation",
    "normals",
    "harmonics",
    "pca",
    "affinity",
    "cut",
    "labels",
    "reconstruction",
)

#: Upstream stage of each stage.
UPSTREAM = {
    "polarisation": None,
    "normals": "polarisation",
    "harmonics": "normals",
    "pca": "harmonics",
    "affinity": "pca",
    "cut": "affinity",
    "labels": "cut",
    "reconstruction": "normals",
}

#: Largest number of blocks for a dense affinity even when asked for (n² float64 entries).
MAX_DENSE_BLOCKS = 12_000

#: Feature kinds computed from the polarisation statistics (engine.polstats), which are
#: z-scored per column before the PCA.
POLSTATS_KINDS = ("polstats", "zonal+polstats")
#: Share of a block's pixels that must be usable for the block to be segmented.
MIN_VALID_BLOCK_FRACTION = 0.25
#: Above this many blocks ``affinity_graph="auto"`` switches to the sparse k-nearest-
#: neighbour affinity. The dense cut is exact for any kernel width, the kNN one only for
#: narrow kernels (features.knn_affinity), so dense is kept while it is affordable: at
#: 6,000 blocks the matrix is 288 MB (plus a 144 MB float32 copy for the eigensolver)
#: and one product ~5 ms, a cut ~0.5 s. The reference 720 × 660 image at w = 10 (4,752
#: blocks) stays dense; a polarisation-camera frame at w = 8 (19,584 blocks: 3 GB dense)
#: goes sparse.
DENSE_MAX_BLOCKS = 6_000


@dataclass
class StageRun:
    """One call into the pipeline: its parameters and callbacks (never shared).

    ``cancel`` is handed to the cut (True raises :class:`Cancelled`); ``within`` is
    (stage, callback(share done)) for the stage being run, whose chunked loops report to
    it (harmonics, reconstruction); ``recomputed`` collects the stages this call computed.
    """

    params: SegmentParams
    cancel: Callable[[], bool] | None = None
    within: tuple[str, Callable[[float], None]] | None = None
    recomputed: list[str] = field(default_factory=list)

    def progress(self, stage: str) -> Callable[[float], None] | None:
        """The progress callback of ``stage`` when it is the stage being run (an upstream
        stage computed on the way reports nothing)."""
        within = self.within
        return within[1] if within is not None and within[0] == stage else None


class StageHost(Protocol):
    """What a stage function reads of the pipeline it runs in (the
    :class:`~.pipeline.Pipeline`, which imports this module: the stages name it by this
    protocol, so the two modules form no import cycle)."""

    stack: np.ndarray
    angles: np.ndarray
    mask: PixelMask
    matrices: MatrixPool
    distances: DenseDistances | None

    def key(self, stage: str, params: SegmentParams | None = None) -> tuple:
        """Cache key of ``stage`` for ``params``."""
        ...

    def cached(self, stage: str) -> Any | None:
        """The value cached for ``stage``, or None."""
        ...

    def stage_value(self, stage: str, run: StageRun) -> Any:
        """Value of ``stage`` for ``run.params``, computed if stale."""
        ...


def valid_blocks(valid: np.ndarray, window: int) -> np.ndarray:
    """Blocks (flat, row-major over the w × w block grid) of which at least
    :data:`MIN_VALID_BLOCK_FRACTION` of the pixels are ``valid`` (H, W bool, e.g.
    :attr:`SegmentationResult.valid`): the blocks that enter the graph."""
    valid = np.asarray(valid, dtype=bool)
    if valid.all():
        grid = harmonics.block_grid(valid.shape, window)
        return np.ones(grid[0] * grid[1], dtype=bool)
    used = harmonics.blockify(valid.astype(np.float64), window).mean(axis=-1)
    return (used >= MIN_VALID_BLOCK_FRACTION).ravel()


def affinity_graph_kind(n_blocks: int, p: SegmentParams) -> str:
    """``"dense"``, ``"knn"`` or ``"spatial"``: how the affinity stage stores the graph.

    ``affinity_graph="auto"`` picks the exact sparse spatial graph when there is a spatial
    term, the dense matrix up to :data:`DENSE_MAX_BLOCKS` blocks, else k nearest
    neighbours.
    """
    if p.affinity_graph == "dense":
        return "dense"
    if p.spatial_radius > 0:
        return "spatial"
    if p.affinity_graph == "sparse" or n_blocks > DENSE_MAX_BLOCKS:
        return "knn"
    return "dense"


def own_key(stage: str, p: SegmentParams) -> tuple:
    """The parameters ``stage`` itself depends on (its cache key without the upstream)."""
    if stage == "polarisation":
        return (p.fit,)
    if stage == "normals":
        branch = p.specular_branch if p.model == "specular" else None
        return (p.refractive_index, p.model, branch)
    if stage == "harmonics":
        return (p.window, p.degree, p.coefficients, p.ridge if p.coefficients == "ridge" else None)
    if stage == "pca":
        return (p.features, p.variance)
    if stage == "affinity":
        spatial = (p.spatial_radius, p.spatial_sigma) if p.spatial_radius > 0 else None
        return (p.scale, p.scale_mode, spatial, p.affinity_graph)
    if stage == "cut":
        if p.clustering == "kway":
            return (p.min_segment_blocks, "kway")
        return (p.min_segment_blocks, p.ncut_threshold)
    if stage == "labels":
        return (p.n_segments,)
    if stage == "reconstruction":
        return (p.window, p.degree, p.ridge)
    return ()


def block_valid(pipe: StageHost, run: StageRun) -> np.ndarray:
    """The blocks of the run's window that enter the graph (:func:`valid_blocks`)."""
    pol = pipe.stage_value("polarisation", run)
    return valid_blocks(~pol.invalid, run.params.window)


def block_vectors(
    pipe: StageHost, run: StageRun, coef: np.ndarray, standardise: bool = True
) -> np.ndarray:
    """Feature vector of every block (rows·cols, F) for ``features``.

    Harmonic kinds come from the coefficients
    (:func:`~napari_polarseg.engine.features.pca.harmonic_features`); ``"polstats"`` from the
    polarisation image directly (:mod:`.polstats`), z-scored
    because its columns have different units; ``"zonal+polstats"`` puts the z-scored
    zonal coefficients and statistics side by side.
    """
    p = run.params
    if p.features not in POLSTATS_KINDS:
        return feat.harmonic_features(coef, p.features)
    pol, nrm = pipe.stage_value("polarisation", run), pipe.stage_value("normals", run)
    stats = polstats.block_polarisation_statistics(
        pol.intensity, pol.dop, pol.phase, nrm.zenith, p.window, valid=~pol.invalid
    ).reshape(-1, len(polstats.STAT_NAMES))
    if p.features == "zonal+polstats":
        stats = np.concatenate([feat.harmonic_features(coef, "zonal"), stats], axis=1)
    return polstats.standardise(stats) if standardise else stats


#: Pixels a chunk of the normals stage works on at once (whole rows of them).
NORMALS_CHUNK_PIXELS = 1 << 16


def polarisation_stage(pipe: StageHost, run: StageRun) -> polarimage.PolarisationImage:
    """Î, ρ, φ of the sinusoid fit (thesis eq. 3.14), masked samples down-weighted.

    The fit runs chunk by chunk into preallocated maps
    (:func:`~.physics.polarimage.polarisation_image`), reporting its progress (which may
    stop it between chunks). The masked samples' weights go in as booleans (1 byte a
    sample, not a float64 copy of the stack) and the final weights are not kept."""
    mask = pipe.mask
    flagged = bool(np.any(mask.flags))
    pol = polarimage.polarisation_image(
        pipe.stack,
        pipe.angles,
        run.params.fit == "robust",
        weights=mask.flags == 0 if flagged else None,
        keep_weights=False,
        progress=run.progress("polarisation"),
    )
    if flagged or mask.region is not None:
        np.logical_or(pol.invalid, ~mask.valid, out=pol.invalid)
    return pol


def normals_stage(pipe: StageHost, run: StageRun) -> Normals:
    """Zenith θ from ρ (Fresnel model, refractive index; eqs. 3.11/3.13) and azimuth
    from φ, radians, in chunks of rows written into preallocated (H, W) maps (every
    pixel on its own: the maps equal one whole-image pass's).

    The diffuse azimuth is φ mod π, and the fit's φ already lies in [0, π) (NaN where
    the fit gave none): it is φ itself, a read-only view instead of a float64 copy."""
    p = run.params
    pol = pipe.stage_value("polarisation", run)
    h, w = pol.dop.shape
    # in temporary files when a large image's full-size arrays do not fit (disk_arrays)
    zenith, clamped = disk_arrays.empty((h, w)), disk_arrays.empty((h, w), dtype=bool)
    diffuse = p.model == "diffuse"
    azimuth = pol.phase.view() if diffuse else disk_arrays.empty((h, w))

    def work(a: int, b: int) -> None:
        est = fresnel.zenith_from_dop(pol.dop[a:b], p.refractive_index, p.model, p.specular_branch)
        zenith[a:b], clamped[a:b] = est.zenith, est.clamped
        if not diffuse:
            azimuth[a:b] = fresnel.azimuth_from_phase(pol.phase[a:b], p.model)

    rows = max(1, NORMALS_CHUNK_PIXELS // max(w, 1))
    run_chunks(chunk_bounds(h, rows), work, h * w, run.progress("normals"))
    azimuth.flags.writeable = not diffuse
    return Normals(zenith, azimuth, clamped)


def harmonics_stage(pipe: StageHost, run: StageRun) -> np.ndarray:
    """Block spherical-harmonic coefficients a_lm (R, C, n_coef)."""
    p = run.params
    pol, nrm = pipe.stage_value("polarisation", run), pipe.stage_value("normals", run)
    harmonics.block_grid(pol.intensity.shape, p.window)  # validates w vs image
    return harmonics.block_coefficients(
        pol.intensity,
        nrm.zenith,
        nrm.azimuth,
        p.window,
        p.degree,
        method=p.coefficients,
        ridge=p.ridge,
        weights=None if not pol.invalid.any() else ~pol.invalid,
        progress=run.progress("harmonics"),
    )


def pca_stage(pipe: StageHost, run: StageRun) -> feat.PCAResult:
    """Block features reduced by PCA to the share ``variance`` of the variance."""
    p = run.params
    coef = pipe.stage_value("harmonics", run)
    if coef.shape[0] * coef.shape[1] < 2:
        raise PolarsegError(
            f"window size {p.window} leaves fewer than 2 blocks in a "
            f"{pipe.stack.shape[1]} x {pipe.stack.shape[2]} image"
        )
    progress = run.progress("pca") or (lambda share: None)
    vectors = block_vectors(pipe, run, coef)
    progress(0.5)  # a checkpoint: the vectors of many small blocks take a while
    valid = block_valid(pipe, run)
    if valid.all():
        return feat.pca_features(vectors, p.variance)
    if valid.sum() < 2:
        raise PolarsegError("the mask leaves fewer than 2 usable blocks to segment")
    # masked-out blocks take no part in the PCA; they hold the mean feature only
    # to keep the block grid (they are no nodes of the graph, see "affinity")
    pca = feat.pca_features(vectors[valid], p.variance)
    full = np.broadcast_to(pca.features.mean(axis=0), (valid.size, pca.n_components))
    full = full.copy()
    full[valid] = pca.features
    return replace(pca, features=full)


def affinity_stage(pipe: StageHost, run: StageRun) -> Any:
    """The affinity S = exp(−D / s) of the valid blocks: dense, kNN or spatial."""
    p = run.params
    pca = pipe.stage_value("pca", run)
    valid = block_valid(pipe, run)
    features = pca.features[valid]  # graph nodes: the blocks the mask leaves
    n = features.shape[0]
    kind = affinity_graph_kind(n, p)
    grid = pipe.stage_value("harmonics", run).shape[:2]
    if kind == "knn":
        return affinity.knn_affinity(
            features, p.scale, p.scale_mode, progress=run.progress("affinity")
        )
    if kind == "spatial":
        W = affinity.spatial_affinity(
            pca.features, grid, p.spatial_radius, p.spatial_sigma, p.scale, p.scale_mode
        )
        return W if valid.all() else W.tocsr()[valid][:, valid]
    if n > MAX_DENSE_BLOCKS:
        raise PolarsegError(
            f"{n} blocks is too many for a dense affinity (limit {MAX_DENSE_BLOCKS}); "
            "use a larger window or affinity_graph 'sparse'"
        )
    W = dense_affinity(pipe, run, features)
    if p.spatial_radius > 0:
        W *= affinity.spatial_kernel(grid, p.spatial_radius, p.spatial_sigma)[np.ix_(valid, valid)]
    return W


def dense_affinity(pipe: StageHost, run: StageRun, features: np.ndarray) -> np.ndarray:
    """exp(−D / s) of the dense graph (thesis section 4.5), D kept between runs.

    The squared Mahalanobis distances D (eq. 4.27) and their median depend only on
    the block features, so they are kept with the ``pca`` stage's key: a change of
    the affinity scale (or its mode) reruns only the exponential, one pass over the
    matrix. From ``dense_graph.FLOAT32_MIN_NODES`` blocks D and the affinity are stored in
    float32 (each entry computed in float64; the normalized cut multiplies with a
    float32 matrix there anyway), which halves their memory: 90 MB each at 4,752
    blocks.
    """
    p = run.params
    key = pipe.key("pca", p)
    if pipe.distances is None or pipe.distances.key != key:
        pipe.distances = None  # free the old matrix before building the new one
        n = features.shape[0]
        dtype = np.float32 if n >= dense_graph.FLOAT32_MIN_NODES else np.float64
        D = feat.mahalanobis_sq(features, dtype, out=pipe.matrices.take((n, n), dtype))
        pipe.distances = DenseDistances(key, D)
    cached = pipe.distances
    D = cached.matrix
    mode = p.scale_mode if D.shape[0] >= 2 else "absolute"
    if mode == "median" and cached.median is None:
        cached.median = affinity.median_offdiagonal(D)
    scale = affinity.effective_scale(p.scale, mode, cached.median)
    return affinity.affinity_from_distances(D, scale, out=pipe.matrices.take(D.shape, D.dtype))


def cut_stage(pipe: StageHost, run: StageRun) -> Any:
    """The recursive normalized-cut tree, or the k-way spectral clustering."""
    p = run.params
    W = pipe.stage_value("affinity", run)
    if p.clustering == "kway":
        # k-way spectral clustering of the same graph (spectral.py); the number of
        # segments only reruns k-means on the cached eigenvectors
        return spectral.SpectralClustering(W, min_size=p.min_segment_blocks)
    # warm start: eigenvectors of the previous tree on the same blocks (e.g. when
    # only the affinity scale changed) start the solves of identical segments
    old = pipe.cached("cut")
    warm = None
    if isinstance(old, ncut.CutTree) and old.W.shape == W.shape:
        warm = old.fiedler_vectors()
    return ncut.CutTree(W, min_size=p.min_segment_blocks, threshold=p.ncut_threshold, warm=warm)


def labels_stage(pipe: StageHost, run: StageRun) -> tuple:
    """(block labels, pixel labels, Ncut values, cut limits, {}) for ``n_segments``."""
    p = run.params
    tree = pipe.stage_value("cut", run)
    coef = pipe.stage_value("harmonics", run)
    valid = block_valid(pipe, run).reshape(coef.shape[:2])
    block = np.zeros(coef.shape[:2], dtype=np.int32)
    block[valid] = tree.labels(p.n_segments, cancel=run.cancel)
    limits = tree.cut_limits(p.n_segments)
    if not valid.all():
        # masked-out blocks take the label of the nearest block that was segmented
        _, (ri, ci) = ndimage.distance_transform_edt(~valid, return_indices=True)
        block = block[ri, ci]
    shape = pipe.stack.shape[1:]
    labels = harmonics.upsample_block_labels(block, shape, p.window)
    return block, labels, tree.ncut_values, limits, {}


def reconstruction_stage(pipe: StageHost, run: StageRun) -> Reconstruction:
    """Î rebuilt from the block harmonics and its absolute error."""
    p = run.params
    pol, nrm = pipe.stage_value("polarisation", run), pipe.stage_value("normals", run)
    rec = harmonics.reconstruct_intensity(
        pol.intensity,
        nrm.zenith,
        nrm.azimuth,
        p.window,
        p.degree,
        ridge=p.ridge,
        weights=None if not pol.invalid.any() else ~pol.invalid,
        progress=run.progress("reconstruction"),
    )
    return Reconstruction(rec, np.abs(rec - pol.intensity))


#: The function computing each stage.
STAGE_FUNCTIONS: dict[str, Callable[[StageHost, StageRun], Any]] = {
    "polarisation": polarisation_stage,
    "normals": normals_stage,
    "harmonics": harmonics_stage,
    "pca": pca_stage,
    "affinity": affinity_stage,
    "cut": cut_stage,
    "labels": labels_stage,
    "reconstruction": reconstruction_stage,
}
