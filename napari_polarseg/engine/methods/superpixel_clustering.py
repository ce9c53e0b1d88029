"""The superpixel method (preset ``auto``): edge-following superpixels clustered by their
polarisation (:mod:`napari_polarseg.engine.unsupervised.segmenter`).

The superpixels, their node features and projection (:func:`prepare_regions`) depend on
the polarisation image and the mask only, so they are kept in the scene's feature
cache: another number of segments reclusters a few thousand nodes
(:func:`cluster_regions`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..params import SegmentParams
from ..timing import timed
from ..unsupervised.params import UnsupervisedParams
from ..unsupervised.segmenter import cluster_regions, prepare_regions
from .base import MethodOutput, MethodRun

if TYPE_CHECKING:
    from .scene import Scene


class SuperpixelClustering:
    """Superpixels clustered by their polarisation as a :class:`~.base.Segmenter`
    (measured defaults, ``UnsupervisedParams()``)."""

    name = "superpixels"
    title = "superpixels (unsupervised)"
    reads = ("fit", "n_segments")
    inputs: tuple[str, ...] = ()
    #: The labels read Î, ρ, φ only: the scene computes the normals after the method
    reads_normals = False

    def __init__(self, params: UnsupervisedParams | None = None) -> None:
        self.params = params or UnsupervisedParams()

    def stages(self, params: SegmentParams) -> tuple[str, ...]:
        return ("superpixels", "clustering")

    def segment(
        self, scene: Scene, params: SegmentParams, inputs: dict[str, Any], run: MethodRun
    ) -> MethodOutput:
        run.begin("superpixels")
        pol = scene.polarisation(params)
        region = scene.region
        seconds: dict[str, float] = {}

        def prepare() -> Any:
            with timed(seconds, "superpixels"):
                return prepare_regions(
                    pol.intensity, pol.dop, pol.phase, self.params, region, run.within
                )

        model = scene.cached("superpixels", (id(pol), self.params), prepare)
        run.begin("clustering")
        with timed(seconds, "clustering"):
            seg = cluster_regions(model, params.n_segments)
        record = {"surface_share": round(seg.surface_share, 6), "close_up": seg.close_up}
        return MethodOutput(seg.labels, seconds, record=record, extra={"unsupervised": seg})
