"""Per-region (superpixel) features of the unsupervised segmentation, from region sums
of per-pixel maps.

:func:`pixel_terms` makes the per-pixel maps (they do not depend on the regions);
:func:`node_features` sums them over the regions (one ``np.bincount`` each) and derives
each feature of :data:`~.params.NODE_FEATURES`; :func:`dop_given_intensity` is the
image-wide ρ–shading cue.
"""

from __future__ import annotations

import numpy as np

from ..features.pixel_features import EPS_DOP, EPS_INTENSITY
from .params import NODE_FEATURES, TREND
from .shape_trend import polarisation_over_trend, region_centroids
from .texture import given_intensity, grain_maps, reads_grain, texture_features

#: Degree of the image-wide polynomial of :func:`dop_given_intensity`.
RESIDUAL_DEGREE = 3


def _region_sums(flat: np.ndarray, n: int, maps: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: np.bincount(flat, weights=v.ravel(), minlength=n) for k, v in maps.items()}


def pixel_terms(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    centre: float | None = None,
    texture: bool = False,
) -> dict[str, np.ndarray]:
    """The per-pixel maps whose region sums give :func:`node_features` (float64): Î, S1,
    S2, log Î (centred on its median, or on ``centre``: the same constant for every
    tile of one image), (log Î)², ρ, ρ², ρ log Î, cos 2φ and sin 2φ; with ``texture``
    also the grain maps of :func:`.texture.grain_maps` (float32).

    They do not depend on the regions, so :func:`~.pixel_maps.pixel_maps` computes them
    while the superpixels' edge map is drawn, once for every superpixel size.
    """
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY)).astype(np.float64)
    log_i -= np.median(log_i) if centre is None else centre
    d = dop.astype(np.float64)
    c, s = np.cos(2 * phase.astype(np.float64)), np.sin(2 * phase.astype(np.float64))
    grain = grain_maps(log_i, d, c, s) if texture else {}
    return {
        **grain,
        "s0": intensity.astype(np.float64),
        "s1": intensity * d * c,
        "s2": intensity * d * s,
        "l": log_i,
        "ll": log_i * log_i,
        "d": d,
        "dd": d * d,
        "ld": log_i * d,
        "c": c,
        "s": s,
    }


def node_features(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    regions: np.ndarray,
    names: tuple[str, ...] = NODE_FEATURES,
    trend: tuple[int, float, int] = TREND,
    terms: dict[str, np.ndarray] | None = None,
) -> np.ndarray:
    """Per-region features (n, len(names)) float64, each of :data:`NODE_FEATURES`;
    ``trend`` = (degree, reach, iterations) of ``dop_over_shape_trend``
    (:func:`.shape_trend.polarisation_over_trend`).

    Computed from region sums of Î, S1, S2, log Î, (log Î)², ρ, ρ², ρ log Î, cos 2φ and
    sin 2φ (one ``np.bincount`` each; the maps: :func:`pixel_terms`, or ``terms`` when
    already made); variances and covariances are differences of means of log Î centred
    on its median.
    """
    flat = regions.ravel()
    n = int(flat.max()) + 1
    count = np.maximum(np.bincount(flat, minlength=n), 1).astype(float)
    if terms is None:
        terms = pixel_terms(intensity, dop, phase, texture=reads_grain(names))
    sums = _region_sums(flat, n, terms)
    centroid = region_centroids(regions, count) if "dop_over_shape_trend" in names else None
    return features_of_sums(sums, count, names, trend, centroid, regions.shape)


def features_of_sums(
    sums: dict[str, np.ndarray],
    count: np.ndarray,
    names: tuple[str, ...] = NODE_FEATURES,
    trend: tuple[int, float, int] = TREND,
    centroid: np.ndarray | None = None,
    shape: tuple[int, int] = (1, 1),
) -> np.ndarray:
    """The features of :func:`node_features` (n, len(names)) from the region sums of the
    :func:`pixel_terms` (each (n,), keyed as they are) and the regions' pixel counts
    ``count`` (n,), at least 1; ``centroid`` (n, 2, pixels) and the frame's ``shape``
    (H, W) are read by ``dop_over_shape_trend`` alone, the sums of the grain maps by the
    texture features (:func:`.texture.texture_features`). Whatever adds the sums up (one
    image, or its tiles one after the other) gives the same features."""
    m = {k: v / count for k, v in sums.items()}
    var_l = np.maximum(m["ll"] - m["l"] ** 2, 0)
    var_d = np.maximum(m["dd"] - m["d"] ** 2, 0)
    cov = m["ld"] - m["l"] * m["d"]
    dolp = np.hypot(sums["s1"], sums["s2"]) / np.maximum(sums["s0"], EPS_INTENSITY)
    make = {
        "log_intensity": lambda: m["l"],
        "intensity_spread": lambda: np.sqrt(var_l),
        "dop": lambda: m["d"],
        "dop_spread": lambda: np.sqrt(var_d),
        "dolp": lambda: dolp,
        "aolp_coherence": lambda: np.hypot(m["c"], m["s"]),
        "dolp_over_dop": lambda: dolp / (m["d"] + EPS_DOP),
        "dop_vs_log_intensity_slope": lambda: cov / (var_l + 1e-6),
        "dop_vs_log_intensity_corr": lambda: cov / np.sqrt(var_l * var_d + 1e-12),
        "log_dop_given_intensity": lambda: dop_given_intensity(m["l"], m["d"], count),
        "dop_over_shape_trend": lambda: _over_trend(sums, count, centroid, shape, trend),
    }
    texture = texture_features(m, count, names)
    return np.stack([texture[k] if k in texture else make[k]() for k in names], axis=1)


def _over_trend(
    sums: dict[str, np.ndarray],
    count: np.ndarray,
    centroid: np.ndarray | None,
    shape: tuple[int, int],
    trend: tuple,
) -> np.ndarray:
    """:func:`.shape_trend.polarisation_over_trend` from the region sums; ``trend`` =
    (degree, reach, iterations)."""
    if centroid is None:
        raise ValueError("dop_over_shape_trend needs the regions' centroids")
    z = (sums["s1"] + 1j * sums["s2"]) / np.maximum(sums["s0"], EPS_INTENSITY)
    return polarisation_over_trend(z, count, centroid, shape, *trend)


def dop_given_intensity(
    log_intensity: np.ndarray, dop: np.ndarray, weight: np.ndarray, degree: int = RESIDUAL_DEGREE
) -> np.ndarray:
    """log ρ̄ − f(log Î), f the polynomial of ``degree`` fitted over all regions
    (least squares weighted by ``weight``, the regions' areas): the material cue taken
    image-wide. Where one material covers most of the image, f is its ρ–shading
    relation, and a region of another material (other n, other depolarisation) lies off
    it at whatever tilt; ρ̄ and log Î are the regions' means.
    """
    return given_intensity(np.log(dop + EPS_DOP), log_intensity, weight, degree)
