"""Parameters of the segmentation pipeline, with the thesis defaults.

Angles inside the engine are radians; the refractive index is dimensionless; window sizes
are pixels and minimum segment sizes are blocks.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from .errors import PolarsegError

MODELS = ("diffuse", "specular")
SPECULAR_BRANCHES = ("below-brewster", "above-brewster")
COEFFICIENT_METHODS = ("thesis", "ridge")
SCALE_MODES = ("absolute", "median")
FEATURE_KINDS = ("thesis", "zonal", "energy", "polstats", "zonal+polstats")
CLUSTERING_METHODS = ("recursive", "kway", "superpixels")
FIT_METHODS = ("lsq", "robust")
AFFINITY_GRAPHS = ("auto", "dense", "sparse")
MAX_DEGREE = 60


@dataclass(frozen=True)
class SegmentParams:
    """Every tunable of the pipeline (thesis section 4.5 defaults).

    Attributes
    ----------
    window : int
        Side w of the non-overlapping w x w pixel blocks (thesis: 10).
    degree : int
        Highest spherical-harmonic degree L; the block vector has (L+1)^2 entries
        (thesis: 12).
    refractive_index : float
        Assumed refractive index n for zenith from degree of polarisation (thesis: 1.45).
    model : {"diffuse", "specular"}
        Fresnel model for the zenith: diffuse eq. 3.13 (corrected) or specular eq. 3.11.
    specular_branch : {"below-brewster", "above-brewster"}
        Which of the two specular zenith solutions to take (specular rho is not
        monotonic; it peaks at 1 at Brewster's angle).
    coefficients : {"thesis", "ridge"}
        Block coefficient estimator: the thesis mean estimator eq. 4.21 or a per-block
        ridge least-squares fit.
    ridge : float
        Ridge penalty, relative to the mean diagonal of the block Gram matrix.
    features : {"thesis", "zonal", "energy", "polstats", "zonal+polstats"}
        Block features fed to the PCA: every coefficient (thesis), the azimuth-invariant
        m = 0 coefficients, the rotation-invariant energy per degree, direct
        polarisation statistics of the block (distributions of ρ, θ and Î and their
        relation; :mod:`~napari_polarseg.engine.polstats`), or the zonal coefficients
        and the statistics together.
    variance : float
        Share of variance the PCA keeps, in (0, 1] (thesis: 0.95).
    scale : float
        Affinity scale s in S = exp(-D / s) (thesis: 1).
    scale_mode : {"absolute", "median"}
        ``"absolute"``: s as given (thesis). ``"median"``: s is relative to the median
        squared Mahalanobis distance between blocks, which keeps the graph connected
        whatever the number of PCA components.
    spatial_radius : float
        Radius, in blocks, of Shi & Malik's spatial term in the affinity; 0 (thesis)
        switches it off and connects every pair of blocks.
    spatial_sigma : float
        Width σ_X, in blocks, of the spatial term exp(−‖X_i − X_j‖² / σ_X²).
    n_segments : int
        Number of segments the recursive normalized cut stops at.
    ncut_threshold : float or None
        Stop splitting earlier when the best cut's Ncut value exceeds this.
    min_segment_blocks : int
        Smallest segment, in blocks, a cut may produce.
    clustering : {"recursive", "kway"}
        ``"recursive"``: greedy recursive two-way normalized cuts (thesis section 4.4.1).
        ``"kway"``: k-way spectral clustering — the first k generalized eigenvectors of
        the same affinity, rows normalised, k-means (Ng, Jordan & Weiss 2002)
        (:mod:`~napari_polarseg.engine.spectral`). ``"superpixels"``: no block graph;
        edge-following superpixels clustered by their ρ statistics
        (:func:`~napari_polarseg.engine.unsupervised.segment_unsupervised` with its
        measured defaults), labels at pixel resolution; the block fields above still give
        the harmonic maps and the reconstruction-error map.
    fit : {"lsq", "robust"}
        Fit of the polarisation image: exact linear least squares (optimal for Gaussian
        noise), or a robust IRLS fit (Tukey's biweight from a trimmed start) that
        resists outlying frames; see :func:`~napari_polarseg.engine.polarisation_image`.
    affinity_graph : {"auto", "dense", "sparse"}
        How the block affinity is stored. ``"dense"``: every pair of blocks (the thesis;
        n_blocks² values). ``"sparse"``: with a spatial term, the pairs within
        ``spatial_radius`` (exact); without one, each block's k nearest neighbours in
        feature space (:data:`~napari_polarseg.engine.features.KNN_NEIGHBORS`).
        ``"auto"``: sparse with a spatial term (it is exact) or above
        :data:`~napari_polarseg.engine.pipeline.DENSE_MAX_BLOCKS` blocks, else dense.
    """

    window: int = 10
    degree: int = 12
    refractive_index: float = 1.45
    model: str = "diffuse"
    specular_branch: str = "below-brewster"
    coefficients: str = "thesis"
    ridge: float = 1e-3
    features: str = "thesis"
    variance: float = 0.95
    scale: float = 1.0
    scale_mode: str = "absolute"
    spatial_radius: float = 0.0
    spatial_sigma: float = 2.0
    n_segments: int = 3
    ncut_threshold: float | None = None
    min_segment_blocks: int = 1
    clustering: str = "recursive"
    fit: str = "lsq"
    affinity_graph: str = "auto"

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`PolarsegError` naming the first parameter that is out of range."""
        if not _is_int(self.window) or self.window < 1:
            raise PolarsegError(f"window must be a positive integer, got {self.window!r}")
        if not _is_int(self.degree) or not 0 <= self.degree <= MAX_DEGREE:
            raise PolarsegError(
                f"degree must be an integer in 0..{MAX_DEGREE}, got {self.degree!r}"
            )
        n = self.refractive_index
        if not _is_number(n) or n <= 1.0:
            raise PolarsegError(f"refractive index must be a finite number > 1, got {n!r}")
        _check_choice("model", self.model, MODELS)
        _check_choice("specular_branch", self.specular_branch, SPECULAR_BRANCHES)
        _check_choice("coefficients", self.coefficients, COEFFICIENT_METHODS)
        _check_choice("scale_mode", self.scale_mode, SCALE_MODES)
        _check_choice("features", self.features, FEATURE_KINDS)
        _check_choice("fit", self.fit, FIT_METHODS)
        _check_choice("clustering", self.clustering, CLUSTERING_METHODS)
        _check_choice("affinity_graph", self.affinity_graph, AFFINITY_GRAPHS)
        if not _is_number(self.ridge) or self.ridge <= 0:
            raise PolarsegError(f"ridge must be a positive number, got {self.ridge!r}")
        if not _is_number(self.variance) or not 0 < self.variance <= 1:
            raise PolarsegError(f"variance share must be in (0, 1], got {self.variance!r}")
        if not _is_number(self.scale) or self.scale <= 0:
            raise PolarsegError(f"affinity scale must be a positive number, got {self.scale!r}")
        if not _is_number(self.spatial_radius) or self.spatial_radius < 0:
            raise PolarsegError(
                f"spatial_radius must be a number >= 0, got {self.spatial_radius!r}"
            )
        if not _is_number(self.spatial_sigma) or self.spatial_sigma <= 0:
            raise PolarsegError(f"spatial_sigma must be a number > 0, got {self.spatial_sigma!r}")
        if not _is_int(self.n_segments) or self.n_segments < 1:
            raise PolarsegError(
                f"number of segments must be a positive integer, got {self.n_segments!r}"
            )
        if self.ncut_threshold is not None and (
            not _is_number(self.ncut_threshold) or self.ncut_threshold <= 0
        ):
            raise PolarsegError(
                f"ncut_threshold must be positive or None, got {self.ncut_threshold!r}"
            )
        if not _is_int(self.min_segment_blocks) or self.min_segment_blocks < 1:
            raise PolarsegError(
                f"min_segment_blocks must be a positive integer, got {self.min_segment_blocks!r}"
            )

    def replace(self, **changes: Any) -> SegmentParams:
        """Return a copy with some fields changed (validated)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise PolarsegError(f"unknown parameter(s): {', '.join(sorted(unknown))}")
        return SegmentParams(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SegmentParams:
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise PolarsegError(f"unknown parameter(s): {', '.join(sorted(unknown))}")
        return cls(**data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> SegmentParams:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise PolarsegError(f"parameters are not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise PolarsegError("parameters JSON must be an object")
        return cls.from_dict(data)


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _is_number(v: Any) -> bool:
    return (
        isinstance(v, (int, float, np.integer, np.floating))
        and not isinstance(v, (bool, np.bool_))
        and math.isfinite(float(v))
    )


def _check_choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if not isinstance(value, str) or value not in choices:
        raise PolarsegError(f"{name} must be one of {', '.join(choices)}; got {value!r}")


#: Parameters that beat the thesis defaults on the bundled synthetic scenes (chosen with
#: ``benchmarks/evaluate.py --sweep``; docs/quality.md has the table).
#: The thesis's absolute affinity scale s = 1 with 10-20 PCA components gives affinities
#: near e^-30: the graph falls apart and the cut peels off single blocks, so the scale is
#: relative to the median distance here; the azimuth-invariant zonal coefficients drop
#: the surface-azimuth variation that dominates the raw coefficients; a minimum segment
#: size stops the cut from isolating a few odd blocks.
RECOMMENDED = SegmentParams(
    window=12,
    degree=8,
    features="zonal",
    scale=2.0,
    scale_mode="median",
    min_segment_blocks=4,
)


#: The default of ``segment``, ``demo`` and the plugin (preset ``auto``): the recommended
#: block parameters for the harmonic maps and the error map, labels from the
#: unsupervised superpixel clustering (``clustering="superpixels"``), the best
#: unsupervised method measured on the rendered scenes and the hand-labelled real frames
#: together (``benchmarks/evaluate_unsupervised.py``).
AUTO = RECOMMENDED.replace(clustering="superpixels")

#: The named starting points of the CLI's ``--preset`` and the plugin's preset menu.
PRESETS: dict[str, SegmentParams] = {
    "auto": AUTO,
    "thesis": SegmentParams(),
    "recommended": RECOMMENDED,
}
