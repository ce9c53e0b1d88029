"""Parameters and result of the unsupervised segmenter (:mod:`.segmenter`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..errors import PolarsegError
from ..features.superpixels import auto_region_area
from .texture import TEXTURE_FEATURES

#: Automatic superpixel area: the image's pixels / this, within the bounds below.
REGIONS_PER_IMAGE = 3000
MIN_REGION_AREA = 32
MAX_REGION_AREA = 1024
#: Superpixels of at least this area (px) grow on the 2 × 2 block means of the edge map
#: (:meth:`UnsupervisedParams.watershed_grid_of`): the largest frame-share area, reached
#: from about 3 MP; no frame of the quality benches is that large.
COARSE_WATERSHED_AREA = MAX_REGION_AREA

#: Superpixel side per object size: at an object size of D px the superpixel area is
#: (D / :data:`REGIONS_PER_OBJECT_SIDE`)² px, within [:data:`MIN_OBJECT_REGION_AREA`,
#: :data:`MAX_REGION_AREA`] (:meth:`UnsupervisedParams.at_object_size`).
REGIONS_PER_OBJECT_SIDE = 8.0
#: The smallest superpixel area the object size gives (a 3 × 3 patch).
MIN_OBJECT_REGION_AREA = 9

#: Projections of the standardised node features (:func:`maf_features`, PCA).
PROJECTIONS = ("pca", "maf")


#: Clustering methods (module docstring, step 3).
CLUSTERINGS = ("gmm", "kmeans", "ncut", "kway")


#: Per-region features of :func:`node_features`, in order.
NODE_FEATURES = (
    "log_intensity",  # mean of log Î over the region
    "intensity_spread",  # standard deviation of log Î over the region
    "dop",  # mean ρ
    "dop_spread",  # standard deviation of ρ
    "dolp",  # |(ΣS1, ΣS2)| / ΣS0: DoLP of the region's summed Stokes vector
    "aolp_coherence",  # |mean e^{2iφ}|
    "dolp_over_dop",  # DoLP / mean ρ: polarisation coherence, shading-free
    "dop_vs_log_intensity_slope",  # least-squares slope of ρ against log Î
    "dop_vs_log_intensity_corr",  # correlation of ρ and log Î
    "log_dop_given_intensity",  # log mean ρ less its image-wide fit on mean log Î
    # the texture group (:mod:`.texture`), each less its fit on the regions' mean log Î:
    "dop_grain",  # γ of ρ at lag 1 px over γ at lags 1 + 2: fine against coarse relief
    "aolp_grain",  # γ of the AoLP phasor e^{2iφ} at lag 1 px
    "intensity_grain",  # log γ of log Î at lag 1 px
    "dop_over_shape_trend",  # polarisation / the trend of one smooth surface (close-up)
)

#: Node features of a close-up of one smooth surface (:meth:`UnsupervisedParams.close_up_params`).
CLOSE_UP_FEATURES = ("dop_over_shape_trend",)
#: Default (degree, reach, iterations) of the surface trend (:mod:`.shape_trend`).
TREND = (2, 0.10, 2)


#: The physical material cue (module docstring): the ρ–shading relation.
MATERIAL_CUE = ("dop_vs_log_intensity_slope", "dop_vs_log_intensity_corr")


@dataclass(frozen=True)
class UnsupervisedParams:
    """Parameters of :func:`segment_unsupervised`.

    Attributes
    ----------
    region_area : int
        Mean superpixel area, pixels; 0 = the image's pixels / :data:`REGIONS_PER_IMAGE`,
        within [:data:`MIN_REGION_AREA`, :data:`MAX_REGION_AREA`].
    boundary : {"polarisation", "intensity"}
        Edges the superpixels follow: log Î and the normalised Stokes components, or
        log Î alone (:func:`~napari_polarseg.engine.features.superpixels.superpixels`).
    polarisation_edge_weight : float
        Weight of the Stokes edge map against the log Î one (``boundary="polarisation"``).
    border_intensity_weight : float
        Weight of the log Î edge map in the border strengths of the diffusion and of the
        merge (:func:`~napari_polarseg.engine.features.superpixels.border_channels`'
        a), in [0, 1]; the superpixels follow their own map whatever it is. 1: the
        superpixels' map; 0: the Stokes edges alone, so the diffusion and the merge cross
        a step of Î across which ρ and φ run on (a cast shadow's edge, a fold in the
        shading) as they cross the inside of a surface (``boundary="polarisation"``).
    border_gate : float
        K of the gate on those log Î edges, >= 0; 0 = off (they weigh in full). Above 0
        a border's log Î edges weigh c = 1 − exp(−(Δz / (K · median Δz))²), Δz the
        difference of the two superpixels' complex polarisation
        (:func:`~.region_diffusion.gated_strength`): an intensity step counts as a
        border only where the polarisation changes across it (``boundary="polarisation"``).
    features : tuple of str
        Node features, names from :data:`NODE_FEATURES` (the default: the measured
        best of the module docstring).
    texture : tuple of str
        Node features of the texture group (:data:`.texture.TEXTURE_FEATURES`) added after
        ``features``: standardised and clipped like them but not diffused (the
        diffusion's borders follow the mean maps, which do not change where only the
        relief does), then scaled by ``texture_weight``; () = none.
    texture_weight : float
        Weight of the texture columns against the others (each of unit variance before
        the diffusion), >= 0.
    pixel_scales : tuple of float
        σ (pixels) of the :mod:`.pixel_features` stack averaged per region and added to
        the node features; () = none.
    pixel_groups : tuple of str
        Groups of that stack (:data:`~napari_polarseg.engine.features.pixel_feature_params.GROUPS`,
        without ``regions``).
    coherence_power : float
        Each node feature weighed per scene by (its Moran's I over the superpixels'
        border graph / the largest)^p (:mod:`.spatial_weights`), p >= 0; 0 = off.
    variance : float
        Share of the variance the PCA of the standardised node features keeps, (0, 1].
    clustering : {"gmm", "kmeans", "ncut", "kway"}
        Module docstring, step 3.
    covariance : {"full", "tied", "diag", "spherical"}
        Covariance type of the Gaussian mixture (scikit-learn ``covariance_type``).
    smoothing : float
        λ of the posterior smoothing over the region adjacency, [0, 1) (gmm, kmeans).
    smoothing_iterations : int
        Iterations of that smoothing.
    scale : float
        s of the affinity exp(−D / s) in units of the median D over the graph's edges
        (ncut, kway).
    refine_boundaries : bool
        Relabel the pixels on segment borders (:func:`refine_boundaries`): a watershed
        border on a straight edge is a pixel off on one side.
    diffusion : float
        λ of the edge-aware diffusion of the standardised node features over the region
        graph (:mod:`.region_diffusion`), [0, 1]; 0 = none.
    diffusion_range : float
        Reach of that diffusion as a share of the image's side √(H·W): after t steps a
        feature has spread over about √(λ t) regions of side √area, so
        t = ⌈range² · n / λ⌉ for n superpixels (:func:`.region_diffusion.diffusion_steps`), the same
        share of the frame whatever its resolution.
    diffusion_tau : float
        τ of its border weights exp(−(e / τ)²), in units of the median border strength.
    clip : float
        Winsorise the standardised node features at ± ``clip`` standard deviations
        before the projection (0 = not at all): a superpixel straddling two materials
        has a large spread of ρ and would otherwise pull a cluster of its own.
    seed : int
        Seed of every random step (k-means and mixture initialisations).
    close_up_share : float
        When the square of one linear field explains more than this share of the
        variance of the superpixels' complex polarisation ρ e^{2iφ}
        (:func:`.shape_trend.surface_trend_share`: ρ e^{2iφ} ≈ c g² with the surface
        gradient g about linear over the frame), the frame is taken for a close-up of
        one smooth surface and segmented with :meth:`close_up_params`; [0, 1],
        1 = never.
    trend_degree : int
        Degree of the polynomial trend of ``dop_over_shape_trend`` in the image
        coordinates.
    trend_reach : float
        σ of the Gaussian weights of ``dop_over_shape_trend`` as a share of √(H·W).
    trend_iterations : int
        Refits of the trend on the surface's main material (an Otsu split of the ratio).
    """

    region_area: int = 0
    boundary: str = "polarisation"
    polarisation_edge_weight: float = 1.0
    border_intensity_weight: float = 1.0
    border_gate: float = 0.0
    features: tuple[str, ...] = (
        "log_intensity",
        "dop",
        "dop_spread",
        "dop_vs_log_intensity_slope",
    )
    texture: tuple[str, ...] = ()
    texture_weight: float = 1.0
    coherence_power: float = 0.0
    pixel_scales: tuple[float, ...] = ()
    pixel_groups: tuple[str, ...] = ("intensity", "polarisation", "invariant")
    variance: float = 0.95
    projection: str = "pca"
    components: int = 4
    clustering: str = "kmeans"
    covariance: str = "full"
    smoothing: float = 0.3
    smoothing_iterations: int = 5
    scale: float = 1.0
    refine_boundaries: bool = True
    diffusion: float = 0.5
    diffusion_range: float = 0.07
    diffusion_tau: float = 0.75
    clip: float = 2.0
    seed: int = 0
    close_up_share: float = 0.8
    trend_degree: int = TREND[0]
    trend_reach: float = TREND[1]
    trend_iterations: int = TREND[2]

    def __post_init__(self) -> None:
        if int(self.region_area) < 0 or 0 < int(self.region_area) < 4:
            raise PolarsegError(f"region_area must be 0 (auto) or >= 4, got {self.region_area}")
        if self.boundary not in ("polarisation", "intensity"):
            raise PolarsegError(
                f"boundary must be 'polarisation' or 'intensity', got {self.boundary!r}"
            )
        self._check_edges()
        features = tuple(str(f) for f in self.features)
        unknown = [f for f in features if f not in NODE_FEATURES]
        self._check_texture()
        if unknown or (not features and not self.pixel_scales):
            raise PolarsegError(
                f"features must be some of {', '.join(NODE_FEATURES)}; got {self.features!r}"
            )
        scales = tuple(float(s) for s in self.pixel_scales)
        if not all(math.isfinite(s) and s > 0 for s in scales):
            raise PolarsegError(f"pixel_scales must be positive, got {self.pixel_scales!r}")
        if not (0 < self.variance <= 1):
            raise PolarsegError(f"variance must be in (0, 1], got {self.variance}")
        if self.projection not in PROJECTIONS:
            raise PolarsegError(
                f"projection must be one of {', '.join(PROJECTIONS)}, got {self.projection!r}"
            )
        if int(self.components) < 1:
            raise PolarsegError(f"components must be >= 1, got {self.components}")
        if self.clustering not in CLUSTERINGS:
            raise PolarsegError(
                f"clustering must be one of {', '.join(CLUSTERINGS)}, got {self.clustering!r}"
            )
        if self.covariance not in ("full", "tied", "diag", "spherical"):
            raise PolarsegError(
                f"covariance must be full, tied, diag or spherical, got {self.covariance!r}"
            )
        if not (0 <= self.smoothing < 1):
            raise PolarsegError(f"smoothing must be in [0, 1), got {self.smoothing}")
        if int(self.smoothing_iterations) < 0:
            raise PolarsegError(
                f"smoothing_iterations must be >= 0, got {self.smoothing_iterations}"
            )
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise PolarsegError(f"scale must be positive, got {self.scale}")
        if not (0 <= self.diffusion <= 1):
            raise PolarsegError(f"diffusion must be in [0, 1], got {self.diffusion}")
        if not (math.isfinite(self.diffusion_range) and 0 <= self.diffusion_range <= 1):
            raise PolarsegError(f"diffusion_range must be in [0, 1], got {self.diffusion_range}")
        if not (math.isfinite(self.diffusion_tau) and self.diffusion_tau > 0):
            raise PolarsegError(f"diffusion_tau must be positive, got {self.diffusion_tau}")
        if not (math.isfinite(self.coherence_power) and self.coherence_power >= 0):
            raise PolarsegError(f"coherence_power must be >= 0, got {self.coherence_power}")
        if not (math.isfinite(self.clip) and self.clip >= 0):
            raise PolarsegError(f"clip must be >= 0, got {self.clip}")
        if not (math.isfinite(self.close_up_share) and 0 <= self.close_up_share <= 1):
            raise PolarsegError(f"close_up_share must be in [0, 1], got {self.close_up_share}")
        if int(self.trend_degree) < 1 or int(self.trend_iterations) < 0:
            raise PolarsegError(
                "trend_degree must be >= 1 and trend_iterations >= 0, got "
                f"{self.trend_degree} and {self.trend_iterations}"
            )
        if not (math.isfinite(self.trend_reach) and self.trend_reach > 0):
            raise PolarsegError(f"trend_reach must be positive, got {self.trend_reach}")
        object.__setattr__(self, "features", features)
        groups = tuple(str(g) for g in self.pixel_groups)
        allowed = ("intensity", "polarisation", "zenith", "filters", "invariant")
        if scales and (not groups or any(g not in allowed for g in groups)):
            raise PolarsegError(
                f"pixel_groups must be some of {', '.join(allowed)}; got {self.pixel_groups!r}"
            )
        object.__setattr__(self, "pixel_groups", groups)
        object.__setattr__(self, "pixel_scales", scales)
        object.__setattr__(self, "region_area", int(self.region_area))
        object.__setattr__(self, "smoothing_iterations", int(self.smoothing_iterations))
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "trend_degree", int(self.trend_degree))
        object.__setattr__(self, "trend_iterations", int(self.trend_iterations))

    def area_of(self, shape: tuple[int, int]) -> int:
        """Superpixel area (pixels) used on an image of ``shape``."""
        if self.region_area:
            return self.region_area
        return auto_region_area(shape, REGIONS_PER_IMAGE, MIN_REGION_AREA, MAX_REGION_AREA)

    def watershed_grid_of(self, shape: tuple[int, int]) -> int:
        """Block side of the superpixels' watershed on an image of ``shape``
        (:func:`~..features.superpixels.watershed_on_grid`): 2 where the superpixel area
        is at least :data:`COARSE_WATERSHED_AREA` (a region then spans 256 blocks and its
        borders are placed again to the pixel by the border refinement), else 1.
        Measured (``docs/performance.md``): at 5 MP the whole-image run 2.1 × faster,
        ARI against the hand labels 0.8396 against 0.8400 at full resolution."""
        return 2 if self.area_of(shape) >= COARSE_WATERSHED_AREA else 1

    def at_object_size(
        self,
        object_size: float,
        shape: tuple[int, int],
        reach_objects: float,
        regions_per_side: float = REGIONS_PER_OBJECT_SIDE,
    ) -> UnsupervisedParams:
        """These parameters at an object size of D = ``object_size`` px on an image of
        ``shape`` (H, W): superpixel area (D / ``regions_per_side``)² px within
        [:data:`MIN_OBJECT_REGION_AREA`, :data:`MAX_REGION_AREA`], and the diffusion's
        reach ``reach_objects`` · D px, as the share of the image side √(H·W) that
        ``diffusion_range`` is (at most 1)."""
        side = max(float(object_size), 1.0) / regions_per_side
        area = int(round(min(max(side * side, MIN_OBJECT_REGION_AREA), MAX_REGION_AREA)))
        reach = min(reach_objects * float(object_size) / math.sqrt(shape[0] * shape[1]), 1.0)
        return self.replace(region_area=area, diffusion_range=reach)

    def _check_edges(self) -> None:
        """``polarisation_edge_weight`` >= 0; ``border_intensity_weight`` in [0, 1] and
        ``border_gate`` >= 0, each away from its neutral value only on the polarisation
        edges."""
        if not (
            math.isfinite(self.polarisation_edge_weight) and self.polarisation_edge_weight >= 0
        ):
            raise PolarsegError(
                f"polarisation_edge_weight must be >= 0, got {self.polarisation_edge_weight}"
            )
        if not 0.0 <= self.border_intensity_weight <= 1.0:
            raise PolarsegError(
                f"border_intensity_weight must be in [0, 1], got {self.border_intensity_weight}"
            )
        if self.border_intensity_weight < 1.0 and self.boundary != "polarisation":
            raise PolarsegError("border_intensity_weight < 1 needs boundary='polarisation'")
        if not (math.isfinite(self.border_gate) and self.border_gate >= 0.0):
            raise PolarsegError(f"border_gate must be >= 0, got {self.border_gate}")
        if self.border_gate > 0.0 and self.boundary != "polarisation":
            raise PolarsegError("border_gate > 0 needs boundary='polarisation'")
        object.__setattr__(self, "border_gate", float(self.border_gate))
        object.__setattr__(self, "border_intensity_weight", float(self.border_intensity_weight))

    def _check_texture(self) -> None:
        """Check and normalise ``texture`` and ``texture_weight``."""
        texture = tuple(str(f) for f in self.texture)
        if any(f not in TEXTURE_FEATURES for f in texture):
            raise PolarsegError(
                f"texture must be some of {', '.join(TEXTURE_FEATURES)}; got {self.texture!r}"
            )
        if not (math.isfinite(self.texture_weight) and self.texture_weight >= 0):
            raise PolarsegError(f"texture_weight must be >= 0, got {self.texture_weight}")
        object.__setattr__(self, "texture", texture)

    def close_up_params(self) -> UnsupervisedParams:
        """The parameters used on a close-up of one smooth surface
        (:mod:`.shape_trend`): the departure of the polarisation from the surface's
        trend alone (:data:`CLOSE_UP_FEATURES`), not diffused (the ratio is already a
        kernel average), not winsorised, no border refinement on (log Î, ρ), which
        follow the tilt there, not the material. Measured in
        ``benchmarks/evaluate_unsupervised.py`` (variants ``close-up-*``)."""
        return self.replace(
            features=CLOSE_UP_FEATURES,
            texture=(),
            pixel_scales=(),
            diffusion=0.0,
            clip=0.0,
            refine_boundaries=False,
            close_up_share=1.0,
        )

    def replace(self, **changes: Any) -> UnsupervisedParams:
        """A copy with some attributes changed (validated again)."""
        return UnsupervisedParams(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (lists for tuples)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


@dataclass(frozen=True)
class UnsupervisedResult:
    """What :func:`segment_unsupervised` returns.

    Attributes
    ----------
    labels : ndarray (H, W) int32
        Segment of every pixel (its superpixel's), 0 … k' − 1 in order of first
        appearance (row-major).
    node_labels : ndarray (n,) int32
        Segment of every superpixel.
    regions : ndarray (H, W) int32
        Superpixel of every pixel, 0 … n − 1.
    node_features : ndarray (n, c) float64
        The PCA components the clustering saw.
    feature_names : tuple of str
        Names of the node features before the PCA.
    seconds : float
        Wall time of the whole segmentation.
    degenerate : bool
        One segment holds ≥ 95 % of the pixels (:func:`.degenerate.degenerate_result`).
    params : UnsupervisedParams
    surface_share : float
        Share of the superpixels' complex polarisation explained by one smooth surface's
        trend (:func:`.shape_trend.surface_trend_share`).
    close_up : bool
        The share was above ``params.close_up_share``: segmented with
        ``params.close_up_params()``.
    """

    labels: np.ndarray
    node_labels: np.ndarray
    regions: np.ndarray
    node_features: np.ndarray
    feature_names: tuple[str, ...]
    seconds: float
    degenerate: bool
    params: UnsupervisedParams
    surface_share: float = 0.0
    close_up: bool = False
