"""The surface-superpixel method run at several superpixel sizes, the runs' segments
combined by a consensus (``--method superpixel_consensus``; a peer of the default, not
the default).

Everything of :class:`~.surface_superpixels.SurfaceSuperpixels` (valid pixels only,
features diffused over whole surfaces, k + 1 clusters merged to k across the weakest
border, ``n_segments = 0`` finds k) is kept; but the superpixels are drawn at
:data:`AREA_FACTORS` × the method's superpixel area, each size is segmented into k, and
the labels are those the sizes agree on
(:func:`~napari_polarseg.engine.unsupervised.consensus.consensus_clustering`: each
superpixel of the finest size described by the share of its pixels in each run's
segments, these shares clustered into k).

What it is for: one set of superpixels decides by where its borders happen to fall
whether a small object, a soft shadow or the rim of a shading gradient joins one
cluster or another; the sizes draw those borders differently. On the development
scenes the consensus scored above one size, with fewer degenerate results, and it
separates the orange from the paper on the real fruits frame, which one size does not;
on the held-out renders it is level with one size, so it is not the default
(``docs/quality.md``, *A consensus over superpixel sizes*). k, when found
(``n_segments = 0``), is found on the finest size, as by the surface-superpixel method.

Cost: one superpixel run per size, drawn concurrently; the sizes' models stay in the
scene's cache, so another number of segments reclusters only the nodes.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from ..chunks import in_background
from ..unsupervised.consensus import consensus_clustering
from ..unsupervised.params import UnsupervisedParams, UnsupervisedResult
from ..unsupervised.pixel_maps import pixel_maps
from ..unsupervised.segmenter import RegionModel, prepare_regions
from .base import MethodRun
from .surface_superpixels import SurfaceSuperpixels
from .valid_superpixels import clustered_pixels

if TYPE_CHECKING:
    from ..physics.polarimage import PolarisationImage
    from .scene import Scene

#: Superpixel areas of the runs, multiples of the method's own area (the first, 1, is
#: the run whose superpixels carry the labels).
AREA_FACTORS = (1.0, 2.0, 3.0)


class SuperpixelConsensus(SurfaceSuperpixels):
    """:class:`~.surface_superpixels.SurfaceSuperpixels` at the superpixel sizes of
    :data:`AREA_FACTORS`, the labels their consensus (module docstring); ``n_segments
    = 0`` finds k."""

    name = "superpixel_consensus"
    title = "superpixels at three sizes, the segments they agree on (unsupervised)"
    area_factors = AREA_FACTORS
    #: its sizes are multiples of the frame-share area, as measured: an estimated object
    #: size is reported, not followed (a given one is)
    follows_estimate = False

    def region_models(
        self, scene: Scene, pol: PolarisationImage, run: MethodRun, params: UnsupervisedParams
    ) -> list[RegionModel]:
        """One region model per size of :attr:`area_factors`, the finest first, kept
        together in the scene's feature cache. What does not depend on the size
        (:func:`pixel_maps`) is made once; the coarser sizes are drawn in threads of
        their own while the finest is drawn here (the watershed and numpy release the
        GIL); the finest reports the stage's progress, and a stop asked for ends the
        wait at once."""
        area = params.area_of(pol.intensity.shape)
        sizes = [
            params if f == 1 else params.replace(region_area=max(4, round(f * area)))
            for f in self.area_factors
        ]

        def prepare() -> list[RegionModel]:
            valid = clustered_pixels(scene.region, pol.invalid)
            maps = (pol.intensity, pol.dop, pol.phase)
            # the maps filled outside the valid pixels, the node features' per-pixel
            # terms and the edge map do not depend on the size: made once
            shared = pixel_maps(*maps, params, valid)
            run.within(0.1)
            later = [
                in_background(partial(prepare_regions, *maps, p, pixels=shared)) for p in sizes[1:]
            ]

            def progress(done: float) -> None:
                run.within(0.1 + 0.9 * done)

            first = prepare_regions(*maps, sizes[0], progress=progress, pixels=shared)
            return [first, *(wait(run.check) for wait in later)]

        return scene.cached(self.name, (id(pol), params), prepare)

    def labels(self, models: list[RegionModel], k: int) -> UnsupervisedResult:
        """k segments the sizes' runs agree on (:func:`consensus_clustering`, each run
        merged by :attr:`merge_rule`)."""
        return consensus_clustering(models, k, merge=self.merge_rule, seed=self.params.seed)
