"""Superpixels: small regions of the image that follow its edges.

Square w × w blocks (thesis section 4.5) straddle material boundaries; superpixels do
not. :func:`polarisation_superpixels` grows compact watershed regions (as below) over
the summed gradient magnitudes of the smoothed log Î and Stokes components
s1 = S1/S0, s2 = S2/S0 (:func:`superpixel_edges`), so a region border sits on an
intensity *or* a polarisation edge: the regions of the pixel features, of the scribble
classifier's region walk and of the unsupervised methods. :func:`superpixels` grows
compact watershed regions (scikit-image ``watershed``
with ``compactness``, Neubert & Protzel 2014) from a regular grid of seeds over the
gradient magnitude of the smoothed log intensity, so region borders sit on intensity
edges. It is used instead of SLIC because it is several times faster on a camera frame
(``docs/performance.md``) and adheres as well to the edges of the real frames.
:func:`region_means` averages any per-pixel maps over the regions (vectorised with
``np.bincount``).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import scipy.sparse as sps
from skimage.segmentation import watershed

from ..errors import PolarsegError
from .gaussian import gradient_magnitude

#: Default mean region area, pixels (about 20 × 20).
REGION_AREA = 400
#: Compactness of the watershed (larger: more square regions, less edge-following).
COMPACTNESS = 1e-3
#: σ (pixels) of the smoothing before an edge map's gradient is taken.
EDGE_SIGMA = 1.5
#: Floor of Î before its logarithm (units of the input).
INTENSITY_FLOOR = 1e-6
#: Fewest cells of the coarser watershed grid a region must span (:func:`watershed_grid`).
MIN_GRID_CELLS = 64


def superpixels(
    intensity: np.ndarray, region_area: int = REGION_AREA, compactness: float = COMPACTNESS
) -> np.ndarray:
    """Label image (H, W) int32 of edge-following regions 0 … n − 1.

    Parameters
    ----------
    intensity : array (H, W)
        Î (units of the input); regions follow the edges of log Î.
    region_area : int
        Mean region size in pixels (seeds on a grid of that spacing²).
    compactness : float
        Watershed compactness (0 = plain watershed).
    """
    i = np.asarray(intensity, dtype=np.float32)
    if i.ndim != 2:
        raise PolarsegError(f"intensity must be a 2-D image, got shape {i.shape}")
    if int(region_area) < 4:
        raise PolarsegError(f"region_area must be at least 4 pixels, got {region_area}")
    log_i = np.log(np.maximum(np.where(np.isfinite(i), i, 0), INTENSITY_FLOOR))
    edges = gradient_magnitude(log_i, EDGE_SIGMA)
    n = max(1, int(round(i.size / region_area)))
    # (tried: the watershed on a 2x coarser grid, 4x faster, cost 0.01 ARI on the real
    # fruits frame; kept at full resolution)
    labels = watershed(edges, markers=n, compactness=compactness)
    labels = (labels - labels.min()).astype(np.int32)
    return np.ascontiguousarray(labels)


def edge_gradients(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, polarisation: bool = True
) -> tuple[np.ndarray, np.ndarray | None]:
    """The two gradient magnitudes of :func:`superpixel_edges` before they are scaled,
    (H, W) each, per pixel: |∇(G * log Î)| (Î in units of the input) and, when
    ``polarisation``, |∇(G * (s1, s2))| (dimensionless; else None)."""
    log_i = np.log(np.maximum(intensity, INTENSITY_FLOOR))
    grad = gradient_magnitude(log_i, EDGE_SIGMA)
    if not polarisation:
        return grad, None
    pol = np.hypot(
        gradient_magnitude(dop * np.cos(2 * phase), EDGE_SIGMA),
        gradient_magnitude(dop * np.sin(2 * phase), EDGE_SIGMA),
    )
    return grad, pol


def edge_terms(
    maps: tuple[np.ndarray, np.ndarray, np.ndarray],
    polarisation_edge_weight: float = 1.0,
    scales: tuple[float, float] | None = None,
) -> np.ndarray:
    """(C, H, W) float64, dimensionless: the terms of :func:`superpixel_edges` of
    ``maps`` (Î, ρ, φ) apart, |∇(G * log Î)| / m_log and, when w > 0,
    w · |∇(G * (s1, s2))| / m_s (C = 2; C = 1 when w = 0), so that one computation of
    the gradients serves the watershed (their sum) and borders that weigh the two
    differently (:func:`border_channels`)."""
    grad, pol = edge_gradients(*maps, polarisation_edge_weight > 0)
    out = np.empty((1 if pol is None else 2, *grad.shape))
    m_log = float(np.median(grad)) if scales is None else float(scales[0])
    np.divide(grad, max(m_log, 1e-12), out=out[0])
    if pol is not None:
        m_pol = float(np.median(pol)) if scales is None else float(scales[1])
        # w · pol / m (not pol · (w / m)): the sum rounds as the edge map always has
        np.divide(polarisation_edge_weight * pol, max(m_pol, 1e-12), out=out[1])
    return out


def superpixel_edges(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    polarisation_edge_weight: float = 1.0,
    scales: tuple[float, float] | None = None,
) -> np.ndarray:
    """Edge map (H, W), dimensionless: |∇(G * log Î)| / m_log + w · |∇(G * (s1, s2))| / m_s.

    s1 = ρ cos 2φ and s2 = ρ sin 2φ are the Stokes components normalised by S0, G a
    Gaussian of :data:`EDGE_SIGMA` px (:func:`edge_gradients`), each gradient divided by
    its median m over the image (so the two edge maps weigh alike whatever the units;
    ``scales`` = (m_log, m_s) when they are known, e.g. of a whole image cut into tiles)
    and w = ``polarisation_edge_weight`` (0: log Î alone): the sum of
    :func:`edge_terms`.
    """
    return edge_terms((intensity, dop, phase), polarisation_edge_weight, scales).sum(axis=0)


def border_channels(terms: np.ndarray, intensity_weight: float) -> np.ndarray:
    """(2, H, W) float32: the log Î and the Stokes edge maps of :func:`edge_terms`
    ``terms``, the log Î one weighed a = ``intensity_weight`` (a = 0: the Stokes edges
    alone, blind to a step of Î across which ρ and φ run on, such as a cast shadow's
    edge; the Stokes map zero where the terms hold the log Î one alone), for borders
    that weigh the two differently."""
    out = np.zeros((2, *terms.shape[1:]), dtype=np.float32)
    np.multiply(terms[0], intensity_weight, out=out[0], casting="same_kind")
    out[1 : len(terms)] = terms[1:]
    return out


def polarisation_superpixels(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    region_area: int,
    polarisation_edge_weight: float = 1.0,
    edges: np.ndarray | None = None,
    grid: int = 1,
) -> np.ndarray:
    """Superpixels (H, W) int32, 0 … n − 1, following intensity and polarisation edges.

    A compact watershed from a grid of ``H·W / region_area`` seeds over the edge map of
    :func:`superpixel_edges` (``edges``, computed when not given). ``grid`` > 1: the
    watershed runs on the ``grid`` × ``grid`` block means of the edge map (``grid``²
    times fewer pixels, the compactness scaled to the coarser pixels) and every pixel
    takes its block's region, so the borders are placed to ``grid`` pixels
    (:func:`watershed_grid` chooses it by the region area).
    """
    if edges is None:
        edges = superpixel_edges(intensity, dop, phase, polarisation_edge_weight)
    return relabel(watershed_on_grid(edges, seed_count(edges.shape, region_area), grid))


def seed_count(shape: tuple[int, int], region_area: int) -> int:
    """Watershed seeds of superpixels of ``region_area`` pixels on an image of ``shape``
    (H, W): H·W / ``region_area`` rounded, at least 2."""
    return max(2, int(round(shape[0] * shape[1] / region_area)))


def watershed_on_grid(edges: np.ndarray, markers: int | np.ndarray, grid: int = 1) -> np.ndarray:
    """Compact watershed (:data:`COMPACTNESS`) of ``edges`` (H, W) from ``markers``, label
    image (H, W): the markers' numbers, 1 … (scikit-image's ``watershed``).

    ``grid`` > 1: on the ``grid`` × ``grid`` block means of ``edges`` (blocks from the
    top-left pixel, the last row and column of blocks padded with the edge values; the
    compactness scaled to the coarser pixels), every pixel taking its block's label.
    ``markers``: a number n of seeds on scikit-image's regular grid of the image
    watershed on (the coarser one when ``grid`` > 1), or an (H, W) int array of seeds
    numbered ≥ 1 at full resolution, each moved to its block (so that a tile whose box
    starts on a multiple of ``grid`` gets the labels of the whole image's blocks).
    Written by hand around scikit-image: it has no block-wise watershed.
    """
    if grid == 1:
        return watershed(edges, markers=markers, compactness=COMPACTNESS)
    h, w = edges.shape
    hh, ww = -(-h // grid) * grid, -(-w // grid) * grid
    padded = np.pad(edges, ((0, hh - h), (0, ww - w)), mode="edge")
    coarse = padded.reshape(hh // grid, grid, ww // grid, grid).mean(axis=(1, 3))
    if not np.isscalar(markers):
        fine = np.asarray(markers)
        rows, cols = np.nonzero(fine)
        markers = np.zeros(coarse.shape, dtype=np.int32)
        markers[rows // grid, cols // grid] = fine[rows, cols]
    labels = watershed(coarse, markers=markers, compactness=COMPACTNESS * grid)
    return np.repeat(np.repeat(labels, grid, axis=0), grid, axis=1)[:h, :w]


def watershed_grid(region_area: int) -> int:
    """Coarsening of :func:`polarisation_superpixels`' watershed for regions of
    ``region_area`` pixels: the coarsest power of two g on whose grid a region still
    spans :data:`MIN_GRID_CELLS` cells (``region_area`` / g² ≥ 64): 1 under 256 px, 2
    up to 1023 px, 4 from 1024 px (the largest automatic area, images from 3.07 MP).

    Measured with the robot user: on the labelled camera frames the 2× coarser
    watershed of their 417 px regions needs as few corrections, at a quarter of the
    cost; on those frames upsampled to 5 and 11 MP (regions of 1024 px) the 4× coarser
    one scores level with the 2× and takes a fifth less time on a 100 MP image (67.6 s
    against 84.9 s; ``benchmarks/watershed_grid.py``, ``docs/performance.md``)."""
    g = 1
    while region_area >= (2 * g) ** 2 * MIN_GRID_CELLS:
        g *= 2
    return g


def relabel(labels: np.ndarray) -> np.ndarray:
    """Labels renumbered 0 … n − 1 (ascending, no gaps): ``np.unique``'s inverse, by a
    count of every label (linear in the pixels) for non-negative labels."""
    flat = np.asarray(labels).ravel()
    if flat.size and np.issubdtype(flat.dtype, np.integer) and flat.min() >= 0:
        present = np.bincount(flat) > 0
        new = (np.cumsum(present) - 1).astype(np.int32)
        return new[flat].reshape(np.shape(labels))
    _, inverse = np.unique(flat, return_inverse=True)
    return inverse.reshape(np.shape(labels)).astype(np.int32)


def region_means(maps: Iterable[np.ndarray], regions: np.ndarray) -> np.ndarray:
    """Mean of every map (each H × W; taken one at a time, so a generator may make
    them) over each region of ``regions`` (0 … n − 1): (F, n) float32.

    Each map's means are one product with a sparse (H·W, n) averaging matrix (entry
    1/|region| at every pixel's region; SciPy), three times faster than
    ``np.bincount`` with weights, which converts every map to float64.
    """
    flat = np.asarray(regions).ravel()
    n = int(flat.max()) + 1
    counts = np.maximum(np.bincount(flat, minlength=n), 1)
    weight = (1.0 / counts[flat]).astype(np.float32)
    average = sps.csc_matrix((weight, (np.arange(flat.size), flat)), shape=(flat.size, n))
    rows = [np.asarray(m.ravel().astype(np.float32, copy=False) @ average) for m in maps]
    return np.asarray(rows, dtype=np.float32).reshape(len(rows), n)


def auto_region_area(shape: tuple[int, int], regions: int, smallest: int, largest: int) -> int:
    """Superpixel area (pixels) that cuts an image of ``shape`` into about ``regions``
    regions, kept within [``smallest``, ``largest``]."""
    return int(min(max(shape[0] * shape[1] // regions, smallest), largest))
