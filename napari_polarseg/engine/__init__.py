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
pipeline's polarisation image by :class:`PixelSegmenter`; :class:`ScribbleSession` is
the interactive loop (features kept, each update retrains and predicts coarse to fine).
"""

from __future__ import annotations

# the registry (light: no method module) hands over its loader, so the first read of
# the choices of SegmentParams.method (--method, the plugin's menu) or the first lookup
# of a method registers the built-in ones
from . import methods as methods
from .errors import Cancelled, PolarsegError
from .lazy import lazy_attributes
from .params import SegmentParams

#: Every public name of the engine and the module that defines it; imported on first use
#: (PEP 562, as scikit-image does), so ``import napari_polarseg.engine`` stays light.
PUBLIC: dict[str, str] = {
    # classifier.pixel_classifier
    "ClassifierParams": ".classifier.pixel_classifier",
    "PixelClassifier": ".classifier.pixel_classifier",
    "PixelPrediction": ".classifier.pixel_classifier",
    "predict_pixels": ".classifier.pixel_classifier",
    "train_pixel_classifier": ".classifier.pixel_classifier",
    # classifier.scribble_session
    "PredictionParams": ".classifier.scribble_session",
    "ScribbleSession": ".classifier.scribble_session",
    # classifier.pixel_segmentation
    "PixelSegmentation": ".classifier.pixel_segmentation",
    "PixelSegmenter": ".classifier.pixel_segmentation",
    # errors
    "Cancelled": ".errors",
    "ClassifierInputError": ".errors",
    "PolarsegError": ".errors",
    # features.harmonics
    "block_coefficients": ".features.harmonics",
    "block_grid": ".features.harmonics",
    "coefficient_index": ".features.harmonics",
    "degree_order": ".features.harmonics",
    "n_coefficients": ".features.harmonics",
    "pixel_block_index": ".features.harmonics",
    "real_sph_harm": ".features.harmonics",
    "reconstruct_intensity": ".features.harmonics",
    "upsample_block_labels": ".features.harmonics",
    # features.pca
    "PCAResult": ".features.pca",
    "mahalanobis_sq": ".features.pca",
    "pca_features": ".features.pca",
    "whiten": ".features.pca",
    # features.pixel_features
    "FeatureStack": ".features.pixel_features",
    "PixelFeatureParams": ".features.pixel_features",
    "pixel_features": ".features.pixel_features",
    # features.superpixels
    "region_means": ".features.superpixels",
    "superpixels": ".features.superpixels",
    # graph.affinity
    "affinity_matrix": ".graph.affinity",
    # graph.eigensolver
    "fiedler_vector": ".graph.eigensolver",
    # graph.ncut
    "CutTree": ".graph.ncut",
    "best_split": ".graph.ncut",
    "bipartition": ".graph.ncut",
    "recursive_ncut": ".graph.ncut",
    # limits
    "check_pipeline_memory": ".run_memory",
    "estimate_pipeline_bytes": ".run_memory",
    # methods
    "MethodOutput": ".methods",
    "Scene": ".methods.scene",
    "Segmenter": ".methods",
    "get_method": ".methods",
    "method_names": ".methods",
    "register_method": ".methods",
    "segment": ".methods.scene",
    # params
    "PRESETS": ".presets",
    "SegmentParams": ".params",
    # physics.colour_mosaic
    "demosaic_colour": ".physics.colour_mosaic",
    "luminance": ".physics.colour_mosaic",
    # physics.fresnel
    "ZenithEstimate": ".physics.fresnel",
    "azimuth_from_phase": ".physics.fresnel",
    "brewster_angle": ".physics.fresnel",
    "diffuse_dop": ".physics.fresnel",
    "diffuse_dop_ceiling": ".physics.fresnel",
    "diffuse_dop_fresnel": ".physics.fresnel",
    "fresnel_reflectance": ".physics.fresnel",
    "specular_dop": ".physics.fresnel",
    "specular_dop_fresnel": ".physics.fresnel",
    "zenith_from_diffuse_dop": ".physics.fresnel",
    "zenith_from_dop": ".physics.fresnel",
    "zenith_from_specular_dop": ".physics.fresnel",
    # physics.mosaic
    "demosaic": ".physics.mosaic",
    "demosaic_interpolated": ".physics.mosaic",
    "demosaic_superpixel": ".physics.mosaic",
    "subtract_dark": ".physics.mosaic",
    # physics.pixel_mask
    "PixelMask": ".physics.pixel_mask",
    # physics.polarimage
    "PolarisationImage": ".physics.polarimage",
    "average_duplicate_angles": ".physics.polarimage",
    "distinct_angle_count": ".physics.polarimage",
    "polarisation_image": ".physics.polarimage",
    "validity_mask": ".physics.pixel_mask",
    # physics.registration
    "register_stack": ".physics.registration",
    # pipeline
    "Pipeline": ".pipeline",
    "intensity_baseline": ".pipeline",
    # result
    "SegmentationResult": ".result",
    # stages
    "STAGES": ".stages",
    "valid_blocks": ".stages",
    # unsupervised.params
    "UnsupervisedParams": ".unsupervised.params",
    # unsupervised.segmenter
    "segment_unsupervised": ".unsupervised.segmenter",
}

#: The names most scripts need (``from napari_polarseg.engine import *``); every name of
#: :data:`PUBLIC` is importable.
__all__ = [
    "Scene",
    "PRESETS",
    "SegmentParams",
    "SegmentationResult",
    "segment",
    "segment_unsupervised",
    "UnsupervisedParams",
    "Pipeline",
    "PixelSegmenter",
    "ScribbleSession",
    "ClassifierParams",
    "PixelClassifier",
    "train_pixel_classifier",
    "predict_pixels",
    "pixel_features",
    "PixelFeatureParams",
    "register_method",
    "method_names",
    "get_method",
    "Segmenter",
    "MethodOutput",
    "polarisation_image",
    "zenith_from_dop",
    "PixelMask",
    "validity_mask",
    "Cancelled",
    "PolarsegError",
]


__getattr__, __dir__ = lazy_attributes(__name__, PUBLIC)
