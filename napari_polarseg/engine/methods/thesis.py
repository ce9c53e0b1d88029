"""The thesis method: recursive normalized cuts of the block graph (thesis section 4.5).

Zenith from ρ (Fresnel), spherical-harmonic coefficients per w × w block, PCA,
Mahalanobis affinity S = exp(−D / s), recursive two-way (or k-way) normalized cuts;
the stages and their cache are the :class:`~napari_polarseg.engine.Pipeline`'s, which
the :class:`~.scene.Scene` shares.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..errors import PolarsegError
from ..param_spec import attribute_docs, check_choice, is_int, is_number, param_field
from ..params import (
    AFFINITY_GRAPHS,
    CLUSTERING_METHODS,
    COEFFICIENT_METHODS,
    FEATURE_KINDS,
    MAX_DEGREE,
    SCALE_MODES,
    SegmentParams,
)
from .base import MethodOutput, MethodRun

if TYPE_CHECKING:
    from .scene import Scene


@dataclass(frozen=True)
class ThesisParams:
    """The thesis method's own parameters (thesis section 4.5 defaults): the w × w block
    grid, the harmonic coefficients, the PCA, the affinity and the cut. The thesis maps
    of any run (harmonic coefficients, PCA features, reconstruction error) read them too.

    Window sizes are pixels, minimum segment sizes blocks, radii and widths blocks.
    """

    window: int = param_field(
        10,
        help="Side w of the non-overlapping w x w pixel blocks, in pixels",
        flag="--window",
        metavar="W",
        label="window size",
        minimum=2,
        maximum=4096,
        effect="Size of the square blocks the image is cut into: larger gives smoother, "
        "blockier segments and a faster run; smaller follows finer detail but is "
        "noisier",
    )
    degree: int = param_field(
        12,
        help="Highest spherical-harmonic degree L; the block vector has (L+1)² entries",
        flag="--degree",
        metavar="L",
        label="harmonic degree",
        minimum=0,
        maximum=MAX_DEGREE,
        effect="How much detail of each block's shading is compared: higher tells similar "
        "materials apart better, but runs slower and can pick up noise",
    )
    coefficients: str = param_field(
        "thesis",
        help="Block coefficient estimator: the thesis mean estimator (eq. 4.21) or a "
        "per-block ridge least-squares fit",
        flag="--coefficients",
        label="coefficients",
        choices=COEFFICIENT_METHODS,
        effect="How each block's shading is summarised: the thesis estimate, or a fit that is "
        "steadier on small or partly masked blocks",
    )
    ridge: float = param_field(
        1e-3,
        help="Ridge penalty of the 'ridge' estimator, relative to the mean diagonal of the "
        "block Gram matrix",
        flag="--ridge",
    )
    features: str = param_field(
        "thesis",
        help="Block features for the PCA: every coefficient (thesis), the "
        "azimuth-invariant m = 0 coefficients (zonal), the energy per degree (energy), "
        "polarisation statistics of the block: the distributions of ρ, θ and Î and "
        "their relation (polstats), or the zonal coefficients and the statistics "
        "together (zonal+polstats)",
        flag="--features",
        label="features",
        choices=FEATURE_KINDS,
        effect="What is compared between blocks: the whole shading description, the part that "
        "does not change when the object turns, or polarisation statistics; changes "
        "which materials look alike",
    )
    variance: float = param_field(
        0.95,
        help="Share of the variance the PCA keeps, in (0, 1]",
        flag="--variance",
        label="PCA variance",
        minimum=0.05,
        maximum=1.0,
        step=0.01,
        decimals=3,
        effect="How much of the block description is kept: lower runs faster and merges "
        "materials that differ only slightly",
    )
    scale: float = param_field(
        1.0,
        help="Affinity scale s in S = exp(-D / s)",
        flag="--scale",
        label="affinity scale",
        minimum=0.001,
        maximum=1e6,
        step=0.1,
        decimals=3,
        effect="How different two blocks must be to end up apart: smaller splits more readily, "
        "larger groups more",
    )
    scale_mode: str = param_field(
        "absolute",
        help="absolute: s as given (thesis); median: s relative to the median squared "
        "Mahalanobis distance between blocks, which keeps the graph connected whatever "
        "the number of PCA components",
        flag="--scale-mode",
        label="scale mode",
        choices=SCALE_MODES,
        effect="absolute: the scale as given; median: the scale adapts to the image, steadier "
        "from one image to the next",
    )
    spatial_radius: float = param_field(
        0.0,
        help="Radius, in blocks, of Shi & Malik's spatial term in the affinity; 0 switches "
        "it off and connects every pair of blocks",
        flag="--spatial-radius",
        metavar="R",
    )
    spatial_sigma: float = param_field(
        2.0,
        help="Width σ_X, in blocks, of the spatial term exp(−‖X_i − X_j‖² / σ_X²)",
        flag="--spatial-sigma",
        metavar="S",
    )
    ncut_threshold: float | None = param_field(
        None,
        help="Stop splitting earlier when the best cut's Ncut value exceeds this (none: never)",
        flag="--ncut-threshold",
        metavar="T",
        optional=True,
    )
    min_segment_blocks: int = param_field(
        1,
        help="Smallest segment, in blocks, a cut may produce",
        flag="--min-segment-blocks",
        metavar="B",
        label="min segment (blocks)",
        minimum=1,
        maximum=100_000,
        effect="The smallest segment allowed, in blocks: raise it to stop tiny specks becoming "
        "segments of their own",
    )
    clustering: str = param_field(
        "recursive",
        help="How the thesis method splits the block graph into segments: recursive "
        "two-way normalized cuts (thesis section 4.4.1) or k-way spectral clustering "
        "(the first k generalized eigenvectors, rows normalised, k-means; Ng, Jordan & "
        "Weiss 2002)",
        flag="--clustering",
        label="clustering",
        choices=CLUSTERING_METHODS,
        choice_names={
            "recursive": "recursive two-way",
            "kway": "k-way spectral",
        },
        effect="How the segments are cut apart: one split at a time (thesis) or all at once "
        "(k-way, often more even segments)",
    )
    affinity_graph: str = param_field(
        "auto",
        help="How the block affinity is stored: every pair of blocks (dense, the thesis); "
        "the pairs within spatial_radius, or without a spatial term each block's k "
        "nearest neighbours in feature space (sparse); sparse with a spatial term or "
        "above 6000 blocks, else dense (auto)",
        flag="--affinity-graph",
        choices=AFFINITY_GRAPHS,
    )

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`PolarsegError` naming the first parameter that is out of range."""
        if not is_int(self.window) or self.window < 1:
            raise PolarsegError(f"window must be a positive integer, got {self.window!r}")
        if not is_int(self.degree) or not 0 <= self.degree <= MAX_DEGREE:
            raise PolarsegError(
                f"degree must be an integer in 0..{MAX_DEGREE}, got {self.degree!r}"
            )
        check_choice("coefficients", self.coefficients, COEFFICIENT_METHODS)
        check_choice("scale_mode", self.scale_mode, SCALE_MODES)
        check_choice("features", self.features, FEATURE_KINDS)
        check_choice("clustering", self.clustering, CLUSTERING_METHODS)
        check_choice("affinity_graph", self.affinity_graph, AFFINITY_GRAPHS)
        if not is_number(self.ridge) or self.ridge <= 0:
            raise PolarsegError(f"ridge must be a positive number, got {self.ridge!r}")
        if not is_number(self.variance) or not 0 < self.variance <= 1:
            raise PolarsegError(f"variance share must be in (0, 1], got {self.variance!r}")
        if not is_number(self.scale) or self.scale <= 0:
            raise PolarsegError(f"affinity scale must be a positive number, got {self.scale!r}")
        if not is_number(self.spatial_radius) or self.spatial_radius < 0:
            raise PolarsegError(
                f"spatial_radius must be a number >= 0, got {self.spatial_radius!r}"
            )
        if not is_number(self.spatial_sigma) or self.spatial_sigma <= 0:
            raise PolarsegError(f"spatial_sigma must be a number > 0, got {self.spatial_sigma!r}")
        if self.ncut_threshold is not None and (
            not is_number(self.ncut_threshold) or self.ncut_threshold <= 0
        ):
            raise PolarsegError(
                f"ncut_threshold must be positive or None, got {self.ncut_threshold!r}"
            )
        if not is_int(self.min_segment_blocks) or self.min_segment_blocks < 1:
            raise PolarsegError(
                f"min_segment_blocks must be a positive integer, got {self.min_segment_blocks!r}"
            )


ThesisParams.__doc__ = (ThesisParams.__doc__ or "") + attribute_docs(ThesisParams, "thesis")

#: The shared SegmentParams fields the block pipeline reads (its own parameters,
#: :class:`ThesisParams`, are part of its cache key in any case).
THESIS_READS = ("fit", "refractive_index", "model", "specular_branch", "n_segments")


class ThesisBlocks:
    """The thesis block pipeline as a :class:`~.base.Segmenter`."""

    name = "thesis"
    title = "thesis blocks (normalized cuts)"
    reads = THESIS_READS
    params_class = ThesisParams
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
