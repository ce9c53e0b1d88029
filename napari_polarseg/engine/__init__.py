"""Headless engine of napari-polarseg: plain functions on arrays, no napari or Qt.

Stages (thesis section 4.5): :func:`polarisation_image` → :func:`zenith_from_dop` /
:func:`azimuth_from_phase` → :func:`block_coefficients` → :func:`pca_features` →
:func:`affinity_matrix` → :func:`recursive_ncut` → :func:`upsample_block_labels`, and
:func:`reconstruct_intensity`. :class:`Pipeline` chains them with a per-stage cache.

Methods are peers (:mod:`.methods`): :class:`Scene` segments a stack with the method
``SegmentParams.method`` names (``PRESETS["auto"]``: the superpixel clustering
:func:`segment_unsupervised`; ``"thesis"``: the block pipeline) or, given scribbles, with
the pixel classifier; :func:`register_method` adds one.
Angles are radians throughout the engine.

Beside the cut: :func:`pixel_features` (multi-scale per-pixel features) →
:func:`train_pixel_classifier` on scribbles → :func:`predict_pixels`, chained on a
pipeline's polarisation image by :class:`PixelSegmenter`.
"""

from .analysis.pixel_classifier import (
    ClassifierParams,
    PixelClassifier,
    PixelPrediction,
    predict_pixels,
    train_pixel_classifier,
)
from .analysis.pixel_segmentation import PixelSegmentation, PixelSegmenter
from .analysis.sweep_result import SweepCell, SweepResult  # sweep(): analysis.sweep.sweep
from .errors import Cancelled, PolarsegError
from .features.harmonics import (
    block_coefficients,
    block_grid,
    coefficient_index,
    degree_order,
    n_coefficients,
    pixel_block_index,
    real_sph_harm,
    reconstruct_intensity,
    upsample_block_labels,
)
from .features.pca import PCAResult, mahalanobis_sq, pca_features, whiten
from .features.pixel_features import FeatureStack, PixelFeatureParams, pixel_features
from .features.superpixels import region_means, superpixels
from .graph.affinity import affinity_matrix
from .graph.eigensolver import fiedler_vector
from .graph.ncut import CutTree, best_split, bipartition, recursive_ncut
from .limits import check_pipeline_memory, estimate_pipeline_bytes
from .methods import (
    MethodOutput,
    Scene,
    Segmenter,
    get_method,
    method_names,
    register_method,
    segment,
)
from .params import PRESETS, SegmentParams
from .physics.colour_mosaic import demosaic_colour, luminance
from .physics.fresnel import (
    ZenithEstimate,
    azimuth_from_phase,
    brewster_angle,
    diffuse_dop,
    diffuse_dop_ceiling,
    diffuse_dop_fresnel,
    fresnel_reflectance,
    specular_dop,
    specular_dop_fresnel,
    zenith_from_diffuse_dop,
    zenith_from_dop,
    zenith_from_specular_dop,
)
from .physics.mosaic import demosaic, demosaic_interpolated, demosaic_superpixel, subtract_dark
from .physics.pixel_mask import PixelMask
from .physics.polarimage import (
    PolarisationImage,
    average_duplicate_angles,
    distinct_angle_count,
    polarisation_image,
    validity_mask,
)
from .physics.registration import register_stack
from .pipeline import Pipeline, intensity_baseline
from .result import SegmentationResult
from .stages import STAGES, valid_blocks
from .unsupervised.params import UnsupervisedParams
from .unsupervised.segmenter import segment_unsupervised

__all__ = [
    "PRESETS",
    "STAGES",
    "MethodOutput",
    "Scene",
    "Segmenter",
    "UnsupervisedParams",
    "get_method",
    "method_names",
    "register_method",
    "segment_unsupervised",
    "Cancelled",
    "ClassifierParams",
    "CutTree",
    "FeatureStack",
    "PCAResult",
    "PixelClassifier",
    "PixelFeatureParams",
    "PixelMask",
    "PixelPrediction",
    "PixelSegmentation",
    "PixelSegmenter",
    "Pipeline",
    "PolarisationImage",
    "PolarsegError",
    "SegmentParams",
    "SegmentationResult",
    "SweepCell",
    "SweepResult",
    "ZenithEstimate",
    "affinity_matrix",
    "average_duplicate_angles",
    "azimuth_from_phase",
    "best_split",
    "bipartition",
    "block_coefficients",
    "block_grid",
    "brewster_angle",
    "check_pipeline_memory",
    "demosaic",
    "demosaic_colour",
    "demosaic_interpolated",
    "demosaic_superpixel",
    "coefficient_index",
    "degree_order",
    "diffuse_dop",
    "diffuse_dop_ceiling",
    "diffuse_dop_fresnel",
    "distinct_angle_count",
    "estimate_pipeline_bytes",
    "fiedler_vector",
    "fresnel_reflectance",
    "intensity_baseline",
    "luminance",
    "mahalanobis_sq",
    "n_coefficients",
    "pca_features",
    "pixel_block_index",
    "pixel_features",
    "polarisation_image",
    "predict_pixels",
    "real_sph_harm",
    "register_stack",
    "reconstruct_intensity",
    "region_means",
    "recursive_ncut",
    "segment",
    "specular_dop",
    "specular_dop_fresnel",
    "subtract_dark",
    "superpixels",
    "train_pixel_classifier",
    "upsample_block_labels",
    "validity_mask",
    "whiten",
    "zenith_from_diffuse_dop",
    "zenith_from_dop",
    "zenith_from_specular_dop",
    "valid_blocks",
]
