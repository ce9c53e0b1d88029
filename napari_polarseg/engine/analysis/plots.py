"""Data of the analyst's plots (thesis figures 4.1, 5.2/5.11, 5.4/5.13, 5.17, table 5.1).

Plain arrays only: no matplotlib here (see :mod:`napari_polarseg.outputs.figures` for the figures
and :mod:`napari_polarseg.widgets.plots` for the napari dock widget).

- :func:`scatter_data` — a sample of (Î, ρ, φ) per pixel with its segment (figure 4.1);
- :func:`explained_variance` — PCA share per component and cumulative;
- :func:`coefficient_maps` — chosen a_lm over the block grid (figures 5.2/5.11);
- :func:`component_maps` — first principal components over the block grid and at pixel
  resolution (figures 5.4/5.13);
- :func:`reconstruction_histograms` — histograms of Î and of its reconstructions at
  several degrees on shared bins over a robust range (figure 5.17), optionally of a
  sample of blocks (:func:`sample_blocks`);
- :func:`reconstruction_error_table` — mean |Î rebuilt − Î| per window and degree
  (table 5.1);
- :func:`feature_importances` — the largest feature importances of a trained pixel
  classifier.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import PolarsegError
from ..features import harmonics

if TYPE_CHECKING:
    from ..result import SegmentationResult

#: Default (l, m) pairs of :func:`coefficient_maps` (thesis figures 5.2/5.11).
DEFAULT_PAIRS: tuple[tuple[int, int], ...] = ((0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2))


@dataclass
class ScatterData:
    """Sampled pixels: their row, column, Î, ρ, φ (radians) and segment label."""

    rows: np.ndarray
    cols: np.ndarray
    intensity: np.ndarray
    dop: np.ndarray
    phase: np.ndarray
    labels: np.ndarray
    n_pixels: int

    def __len__(self) -> int:
        return int(self.rows.size)


@dataclass
class ExplainedVariance:
    """Share of the variance of each kept principal component, and the running sum."""

    ratio: np.ndarray
    cumulative: np.ndarray


@dataclass
class FeatureImportances:
    """The ``top`` largest importances of a pixel classifier, largest first.

    ``names`` and ``values`` of the shown features; ``n_features`` the classifier's
    number of features and ``shown_share`` the sum of the shown values (importances of
    a forest sum to 1 over all features).
    """

    names: list[str]
    values: np.ndarray
    n_features: int
    shown_share: float


@dataclass
class CoefficientMaps:
    """``maps[k]`` is a_lm with (l, m) = ``pairs[k]`` over the (H // w, W // w) block grid."""

    pairs: list[tuple[int, int]]
    maps: np.ndarray


@dataclass
class ComponentMaps:
    """First principal components: ``blocks`` (n, H // w, W // w), ``pixels`` (n, H, W)."""

    blocks: np.ndarray
    pixels: np.ndarray
    explained: np.ndarray


@dataclass
class ReconstructionHistograms:
    """Histograms of Î and of its reconstruction at each degree, on the same ``edges``.

    The edges span the union of the curves' :func:`robust_range`:
    ``outside_original`` and ``outside[L]`` count the pixels beyond it, so the counts of
    a curve plus its outside count are ``n_pixels``, the pixels counted (all the used
    pixels, or those of ``sampled_blocks`` random blocks).
    """

    edges: np.ndarray
    original: np.ndarray
    reconstructed: dict[int, np.ndarray]
    mean_error: dict[int, float]
    window: int
    outside_original: int = 0
    outside: dict[int, int] = field(default_factory=dict)
    n_pixels: int = 0
    sampled_blocks: int | None = None

    @property
    def centres(self) -> np.ndarray:
        return 0.5 * (self.edges[:-1] + self.edges[1:])

    def l1_distance(self, degree: int) -> int:
        """Σ |counts of the degree-L reconstruction − counts of Î| over the bins."""
        return int(np.abs(self.reconstructed[degree] - self.original).sum())


@dataclass
class ErrorTable:
    """``errors[i, j]`` = mean |Î rebuilt − Î| for window ``windows[i]``, degree ``degrees[j]``."""

    windows: list[int]
    degrees: list[int]
    errors: np.ndarray


def _used(result: SegmentationResult) -> np.ndarray:
    used = np.isfinite(result.intensity) & np.isfinite(result.dop) & np.isfinite(result.phase)
    if result.valid is not None:
        used &= np.asarray(result.valid, dtype=bool)
    return used


def scatter_data(
    result: SegmentationResult,
    max_points: int = 20000,
    seed: int = 0,
    labels: np.ndarray | None = None,
) -> ScatterData:
    """At most ``max_points`` used pixels (uniform sample without replacement, in
    row-major order) with Î, ρ, φ and their label (``result.labels`` or ``labels``, an
    (H, W) array such as a ground truth), for Î against ρ and against φ (figure 4.1)."""
    if max_points < 1:
        raise PolarsegError(f"max_points must be >= 1, got {max_points}")
    lab = result.labels if labels is None else np.asarray(labels)
    if lab.shape != result.intensity.shape:
        raise PolarsegError(
            f"the labels are {lab.shape} but the result is {result.intensity.shape}"
        )
    flat = np.flatnonzero(_used(result))
    if flat.size > max_points:
        rng = np.random.default_rng(seed)
        flat = np.sort(rng.choice(flat, size=max_points, replace=False))
    rows, cols = np.unravel_index(flat, result.intensity.shape)
    return ScatterData(
        rows=rows,
        cols=cols,
        intensity=np.asarray(result.intensity)[rows, cols],
        dop=np.asarray(result.dop)[rows, cols],
        phase=np.asarray(result.phase)[rows, cols],
        labels=lab[rows, cols],
        n_pixels=int(result.intensity.size),
    )


def explained_variance(result: SegmentationResult) -> ExplainedVariance:
    """Per-component explained-variance share of the kept PCA components and its cumsum."""
    ratio = np.asarray(result.explained_variance_ratio, dtype=float).ravel()
    return ExplainedVariance(ratio=ratio.copy(), cumulative=np.cumsum(ratio))


def feature_importances(importances: dict[str, float], top: int = 15) -> FeatureImportances:
    """The ``top`` largest of ``importances`` (feature name → importance, e.g.
    :meth:`PixelClassifier.importances
    <napari_polarseg.engine.classifier.pixel_classifier.PixelClassifier.importances>`), largest
    first; ties keep the given order. Empty for a model without importances."""
    if top < 1:
        raise PolarsegError(f"top must be >= 1, got {top}")
    items = sorted(importances.items(), key=lambda kv: -kv[1])[:top]
    values = np.asarray([v for _, v in items], dtype=float)
    return FeatureImportances(
        names=[k for k, _ in items],
        values=values,
        n_features=len(importances),
        shown_share=float(values.sum()),
    )


def coefficient_maps(
    result: SegmentationResult, pairs: Iterable[tuple[int, int]] = DEFAULT_PAIRS
) -> CoefficientMaps:
    """Block-grid maps of the chosen a_lm (index l² + l + m of the coefficient vector)."""
    coef = np.asarray(result.coefficients)
    degree = int(round(np.sqrt(coef.shape[-1]))) - 1
    pairs = [(int(l), int(m)) for l, m in pairs]  # noqa: E741
    if not pairs:
        raise PolarsegError("give at least one (l, m) pair")
    index = []
    for l, m in pairs:  # noqa: E741
        if l > degree:
            raise PolarsegError(f"a_{l}{m} is above the result's degree L = {degree}")
        index.append(harmonics.coefficient_index(l, m))
    return CoefficientMaps(pairs=pairs, maps=np.moveaxis(coef[..., index], -1, 0).copy())


def component_maps(result: SegmentationResult, n: int = 3) -> ComponentMaps:
    """The first ``n`` principal components (fewer if the PCA kept fewer) over the block
    grid and upsampled to every pixel (remainder strips take the nearest block's)."""
    if n < 1:
        raise PolarsegError(f"n must be >= 1, got {n}")
    grid = result.block_labels.shape
    features = np.asarray(result.features)
    k = min(int(n), features.shape[1])
    blocks = features[:, :k].T.reshape(k, *grid)
    shape = result.intensity.shape
    rows, cols = harmonics.pixel_block_index(shape, result.params.window)
    pixels = blocks[:, rows[:, None], cols[None, :]]
    ratio = np.asarray(result.explained_variance_ratio, dtype=float)[:k]
    return ComponentMaps(blocks=blocks, pixels=pixels, explained=ratio)


def _reconstruct(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    ridge: float,
    weights: np.ndarray | None,
) -> np.ndarray:
    if not 0 <= int(degree):
        raise PolarsegError(f"degree must be >= 0, got {degree}")
    harmonics.block_grid(np.shape(intensity), int(window))  # validates w vs image
    return harmonics.reconstruct_intensity(
        intensity, zenith, azimuth, int(window), int(degree), ridge=ridge, weights=weights
    )


def sample_blocks(
    arrays: Sequence[np.ndarray | None], window: int, max_blocks: int, seed: int = 0
) -> tuple[list[np.ndarray | None], int | None]:
    """At most ``max_blocks`` random whole w × w blocks of each (H, W) array (None stays
    None), laid side by side in one (w, k·w) strip, and k (None when every block is kept
    and the arrays are returned as they are). The blocks are the same in every array and
    in block order; a block fit (:mod:`.harmonics`) sees each one as in the full image.
    Remainder strips (beyond the last whole block) are never sampled."""
    if max_blocks < 1:
        raise PolarsegError(f"max_blocks must be >= 1, got {max_blocks}")
    first = next(a for a in arrays if a is not None)
    nby, nbx = harmonics.block_grid(np.shape(first), int(window))
    if nby * nbx <= max_blocks:
        return list(arrays), None
    pick = np.sort(np.random.default_rng(seed).choice(nby * nbx, max_blocks, replace=False))
    offsets = np.arange(window)
    rows = (pick // nbx)[:, None] * window + offsets  # (k, w) pixel rows of each block
    cols = (pick % nbx)[:, None] * window + offsets
    out: list[np.ndarray | None] = []
    for a in arrays:
        if a is None:
            out.append(None)
            continue
        blocks = np.asarray(a)[rows[:, :, None], cols[:, None, :]]  # (k, w, w)
        out.append(blocks.transpose(1, 0, 2).reshape(window, max_blocks * window))
    return out, int(max_blocks)


#: Percentiles of each curve's values (Î and every reconstruction) whose union bounds the
#: bins of :func:`reconstruction_histograms`: a degree-20 fit overshoots by orders of
#: magnitude at a few pixels of a real frame, and bins spanning every value (−40,000 …
#: 80,000 on the fruits frame) squeezed all four curves into a few bins.
HISTOGRAM_PERCENTILES = (0.5, 99.5)


def robust_range(values: np.ndarray) -> tuple[float, float]:
    """The :data:`HISTOGRAM_PERCENTILES` of the finite ``values`` ((0, 1) if none)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return 0.0, 1.0
    lo, hi = np.percentile(values, HISTOGRAM_PERCENTILES)
    return float(lo), float(hi)


def reconstruction_histograms(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degrees: Sequence[int] = (4, 12, 20),
    bins: int = 64,
    ridge: float = 1e-3,
    weights: np.ndarray | None = None,
    max_blocks: int | None = None,
    seed: int = 0,
) -> ReconstructionHistograms:
    """Histogram of Î and of its block-harmonic reconstruction at each degree (figure
    5.17), all on the same ``bins`` equal bins over the union of the curves'
    :func:`robust_range` (the pixels beyond are counted apart). Only the pixels of
    ``weights`` (bool, True = used) are counted when given. With ``max_blocks``, only
    that many random blocks (:func:`sample_blocks`, ``seed``) are reconstructed and
    counted: the time no longer grows with the image (the mean errors are then those of
    the sample)."""
    intensity = np.asarray(intensity, dtype=float)
    sampled = None
    if max_blocks is not None:
        (intensity, zenith, azimuth, weights), sampled = sample_blocks(
            [intensity, np.asarray(zenith), np.asarray(azimuth), weights],
            int(window),
            int(max_blocks),
            seed,
        )
        assert intensity is not None and zenith is not None and azimuth is not None
    used = np.isfinite(intensity) if weights is None else np.asarray(weights, dtype=bool)
    recs = {
        int(d): _reconstruct(intensity, zenith, azimuth, window, d, ridge, weights) for d in degrees
    }
    values = [intensity[used]] + [r[used] for r in recs.values()]
    ranges = np.array([robust_range(v) for v in values])
    lo, hi = float(ranges[:, 0].min()), float(ranges[:, 1].max())
    if not hi > lo:
        hi = lo + 1.0
    edges = np.linspace(lo, hi, int(bins) + 1)
    counts = [np.histogram(v, edges)[0] for v in values]
    outside = [int(v.size - c.sum()) for v, c in zip(values, counts, strict=True)]
    return ReconstructionHistograms(
        edges=edges,
        original=counts[0],
        reconstructed=dict(zip(recs, counts[1:], strict=True)),
        mean_error={d: float(np.mean(np.abs(r - intensity)[used])) for d, r in recs.items()},
        window=int(window),
        outside_original=outside[0],
        outside=dict(zip(recs, outside[1:], strict=True)),
        n_pixels=int(values[0].size),
        sampled_blocks=sampled,
    )


def reconstruction_error_table(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    windows: Sequence[int],
    degrees: Sequence[int],
    ridge: float = 1e-3,
    weights: np.ndarray | None = None,
) -> ErrorTable:
    """Mean |Î rebuilt − Î| for every window w and degree L (thesis table 5.1)."""
    intensity = np.asarray(intensity, dtype=float)
    used = np.isfinite(intensity) if weights is None else np.asarray(weights, dtype=bool)
    windows, degrees = [int(w) for w in windows], [int(d) for d in degrees]
    errors = np.empty((len(windows), len(degrees)))
    for i, w in enumerate(windows):
        for j, d in enumerate(degrees):
            rec = _reconstruct(intensity, zenith, azimuth, w, d, ridge, weights)
            errors[i, j] = np.mean(np.abs(rec - intensity)[used])
    return ErrorTable(windows=windows, degrees=degrees, errors=errors)


def result_histograms(
    result: SegmentationResult,
    degrees: Sequence[int] = (4, 12, 20),
    bins: int = 64,
    max_blocks: int | None = None,
) -> ReconstructionHistograms:
    """:func:`reconstruction_histograms` with the result's Î, θ, azimuth, w and ridge
    (of at most ``max_blocks`` random blocks when given)."""
    return reconstruction_histograms(
        result.intensity,
        result.zenith,
        result.azimuth,
        result.params.window,
        degrees,
        bins=bins,
        ridge=result.params.ridge,
        weights=_weights(result),
        max_blocks=max_blocks,
    )


def result_error_table(
    result: SegmentationResult, windows: Sequence[int], degrees: Sequence[int]
) -> ErrorTable:
    """:func:`reconstruction_error_table` with the result's Î, θ, azimuth and ridge."""
    return reconstruction_error_table(
        result.intensity,
        result.zenith,
        result.azimuth,
        windows,
        degrees,
        ridge=result.params.ridge,
        weights=_weights(result),
    )


def _weights(result: SegmentationResult) -> np.ndarray | None:
    if result.valid is None or np.asarray(result.valid).all():
        return None
    return np.asarray(result.valid, dtype=bool)
