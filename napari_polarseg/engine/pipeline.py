"""The segmentation pipeline of thesis section 4.5, with a per-stage cache.

Stages, each a plain function of the engine, and the parameters each depends on::

    polarisation   (stack, angles)                       → Î, ρ, φ          polarimage.py
    normals        refractive_index, model, branch        → θ, azimuth       fresnel.py
    harmonics      window, degree, coefficients, ridge    → block a_lm       harmonics.py
    pca            features, variance                     → block features   features.py
    affinity       scale, scale_mode, spatial_*, graph    → S = exp(−D/s)    features.py
    cut            min_segment_blocks, ncut_threshold     → cut tree         ncut.py
    labels         n_segments                             → labels           ncut.py
    reconstruction window, degree, ridge (after normals)  → Î rebuilt, error harmonics.py

A stage is recomputed only when one of its own parameters or an upstream stage changed:
changing ``n_segments`` re-reads the cached cut tree and never recomputes harmonics.
"""

from __future__ import annotations

import sys
import time
import warnings
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from scipy import ndimage

from .analysis.degenerate import DegenerateCheck, degenerate_result
from .errors import Cancelled, PolarsegError
from .features import harmonics, polstats
from .features import pca as feat
from .graph import affinity, dense_graph, ncut, spectral
from .params import SegmentParams
from .physics import fresnel, polarimage
from .unsupervised import segmenter as unsupervised

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


def _own_key(stage: str, p: SegmentParams) -> tuple:
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
        return (p.n_segments, p.clustering == "superpixels")
    if stage == "reconstruction":
        return (p.window, p.degree, p.ridge)
    return ()


class ScribbleSegmentation(NamedTuple):
    """What :meth:`Pipeline.scribble_segmentation` returns."""

    result: SegmentationResult
    probabilities: np.ndarray
    classes: np.ndarray
    training_blocks: int


@dataclass
class Normals:
    zenith: np.ndarray
    azimuth: np.ndarray
    clamped: np.ndarray


@dataclass
class Reconstruction:
    intensity: np.ndarray
    error: np.ndarray

    @property
    def mean_error(self) -> float:
        return float(np.mean(self.error))


