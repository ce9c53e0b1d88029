"""``segments.csv``'s statistics of a large result, summed band by band of rows (issue 39).

:func:`banded_segment_statistics` gives the rows of
:func:`~napari_polarseg.engine.analysis.evaluation.segment_statistics` without its
full-size temporaries (the labels as int64, sin 2φ and cos 2φ, the masked maps: 3 GB at
100 MP): the sums per segment are accumulated :data:`~.bands.BAND_ROWS` rows at a time
with :func:`numpy.add.at`, which adds each pixel in turn as ``numpy.bincount`` does, so
every sum, and so every mean, is the same to the bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..engine.analysis.evaluation import segment_count, segment_pca_means, statistics_rows
from .bands import read_band, row_bands


def _band_maps(
    rows: slice, intensity: np.ndarray, dop: np.ndarray, zenith: np.ndarray, phase: np.ndarray
) -> list[np.ndarray]:
    """Flat float64 Î, ρ, θ, sin 2φ, cos 2φ of a band of rows."""
    bands = read_band(rows, np.float64, intensity, dop, zenith, phase)
    maps, phi = [band.ravel() for band in bands[:3]], bands[3].ravel()
    with np.errstate(invalid="ignore"):  # φ not finite: left out of the means
        maps += [np.sin(2 * phi), np.cos(2 * phi)]
    return maps


def _segment_sums(
    labels: np.ndarray, maps: tuple[np.ndarray, ...], valid: np.ndarray | None, k: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per segment (k): pixel counts, counts of the used pixels (every map finite and
    ``valid``) and the (5, k) sums of the band maps (:func:`_band_maps`) over them."""
    pixels = np.zeros(k, np.int64)
    total = np.zeros(k)
    sums = np.zeros((5, k))
    for rows in row_bands(labels.shape[0]):
        index = read_band(rows, None, labels)[0].ravel().astype(np.int64)
        values = _band_maps(rows, *maps)
        ok = np.ones(index.size, dtype=bool)
        for v in values:
            ok &= np.isfinite(v)
        if valid is not None:
            ok &= read_band(rows, bool, valid)[0].ravel()
        pixels += np.bincount(index, minlength=k)
        np.add.at(total, index, ok.astype(np.float64))
        for j, v in enumerate(values):
            np.add.at(sums[j], index, np.where(ok, v, 0.0))
    return pixels, total, sums


def banded_segment_statistics(
    labels: np.ndarray,
    intensity: np.ndarray,
    dop: np.ndarray,
    zenith: np.ndarray,
    phase: np.ndarray,
    *,
    valid: np.ndarray | None = None,
    block_labels: np.ndarray | None = None,
    features: np.ndarray | None = None,
    block_valid: np.ndarray | None = None,
) -> list[dict[str, Any]]:
    """:func:`~napari_polarseg.engine.analysis.evaluation.segment_statistics` (same
    arguments, same rows: Î in input units, ρ, θ and φ means in degrees) computed band by
    band of rows (module docstring)."""
    k = segment_count(labels, intensity, dop, zenith, phase)
    pixels, total, sums = _segment_sums(labels, (intensity, dop, zenith, phase), valid, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = [np.where(total > 0, s / np.where(total > 0, total, 1), np.nan) for s in sums]
    pca = segment_pca_means(k, block_labels, features, block_valid)
    return statistics_rows(pixels, int(np.prod(np.shape(labels))), means, pca)
