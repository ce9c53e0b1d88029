"""Headless engine of napari-polarseg: plain functions on arrays, no napari or Qt.

Stages (thesis section 4.5): :func:`polarisation_image` → :func:`zenith_from_dop` /
:func:`azimuth_from_phase` → :func:`block_coefficients` → :func:`pca_features` →
:func:`affinity_matrix` → :func:`recursive_ncut` → :func:`upsample_block_labels`, and
:func:`reconstruct_intensity`. :class:`Pipeline` chains them with a per-stage cache.
Angles are radians throughout the engine.

Beside the cut: :func:`pixel_features` (multi-scale per-pixel features) →
:func:`train_pixel_classifier` on scribbles → :func:`predict_pixels`, chained on a
pipeline's polarisation image by :class:`PixelSegmenter`.
"""

from .colour_mosaic import demosaic_colour, luminance
from .errors import Cancelled, PolarsegError
from .features import PCAResult, affinity_matrix, mahalanobis_sq, pca_features, whiten
from .fresnel import (
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
from .harmonics import (
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
from .limits import check_pipeline_memory, estimate_pipeline_bytes
from .mosaic import demosaic, demosaic_interpolated, demosaic_superpixel, subtract_dark
from .ncut import CutTree, best_split, bipartition, fiedler_vector, recursive_ncut
from .params import SegmentParams
from .pipeline import Pipeline, intensity_baseline, segment
from .pixel_classifier import (
    ClassifierParams,
    PixelClassifier,
    PixelPrediction,
    predict_pixels,
    train_pixel_classifier,
)
from .pixel_features import FeatureStack, PixelFeatureParams, pixel_features
from .pixel_segmentation import PixelSegmentation, PixelSegmenter
from .polarimage import (
    PixelMask,
    PolarisationImage,
    average_duplicate_angles,
    distinct_angle_count,
    polarisation_image,
    validity_mask,
)
from .registration import register_stack
from .result import SegmentationResult
from .stages import STAGES, valid_blocks
from .superpixels import region_means, superpixels
from .sweep import SweepCell, SweepResult  # the function: engine.sweep.sweep

__all__ = [
    "STAGES",
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