@dataclass
class SegmentationResult:
    """Everything one pipeline run produced (arrays are H × W unless noted).

    ``labels`` covers every input pixel (remainder strips take their nearest block's
    label); ``block_labels`` is (H // w, W // w). Angles are radians. ``residual`` is the
    RMS residual of the sinusoid fit. ``valid`` marks the pixels the block features and
    the reconstruction fit used (inside the pixel mask and with Î > 0); ``mask_counts``
    holds the pixel counts per exclusion reason
    (:meth:`~napari_polarseg.engine.polarimage.PixelMask.counts`);
    ``duplicate_angle_frames`` lists the frames taken at a repeated polariser angle
    (modulo π), which were averaged before the fit. ``cut_limits`` holds the cut's
    work counts (:meth:`~napari_polarseg.engine.ncut.CutTree.cut_limits`: eigensolves
    capped, segments with an isolated block not solved, products); empty when labels
    came from elsewhere (scribbles).
    """

    params: SegmentParams
    intensity: np.ndarray
    dop: np.ndarray
    phase: np.ndarray
    residual: np.ndarray
    zenith: np.ndarray
    azimuth: np.ndarray
    clamped: np.ndarray
    coefficients: np.ndarray
    features: np.ndarray
    explained_variance_ratio: np.ndarray
    block_labels: np.ndarray
    labels: np.ndarray
    ncut_values: list[float]
    timings: dict[str, float]
    recomputed: list[str] = field(default_factory=list)
    reconstruction: np.ndarray | None = None
    reconstruction_error: np.ndarray | None = None
    valid: np.ndarray | None = None
    mask_counts: dict[str, Any] = field(default_factory=dict)
    duplicate_angle_frames: list[list[int]] = field(default_factory=list)
    cut_limits: dict[str, int] = field(default_factory=dict)

    @property
    def n_segments(self) -> int:
        return int(self.block_labels.max()) + 1

    @property
    def n_clamped(self) -> int:
        return int(np.count_nonzero(self.clamped))

    @property
    def mean_reconstruction_error(self) -> float | None:
        """Mean absolute reconstruction error over the used pixels (``valid``)."""
        if self.reconstruction_error is None:
            return None
        if self.valid is not None and not self.valid.all():
            return float(np.mean(self.reconstruction_error[self.valid]))
        return float(np.mean(self.reconstruction_error))

    def degenerate(self) -> DegenerateCheck:
        """Whether (nearly) every pixel is in one segment
        (:func:`~napari_polarseg.engine.degenerate.degenerate_result`, minimum segment size
        ``min_segment_blocks`` · w² pixels)."""
        p = self.params
        return degenerate_result(
            self.labels, p.min_segment_blocks * p.window**2, requested=p.n_segments
        )

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures of the run (stage seconds, segments, variance, error).

        ``degenerate`` (with ``largest_segment_share`` and ``degenerate_reason``): see
        :meth:`degenerate`; ``cut_limits``: see the class docstring.
        """
        check = self.degenerate()
        return {
            "stage_seconds": {k: round(v, 6) for k, v in self.timings.items()},
            # stages this run computed (the others came from the cache) and their time
            "recomputed_stages": list(self.recomputed),
            "total_seconds": round(sum(self.timings[s] for s in self.recomputed), 6),
            "n_segments": self.n_segments,
            "segment_pixels": np.bincount(self.labels.ravel()).tolist(),
            "degenerate": check.degenerate,
            "largest_segment_share": round(check.largest_share, 6),
            "degenerate_reason": check.reason,
            "n_blocks": int(self.block_labels.size),
            "block_grid": list(self.block_labels.shape),
            "n_components": int(self.features.shape[1]),
            "explained_variance": float(np.sum(self.explained_variance_ratio)),
            "explained_variance_ratio": [float(v) for v in self.explained_variance_ratio],
            "ncut_values": [float(v) for v in self.ncut_values],
            "clamped_pixels": self.n_clamped,
            "mean_reconstruction_error": self.mean_reconstruction_error,
            "fit": self.params.fit,
            "mask": dict(self.mask_counts),
            "averaged_duplicate_angles": [list(g) for g in self.duplicate_angle_frames],
            "cut_limits": dict(self.cut_limits),
        }


class MatrixPool:
    """Memory for the n × n matrices a pipeline recomputes (distances, affinity).

    :meth:`take` hands out a view of a kept flat buffer when no array made from that
    buffer is alive any more (its reference count shows only the pool), else a new one;
    so an array a caller still holds (e.g. an affinity from ``get("affinity")``) is never
    overwritten. Reusing memory this way spares a rerun the fresh pages of each new
    matrix (90 MB at 4,752 blocks in float32): on the reference VM those cost 0.02–0.2 s
    each, depending on where the kernel found them. At most ``keep`` buffers are kept.
    """

    def __init__(self, keep: int = 3) -> None:
        self.keep = keep
        self._buffers: list[np.ndarray] = []
        # the references a buffer with no view has when _free looks at it (the list, the
        # loop variable, the arguments), counted on a probe taken the same way; every
        # live view or reshape of a buffer adds one (its ``base``)
        probe = [np.empty(0)]
        self._unused = min(self._references(b) for b in probe)

    @staticmethod
    def _references(buffer: np.ndarray) -> int:
        return sys.getrefcount(buffer)

    def _free(self, buffer: np.ndarray) -> bool:
        return self._references(buffer) <= self._unused + 1  # + _free's own argument

    def reserve(self, shape: tuple[int, ...], dtype: np.dtype | type) -> None:
        """Make sure a free buffer of ``shape`` and ``dtype`` is kept, its pages touched
        (idle-time preparation: the next :meth:`take` of that size then writes into
        memory the process already has)."""
        dtype = np.dtype(dtype)
        size = int(np.prod(shape))
        if any(b.dtype == dtype and b.size == size and self._free(b) for b in self._buffers):
            return
        spare = self.take(shape, dtype)
        if self.owns(spare):
            spare.fill(0)  # touch every page now

    def owns(self, array: np.ndarray) -> bool:
        """True if ``array`` was handed out from a buffer the pool keeps."""
        return any(array.base is b for b in self._buffers)

    def take(self, shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
        """An uninitialised array of ``shape`` and ``dtype``."""
        dtype = np.dtype(dtype)
        size = int(np.prod(shape))
        for buffer in self._buffers:
            if buffer.dtype == dtype and buffer.size == size and self._free(buffer):
                return buffer.reshape(shape)
        # make room: forget free buffers (of other sizes first) beyond the limit
        free = [b for b in self._buffers if self._free(b)]
        free.sort(key=lambda b: b.size == size)
        while len(self._buffers) >= self.keep and free:
            drop = free.pop(0)
            self._buffers = [b for b in self._buffers if b is not drop]
        buffer = np.empty(size, dtype=dtype)
        if len(self._buffers) < self.keep:
            self._buffers.append(buffer)
        return buffer.reshape(shape)


@dataclass
class Pipeline:
    """Cached pipeline over one angle stack.

    Parameters
    ----------
    stack : array (N, H, W)
        Angle stack.
    angles : array (N,)
        Polariser angles in radians.
    params : SegmentParams
        Initial parameters; assign ``pipeline.params`` (or call :meth:`update`) to change.
    mask : array (H, W) or PixelMask, optional
        Which pixels the fit and the block features use. An (H, W) array is the user's
        region (non-zero = segment here), combined with the samples flagged by
        :func:`~napari_polarseg.engine.polarimage.validity_mask` with its defaults
        (saturated at the integer dtype's maximum, black at or below 0, not finite). A
        :class:`~napari_polarseg.engine.polarimage.PixelMask` is used as it is (e.g. with
        another saturation level, or found by the reader before dark subtraction). None:
        the default flags over the whole image. Fixed for the pipeline's lifetime.
        Excluded pixels still get values and labels (their block's), but are left out of
        the sinusoid fit of their own pixel where possible, of the block coefficients and
        of the reconstruction fit; counts are in :meth:`SegmentationResult.summary`.

    Examples
    --------
    >>> from napari_polarseg.engine import Pipeline, SegmentParams
    >>> pipe = Pipeline(stack, angles, SegmentParams(n_segments=3))  # doctest: +SKIP
    >>> result = pipe.run()                                          # doctest: +SKIP
    >>> pipe.update(n_segments=4); pipe.run().n_segments             # doctest: +SKIP
    4
    """

    stack: np.ndarray
    angles: np.ndarray
    params: SegmentParams = field(default_factory=SegmentParams)
    mask: np.ndarray | polarimage.PixelMask | None = None
    calls: Counter = field(default_factory=Counter, init=False)
    _cache: dict[str, tuple[tuple, Any]] = field(default_factory=dict, init=False)
    _seconds: dict[str, float] = field(default_factory=dict, init=False)
    _active: SegmentParams | None = field(default=None, init=False, repr=False)
    _recomputed: list[str] = field(default_factory=list, init=False, repr=False)
    #: [pca key, dense squared distances D, their median or None] (see _dense_affinity)
    _distances: list | None = field(default=None, init=False, repr=False)
    _matrices: MatrixPool = field(default_factory=lambda: MatrixPool(), init=False, repr=False)
    #: the ``cancel`` of the running run_iter / prefetch, handed to the cut
    _cancel: Callable[[], bool] | None = field(default=None, init=False, repr=False)
    #: (stage, callback(share done)) of the running run_iter / get: the stage's chunked
    #: loops report to it (harmonics and reconstruction)
    _within: tuple[str, Callable[[float], None]] | None = field(
        default=None, init=False, repr=False
    )

    def __post_init__(self) -> None:
        raw = self.stack
        self.stack, self.angles = polarimage.check_stack(self.stack, self.angles)
        if not isinstance(self.params, SegmentParams):
            raise PolarsegError("params must be a SegmentParams")
        if not isinstance(self.mask, polarimage.PixelMask):
            self.mask = polarimage.validity_mask(raw, region=self.mask)
        elif self.mask.flags.shape != self.stack.shape:
            raise PolarsegError(
                f"the pixel mask covers {self.mask.flags.shape} samples but the stack is "
                f"{self.stack.shape}"
            )
        polarimage.check_usable(self.stack, self.mask)

    # -- parameters -------------------------------------------------------------------
    def update(self, **changes: Any) -> SegmentParams:
        """Change some parameters (validated); stale stages rerun on the next :meth:`run`."""
        self.params = self.params.replace(**changes)
        return self.params

    def _p(self) -> SegmentParams:
        """Parameters in force: a snapshot while a stage computes, else ``self.params``."""
        return self._active if self._active is not None else self.params

    def key(self, stage: str) -> tuple:
        """Cache key of a stage: its own parameters plus its upstream stage's key."""
        up = UPSTREAM[stage]
        own = _own_key(stage, self._p())
        return own if up is None else (own, self.key(up))

    def is_fresh(self, stage: str) -> bool:
        """True if ``stage`` is cached for the current parameters."""
        entry = self._cache.get(stage)
        return entry is not None and entry[0] == self.key(stage)

    def stages(self, reconstruction: bool = True) -> list[str]:
        """Stages a run computes, in order: every stage of :data:`STAGES` but the
        reconstruction when not asked for, and no affinity and cut when the labels come
        from the superpixel clustering (``clustering="superpixels"``)."""
        names = list(STAGES if reconstruction else STAGES[:-1])
        if self._p().clustering == "superpixels":
            names = [s for s in names if s not in ("affinity", "cut")]
        return names

    def stale_stages(self, reconstruction: bool = True) -> list[str]:
        names = self.stages(reconstruction)
        return [s for s in names if not self.is_fresh(s)]

    def block_valid(self) -> np.ndarray:
        """Blocks that enter the graph (flat, row-major): at least
        :data:`MIN_VALID_BLOCK_FRACTION` of their pixels are used (not masked, saturated,
        black or invalid). The others are labelled from their nearest valid block."""
        return valid_blocks(~self.get("polarisation").invalid, self._p().window)

    # -- stages -----------------------------------------------------------------------
    def _progress(self, stage: str) -> Callable[[float], None] | None:
        """The progress callback of ``stage`` when it is the stage being run (an upstream
        stage computed on the way reports nothing)."""
        within = self._within
        return within[1] if within is not None and within[0] == stage else None

    def _compute(self, stage: str) -> Any:
        p = self._p()
        if stage == "polarisation":
            mask = self.mask
            flagged = bool(np.any(mask.flags))
            pol = polarimage.polarisation_image(
                self.stack,
                self.angles,
                robust=p.fit == "robust",
                weights=mask.sample_weights if flagged else None,
            )
            if flagged or mask.region is not None:
                pol = replace(pol, invalid=pol.invalid | ~mask.valid)
            return pol
        if stage == "normals":
            pol = self.get("polarisation")
            est = fresnel.zenith_from_dop(pol.dop, p.refractive_index, p.model, p.specular_branch)
            azimuth = fresnel.azimuth_from_phase(pol.phase, p.model)
            return Normals(est.zenith, azimuth, est.clamped)
        if stage == "harmonics":
            pol, nrm = self.get("polarisation"), self.get("normals")
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
                progress=self._progress(stage),
            )
        if stage == "pca":
            coef = self.get("harmonics")
            if coef.shape[0] * coef.shape[1] < 2:
                raise PolarsegError(
                    f"window size {p.window} leaves fewer than 2 blocks in a "
                    f"{self.stack.shape[1]} x {self.stack.shape[2]} image"
                )
            vectors = self._block_vectors(coef, p)
            valid = self.block_valid()
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
        if stage == "affinity":
            pca = self.get("pca")
            valid = self.block_valid()
            features = pca.features[valid]  # graph nodes: the blocks the mask leaves
            n = features.shape[0]
            kind = affinity_graph_kind(n, p)
            grid = self.get("harmonics").shape[:2]
            if kind == "knn":
                return affinity.knn_affinity(features, p.scale, p.scale_mode)
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
            W = self._dense_affinity(features, p)
            if p.spatial_radius > 0:
                W *= affinity.spatial_kernel(grid, p.spatial_radius, p.spatial_sigma)[
                    np.ix_(valid, valid)
                ]
            return W
        if stage == "cut":
            W = self.get("affinity")
            if p.clustering == "kway":
                # k-way spectral clustering of the same graph (spectral.py); the number of
                # segments only reruns k-means on the cached eigenvectors
                return spectral.SpectralClustering(W, min_size=p.min_segment_blocks)
            # warm start: eigenvectors of the previous tree on the same blocks (e.g. when
            # only the affinity scale changed) start the solves of identical segments
            old = self._cache.get("cut")
            warm = None
            if old is not None and isinstance(old[1], ncut.CutTree) and old[1].W.shape == W.shape:
                warm = old[1].fiedler_vectors()
            return ncut.CutTree(
                W, min_size=p.min_segment_blocks, threshold=p.ncut_threshold, warm=warm
            )
        if stage == "labels":
            if p.clustering == "superpixels":
                return self._superpixel_labels(p)
            tree = self.get("cut")
            coef = self.get("harmonics")
            valid = self.block_valid().reshape(coef.shape[:2])
            block = np.zeros(coef.shape[:2], dtype=np.int32)
            block[valid] = tree.labels(p.n_segments, cancel=self._cancel)
            limits = tree.cut_limits(p.n_segments)
            if not valid.all():
                # masked-out blocks take the label of the nearest block that was segmented
                _, (ri, ci) = ndimage.distance_transform_edt(~valid, return_indices=True)
                block = block[ri, ci]
            shape = self.stack.shape[1:]
            labels = harmonics.upsample_block_labels(block, shape, p.window)
            return block, labels, tree.ncut_values, limits
        if stage == "reconstruction":
            pol, nrm = self.get("polarisation"), self.get("normals")
            rec = harmonics.reconstruct_intensity(
                pol.intensity,
                nrm.zenith,
                nrm.azimuth,
                p.window,
                p.degree,
                ridge=p.ridge,
                weights=None if not pol.invalid.any() else ~pol.invalid,
                progress=self._progress(stage),
            )
            return Reconstruction(rec, np.abs(rec - pol.intensity))
        raise KeyError(stage)

    def _superpixel_labels(self, p: SegmentParams) -> tuple:
        """Labels stage of ``clustering="superpixels"``: (block, labels, [], None).

        The pixel labels of :func:`.unsupervised.segment_unsupervised` (measured
        defaults) on the polarisation image; block labels are the label at each block's
        top-left pixel. No graph is cut, so there are no Ncut values and no cut limits.
        """
        pol = self.get("polarisation")
        if self._cancel is not None and self._cancel():
            raise Cancelled("cancelled before the superpixel clustering")
        seg = unsupervised.segment_unsupervised(pol.intensity, pol.dop, pol.phase, p.n_segments)
        block = harmonics.top_left_block_labels(seg.labels, p.window).astype(np.int32)
        return block, seg.labels.astype(np.int64), [], None

    def _dense_affinity(self, features: np.ndarray, p: SegmentParams) -> np.ndarray:
        """exp(−D / s) of the dense graph (thesis section 4.5), D kept between runs.

        The squared Mahalanobis distances D (eq. 4.27) and their median depend only on
        the block features, so they are kept with the ``pca`` stage's key: a change of
        the affinity scale (or its mode) reruns only the exponential, one pass over the
        matrix. From ``ncut.FLOAT32_MIN_NODES`` blocks D and the affinity are stored in
        float32 (each entry computed in float64; the normalized cut multiplies with a
        float32 matrix there anyway), which halves their memory: 90 MB each at 4,752
        blocks.
        """
        key = self.key("pca")
        if self._distances is None or self._distances[0] != key:
            self._distances = None  # free the old matrix before building the new one
            n = features.shape[0]
            dtype = np.float32 if n >= dense_graph.FLOAT32_MIN_NODES else np.float64
            D = feat.mahalanobis_sq(features, dtype, out=self._matrices.take((n, n), dtype))
            self._distances = [key, D, None]
        cached = self._distances
        D = cached[1]
        mode = p.scale_mode if D.shape[0] >= 2 else "absolute"
        if mode == "median" and cached[2] is None:
            cached[2] = affinity.median_offdiagonal(D)
        scale = affinity.effective_scale(p.scale, mode, cached[2])
        return affinity.affinity_from_distances(D, scale, out=self._matrices.take(D.shape, D.dtype))

    def block_vectors(self, standardise: bool = True) -> np.ndarray:
        """Feature vector of every block (rows·cols, F) for the current ``features`` kind.

        What the ``pca`` stage reduces. With ``standardise=False`` the polarisation
        statistics are returned in their own units, so that a caller pooling several
        images (the time series' shared basis) can standardise them over all of them.
        """
        p = self._p()
        return self._block_vectors(self.get("harmonics"), p, standardise)

    def _block_vectors(
        self, coef: np.ndarray, p: SegmentParams, standardise: bool = True
    ) -> np.ndarray:
        """Feature vector of every block (rows·cols, F) for ``p.features``.

        Harmonic kinds come from the coefficients (:func:`~.features.harmonic_features`);
        ``"polstats"`` from the polarisation image directly (:mod:`.polstats`), z-scored
        because its columns have different units; ``"zonal+polstats"`` puts the z-scored
        zonal coefficients and statistics side by side.
        """
        if p.features not in POLSTATS_KINDS:
            return feat.harmonic_features(coef, p.features)
        pol, nrm = self.get("polarisation"), self.get("normals")
        stats = polstats.block_polarisation_statistics(
            pol.intensity, pol.dop, pol.phase, nrm.zenith, p.window, valid=~pol.invalid
        ).reshape(-1, len(polstats.STAT_NAMES))
        if p.features == "zonal+polstats":
            stats = np.concatenate([feat.harmonic_features(coef, "zonal"), stats], axis=1)
        return polstats.standardise(stats) if standardise else stats

    def get(self, stage: str, progress: Callable[[float], None] | None = None) -> Any:
        """Value of a stage for the current parameters, computing it if stale.

        The parameters are read once per call (a snapshot used for the cache key and by
        every upstream stage it needs), so a change made from another thread while the
        stage computes can never store a value under the wrong key. ``progress`` is
        called with the share of ``stage`` done (0..1] by the stages that loop in chunks
        (harmonics, reconstruction), after each chunk.
        """
        outer = self._active is None
        if outer:
            self._active = self.params
        if progress is not None:
            self._within = (stage, progress)
        try:
            key = self.key(stage)
            entry = self._cache.get(stage)
            if entry is not None and entry[0] == key:
                return entry[1]
            t0 = time.perf_counter()
            value = self._compute(stage)
            self._seconds[stage] = time.perf_counter() - t0
            self.calls[stage] += 1
            self._recomputed.append(stage)
            self._cache[stage] = (key, value)
            return value
        finally:
            if outer:
                self._active = None
            if progress is not None:
                self._within = None

    def stage_seconds(self, stage: str) -> float:
        """Seconds the last computation of ``stage`` took (0 if never computed)."""
        return self._seconds.get(stage, 0.0)

    # -- running ----------------------------------------------------------------------
    def run_iter(
        self,
        reconstruction: bool = True,
        cancel: Callable[[], bool] | None = None,
        progress: Callable[[str, float, int], None] | None = None,
    ) -> Iterator[tuple[str, int, int]]:
        """Run stage by stage, yielding ``(stage, index, total)`` after each.

        Stopping the iteration between yields cancels the run; cached stages stay valid.
        ``cancel`` also stops the labels stage's normalized cut from within: it is called
        before every product of its eigensolvers, and True raises :class:`Cancelled`
        (the splits made so far stay cached in the cut tree). ``progress`` is called
        *within* the stages that loop in chunks (harmonics, reconstruction) with
        ``(stage, index, total)``, ``index`` a float between the stage's boundaries: the
        stages done plus the share of this one done (e.g. 2.4 of 8 in the third stage).
        """
        names = self.stages(reconstruction)
        n = len(names)
        self._recomputed = []
        for i, name in enumerate(names):
            self._cancel = cancel
            within = None
            if progress is not None:

                def within(share: float, name: str = name, i: int = i) -> None:
                    progress(name, i + share, n)

            try:
                self.get(name, within)
            finally:
                self._cancel = None
            yield name, i + 1, n

    def run(
        self,
        reconstruction: bool = True,
        progress: Callable[[str, int, int], None] | None = None,
        cancel: Callable[[], bool] | None = None,
    ) -> SegmentationResult:
        """Run every stale stage and return the result.

        Parameters
        ----------
        reconstruction : bool
            Also rebuild Î from the harmonics and compute the error map.
        progress : callable(stage, index, total), optional
            Called after each stage.
        cancel : callable() -> bool, optional
            Checked between stages, and by the normalized cut before every product of
            its eigensolvers; returning True raises :class:`Cancelled`.
        """
        params = self.params
        for name, i, n in self.run_iter(reconstruction, cancel):
            if progress is not None:
                progress(name, i, n)
            if cancel is not None and cancel() and i < n:
                raise Cancelled(f"cancelled after stage {name!r}")
        return self.result(reconstruction, params)

    def prefetch(self, cancel: Callable[[], bool] | None = None) -> Iterator[int]:
        """Precompute, in idle time, what one more segment would need.

        With recursive cuts whose labels are fresh for the current parameters and whose
        tree stops at the current number of segments, solves the candidate split of every
        segment (:meth:`ncut.CutTree.prefetch`), yielding after each; a later change of
        ``n_segments`` to k + 1 then costs only the split (milliseconds instead of one
        or two eigensolves). Then keeps a touched buffer for the next dense affinity
        (:meth:`MatrixPool.reserve`; yields −1). Does nothing otherwise. Stopping the
        iteration between yields is safe; ``cancel`` (called before every product of an
        eigensolve, True raises :class:`Cancelled`) stops it inside a solve.
        """
        p = self.params
        if p.clustering != "recursive" or not self.is_fresh("labels"):
            return
        tree = self._cache["cut"][1]
        if isinstance(tree, ncut.CutTree) and len(tree.ncut_values) + 1 <= p.n_segments:
            yield from tree.prefetch(cancel)
        W = self._cache["affinity"][1]
        if isinstance(W, np.ndarray) and self._matrices.owns(W):
            # memory for the next affinity (a change of the scale, n or w): touched now
            # rather than while the user waits
            self._matrices.reserve(W.shape, W.dtype)
            yield -1

    def result(
        self, reconstruction: bool = True, params: SegmentParams | None = None
    ) -> SegmentationResult:
        """Assemble the result from the cache (runs stale stages if needed)."""
        if params is not None and params != self.params:
            raise PolarsegError("parameters changed while the pipeline was running")
        block, labels, ncut_values, limits = self.get("labels")
        names = self.stages(reconstruction)
        return self.assemble_result(
            block,
            labels,
            ncut_values,
            reconstruction,
            timings={s: self._seconds.get(s, 0.0) for s in names},
            recomputed=[s for s in names if s in self._recomputed],
            cut_limits=limits,
        )

    def assemble_result(
        self,
        block: np.ndarray,
        labels: np.ndarray,
        ncut_values: list[float],
        reconstruction: bool,
        timings: dict[str, float],
        recomputed: list[str],
        cut_limits: dict[str, int] | None = None,
    ) -> SegmentationResult:
        """A :class:`SegmentationResult` of the cached stages and the given labels.

        Used by the runs whose labels do not come from the cut (block and pixel
        classifiers): ``block`` (R, C) and ``labels`` (H, W) are theirs.
        """
        pol, nrm = self.get("polarisation"), self.get("normals")
        coef, pca = self.get("harmonics"), self.get("pca")
        rec = self.get("reconstruction") if reconstruction else None
        return SegmentationResult(
            params=self.params,
            intensity=pol.intensity,
            dop=pol.dop,
            phase=pol.phase,
            residual=pol.residual,
            zenith=nrm.zenith,
            azimuth=nrm.azimuth,
            clamped=nrm.clamped,
            coefficients=coef,
            features=pca.features,
            explained_variance_ratio=pca.explained_variance_ratio,
            block_labels=block,
            labels=labels,
            ncut_values=ncut_values,
            timings=timings,
            recomputed=recomputed,
            reconstruction=None if rec is None else rec.intensity,
            reconstruction_error=None if rec is None else rec.error,
            valid=~pol.invalid,
            mask_counts=self.mask.counts(),
            duplicate_angle_frames=polarimage.duplicate_angle_frames(self.angles),
            cut_limits=dict(cut_limits or {}),
        )

    def scribble_segmentation(
        self, scribbles: np.ndarray, reconstruction: bool = True
    ) -> ScribbleSegmentation:
        """The whole result of a scribble-guided run (:meth:`scribble_result`).

        Returns the :class:`SegmentationResult` (labels = class index 0..K−1, no Ncut
        values; affinity and cut are neither computed nor invalidated), the class
        probabilities (K, H, W), the scribble value of every class and the number of
        training blocks.
        """
        t0 = time.perf_counter()
        block, labels, maps, classes, n_train = self._classify(scribbles)
        seconds = time.perf_counter() - t0
        names = ["polarisation", "normals", "harmonics", "pca"]
        names += ["reconstruction"] if reconstruction else []
        timings = {s: self._seconds.get(s, 0.0) for s in names}
        timings["scribbles"] = seconds
        recomputed = [s for s in names if s in self._recomputed] + ["scribbles"]
        result = self.assemble_result(block, labels, [], reconstruction, timings, recomputed)
        return ScribbleSegmentation(result, maps, classes, n_train)

    def scribble_result(self, scribbles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Labels from a classifier trained on user strokes instead of the normalized cut.

        The block features of the ``pca`` stage (thesis section 4.3.3) of the blocks the
        strokes cover train :func:`~napari_polarseg.engine.scribbles.classify_blocks`,
        which labels every block; affinity and cut are not needed.

        Parameters
        ----------
        scribbles : array (H, W) of int
            Strokes over the stack's frames: 0 = unlabelled, 1, 2, … = materials (at
            least two).

        Returns
        -------
        labels : ndarray (H, W) of int
            Class of every pixel (remainder strips take their nearest block's), as an
            index 0..K-1 into the scribble values in ascending order.
        probabilities : ndarray (K, H, W) float
            Probability of each class per pixel (its block's); sums to 1 over K.
        """
        _, labels, maps, _, _ = self._classify(scribbles)
        return labels, maps

    def _classify(
        self, scribbles: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
        """(block labels, pixel labels, probability maps, classes, training blocks)."""
        from .analysis.scribbles import classify_blocks, training_blocks

        scribbles = np.asarray(scribbles)
        shape = self.stack.shape[1:]
        if scribbles.shape != shape:
            raise PolarsegError(
                f"the scribbles are {' x '.join(map(str, scribbles.shape))} pixels but the "
                f"frames are {shape[0]} x {shape[1]}"
            )
        window = self._p().window
        grid = self.get("harmonics").shape[:2]
        valid = self.block_valid()
        block, proba, classes = classify_blocks(
            self.get("pca").features, grid, scribbles, window, valid=valid
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # classify_blocks has warned already
            blocks, _, _ = training_blocks(scribbles, grid, window)
        rows, cols = harmonics.pixel_block_index(shape, window)
        labels = harmonics.upsample_block_labels(block, shape, window)
        maps = proba.T.reshape(-1, *grid)[:, rows[:, None], cols[None, :]]
        return block, labels, maps, classes, int(valid[blocks].sum())


def segment(
    stack: np.ndarray, angles: np.ndarray, params: SegmentParams | None = None, **changes: Any
) -> SegmentationResult:
    """One-shot convenience: run the whole pipeline on a stack (angles in radians)."""
    params = (
        (params or SegmentParams()).replace(**changes) if changes else (params or SegmentParams())
    )
    return Pipeline(stack, angles, params).run()


def intensity_baseline(
    intensity: np.ndarray,
    window: int,
    n_segments: int,
    scale: float = 1.0,
    min_segment_blocks: int = 1,
) -> np.ndarray:
    """Intensity-only baseline: the same Mahalanobis affinity and recursive normalized
    cuts on block mean and standard deviation of Î (no polarisation at all).

    Returns pixel labels (H, W) covering the whole image.
    """
    nby, nbx = harmonics.block_grid(intensity.shape, window)
    blocks = harmonics.blockify(intensity, window)  # (nby, nbx, w*w)
    x = np.stack([blocks.mean(-1), blocks.std(-1)], axis=-1).reshape(-1, 2)
    if not np.all(x.var(axis=0) > 0):
        x = x + 1e-12 * np.arange(x.shape[0])[:, None]
    W = affinity.affinity_matrix(x, scale)
    block = ncut.recursive_ncut(W, n_segments, min_size=min_segment_blocks).reshape(nby, nbx)
    return harmonics.upsample_block_labels(block, intensity.shape, window)
