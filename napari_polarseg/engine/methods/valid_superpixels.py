"""Superpixels clustered on the valid pixels only, k + 1 clusters merged down to k, and k
found by itself when asked (``n_segments = 0``): the default method (preset ``auto``).

It reads the superpixels and node features of the superpixel method
(:mod:`.superpixel_clustering`: ``unsupervised.segmenter.prepare_regions``) with two
changes, each measured:

- **Valid pixels only.** The superpixel method clusters every pixel of the user's
  region, the invalid ones (saturated, dark, failed fit: ``PolarisationImage.invalid``)
  too; their ρ and φ are meaningless, and on a frame with large saturated patches (the
  real polariser frame: 15 % of its pixels) they pull a cluster to themselves. Here
  the clustering reads the pixels that are in the region *and* valid: the maps
  elsewhere are filled from the nearest such pixel before the superpixels are drawn
  (:func:`~napari_polarseg.engine.physics.pixel_mask.fill_from_nearest`, as for a user
  region) and every other pixel takes the label of the nearest clustered one, so the
  labels inside the region still depend on nothing outside it.
- **k + 1, then merge** (:func:`~napari_polarseg.engine.unsupervised.merge.merged_clustering`):
  the superpixels are clustered into k + 1 segments and the two whose mean node
  features are closest are merged: the extra segment takes what fits no material well
  (shadows, highlights, superpixels straddling a border) instead of a material's
  cluster being bent towards it.

With ``n_segments = 0`` the number of segments is chosen among 2..6 by the silhouette
of the clustering on the superpixels' node features (:func:`choose_k`,
:func:`~napari_polarseg.engine.unsupervised.choose_k.estimate_k`); the record says
which k was used (``k``), whether it was found (``k_found``), how sure the choice is
(``k_confidence``), every k's score (``k_scores``) and the tolerance used
(``k_tolerance``); :func:`~napari_polarseg.engine.unsupervised.choose_k.choice_text`
says it in words (the CLI's lines and the plugin's status line).

The figures that chose it (and the variants not kept) are in ``docs/quality.md``
(*A default chosen on the development half*).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..params import SegmentParams
from ..unsupervised.choose_k import K_RANGE, estimate_k
from ..unsupervised.merge import EXTRA_SEGMENTS, closest_centroids, merged_clustering
from ..unsupervised.params import REGIONS_PER_OBJECT_SIDE, UnsupervisedParams, UnsupervisedResult
from ..unsupervised.segmenter import (
    RegionModel,
    cluster_regions,
    prepare_regions,
    without_refinement,
)
from ..unsupervised.tiled_regions import region_tiles, tiled_prepare_regions
from .base import MethodOutput, MethodRun
from .superpixel_clustering import SuperpixelClustering

#: Reach of the node features' diffusion in object sizes (``SegmentParams.object_size``),
#: never beyond its ``diffusion_range`` of the image side (:meth:`ValidSuperpixels.scaled_params`)
REACH_OBJECTS = 0.18

if TYPE_CHECKING:
    from ..physics.polarimage import PolarisationImage
    from .scene import Scene


def clustered_pixels(region: np.ndarray | None, invalid: np.ndarray) -> np.ndarray | None:
    """(H, W) bool: the pixels the clustering reads (in ``region`` and not ``invalid``);
    the region alone when that leaves none, None when it is every pixel."""
    valid = ~np.asarray(invalid, dtype=bool)
    if region is not None:
        valid &= region
    if not valid.any():
        valid = region
    return None if valid is None or valid.all() else valid


def choose_k(model: RegionModel, tolerance: float = 0.0) -> dict[str, Any]:
    """k of the best silhouette over :data:`K_RANGE` (no more than the superpixels
    allow; with ``tolerance``, the fewest within it of the best: :func:`estimate_k`),
    how sure, and every k's score. Each k is scored on the plain clustering
    into k (:func:`~napari_polarseg.engine.unsupervised.segmenter.cluster_regions`):
    measured, it found the true k more often than the merged one the labels come from
    (exact / within ±1 on the rendered development half 4 / 7 of 12 against 2 / 5, on
    the real frames 2 / 4 of 4 against 1 / 3)."""

    # only the superpixels' labels are scored: no pixel-level border refinement
    nodes_only = without_refinement(model)

    def node_labels(k: int) -> np.ndarray:
        return cluster_regions(nodes_only, k).node_labels

    ks = [k for k in K_RANGE if k <= model.n]
    k, confidence, scores = estimate_k(model.z, model.weight, ks, node_labels, tolerance=tolerance)
    return {"k": k, "confidence": confidence, "scores": scores}


class ValidSuperpixels(SuperpixelClustering):
    """Superpixels clustered on the valid pixels (module docstring) as a
    :class:`~.base.Segmenter`; ``n_segments = 0`` finds k. Its parameters, the
    SegmentParams fields it reads and its stages are the superpixel method's."""

    name = "valid_superpixels"
    title = "superpixels on valid pixels (unsupervised; 0 segments = find k)"
    #: ``n_segments = 0`` means "find the number of segments"
    finds_k = True
    #: ``tolerance`` of :func:`choose_k`
    k_tolerance = 0.0
    #: Which two of the k + 1 segments are merged (:mod:`..unsupervised.merge`)
    merge_rule = staticmethod(closest_centroids)
    #: Segments clustered beyond k, then merged away by :attr:`merge_rule`
    extra_segments = EXTRA_SEGMENTS
    #: The superpixel area and the diffusion's reach follow the object size
    #: (``SegmentParams.object_size``) when it is given, and also when it is estimated
    #: (``object_size = 0``) if this is set. Off: on the
    #: development halves of the scene families the estimate gained on many small
    #: objects and lost on camouflage and texture, whose grain it takes for the
    #: objects (docs/quality.md, *Scene families*); the estimate is still made and
    #: reported
    follows_estimate = False
    #: With :attr:`follows_estimate`, the estimate is followed only where it is at least
    #: this share of the image's short side; a smaller one (a texture's grain, a
    #: camouflage net's mesh, taken for objects) leaves the frame-share scales
    estimate_floor = 0.0
    #: Reach of the node features' diffusion, in object sizes
    reach_objects = REACH_OBJECTS
    #: Superpixels across one object size (the superpixel side is the object size / this)
    regions_per_side = REGIONS_PER_OBJECT_SIDE
    reads = ("fit", "n_segments", "object_size")

    def scaled_params(self, object_size: float, shape: tuple[int, int]) -> UnsupervisedParams:
        """``self.params`` at an object size of D = ``object_size`` px on an image of
        ``shape``: superpixels of side D / :attr:`regions_per_side` and a diffusion
        reaching :attr:`reach_objects` · D (:meth:`UnsupervisedParams.at_object_size`),
        each no coarser than ``self.params``' own share of the frame: small objects get
        finer superpixels and a shorter reach, large ones the frame-share scales chosen
        on the large objects of the shared renders."""
        scaled = self.params.at_object_size(
            object_size, shape, self.reach_objects, self.regions_per_side
        )
        return scaled.replace(
            region_area=min(scaled.region_area, self.params.area_of(shape)),
            diffusion_range=min(scaled.diffusion_range, self.params.diffusion_range),
        )

    def region_models(
        self, scene: Scene, pol: PolarisationImage, run: MethodRun, params: UnsupervisedParams
    ) -> list[RegionModel]:
        """The region models the labels are drawn from: here one, the superpixels and node
        features of ``params`` on the scene's clustered pixels
        (:func:`clustered_pixels`), made once per image, region and parameters and kept
        in the scene's feature cache, tile by tile when the whole image would not fit
        the scene's memory limit (less the stack: ``scene.work_limit()``;
        :func:`~..unsupervised.tiled_regions.region_tiles`); ``run`` shows the
        progress and may stop it."""

        def prepare() -> RegionModel:
            valid = clustered_pixels(scene.region, pol.invalid)
            maps = (pol.intensity, pol.dop, pol.phase)
            grid = region_tiles(pol.intensity.shape, params, scene.work_limit())
            if grid is None:
                return prepare_regions(*maps, params, valid, run.within)
            return tiled_prepare_regions(*maps, params, valid, grid, run.within)

        # the clustered pixels follow from the image (its invalid pixels) and the
        # scene's region, fixed for the scene's life: the image's identity keys them
        return [scene.cached(self.name, (id(pol), params), prepare)]

    def labels(self, models: list[RegionModel], k: int) -> UnsupervisedResult:
        """k segments of the region models: k + :attr:`extra_segments` clusters of the
        one model merged to k by :attr:`merge_rule` (:func:`merged_clustering`)."""
        return merged_clustering(models[0], k, self.extra_segments, self.merge_rule)

    def segment(
        self, scene: Scene, params: SegmentParams, inputs: dict[str, Any], run: MethodRun
    ) -> MethodOutput:
        run.begin("superpixels")
        pol = scene.polarisation(params)
        shape = pol.intensity.shape
        record: dict[str, Any] = {"invalid_share": round(float(np.mean(pol.invalid)), 6)}
        size = scene.object_size(params)
        followed = self.follows_estimate and size.size_px >= self.estimate_floor * min(shape)
        applied = followed or not size.estimated
        unsupervised = self.scaled_params(size.size_px, shape) if applied else self.params
        record.update(
            object_size=round(size.size_px, 1),
            object_size_found=size.estimated,
            object_size_applied=applied,
        )
        models = self.region_models(scene, pol, run, unsupervised)
        run.begin("clustering")
        record["k_found"] = params.n_segments == 0
        record["region_areas"] = [m.params.area_of(shape) for m in models]
        k = params.n_segments
        if k == 0:  # found on the first model's superpixels
            key = (id(pol), models[0].params)
            choice = scene.cached(
                f"{self.name}:k", key, lambda: choose_k(models[0], self.k_tolerance)
            )
            k = choice["k"]
            record["k_confidence"] = round(choice["confidence"], 4)
            record["k_tolerance"] = self.k_tolerance
            record["k_scores"] = {str(j): round(s, 4) for j, s in choice["scores"].items()}
        seg = self.labels(models, k)
        record["k"] = k
        record.update(surface_share=round(seg.surface_share, 6), close_up=seg.close_up)
        return MethodOutput(seg.labels, record=record, extra={"unsupervised": seg})
