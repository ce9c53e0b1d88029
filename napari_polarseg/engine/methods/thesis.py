"""The thesis method: recursive normalized cuts of the block graph (thesis section 4.5).

Zenith from ρ (Fresnel), spherical-harmonic coefficients per w × w block, PCA,
Mahalanobis affinity S = exp(−D / s), recursive two-way (or k-way) normalized cuts;
the stages and their cache are the :class:`~napari_polarseg.engine.Pipeline`'s, which
the :class:`~.scene.Scene` shares.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..params import SegmentParams
from .base import MethodOutput, MethodRun

if TYPE_CHECKING:
    from .scene import Scene

#: The SegmentParams fields of the block pipeline (every stage up to the labels).
THESIS_READS = (
    "fit",
    "refractive_index",
    "model",
    "specular_branch",
    "window",
    "degree",
    "coefficients",
    "ridge",
    "features",
    "variance",
    "scale",
    "scale_mode",
    "spatial_radius",
    "spatial_sigma",
    "affinity_graph",
    "min_segment_blocks",
    "ncut_threshold",
    "clustering",
    "n_segments",
)


class ThesisBlocks:
    """The thesis block pipeline as a :class:`~.base.Segmenter`."""

    name = "thesis"
    title = "thesis blocks (normalized cuts)"
    reads = THESIS_READS
    inputs: tuple[str, ...] = ()
    #: it cuts the block grid and computes the block maps (harmonics, PCA, error map)
    block_maps = True

    def stages(self, params: SegmentParams) -> tuple[str, ...]:
        return ("harmonics", "pca", "affinity", "cut", "labels")

    def segment(
        self, scene: Scene, params: SegmentParams, inputs: dict[str, Any], run: MethodRun
    ) -> MethodOutput:
        pipe = scene.pipeline
        value, seconds = None, {}
        for stage in self.stages(params):
            run.begin(stage)
            fresh = pipe.is_fresh(stage, params)
            value = pipe.get(stage, params, progress=run.within, cancel=run.cancel)
            if not fresh:
                seconds[stage] = pipe.stage_seconds(stage)
        _, labels, ncut_values, limits, _ = value
        return MethodOutput(
            labels, seconds or {"labels": 0.0}, list(ncut_values), dict(limits or {})
        )
