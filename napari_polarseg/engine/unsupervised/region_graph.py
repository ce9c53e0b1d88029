"""The superpixels of the unsupervised segmentation and the graph between them.

:func:`polarisation_superpixels` is a compact watershed over the summed gradient
magnitudes of the smoothed log Î and Stokes components s1 = S1/S0, s2 = S2/S0
(:func:`superpixel_edges`), so a region border sits on an intensity *or* a polarisation
edge; :func:`region_adjacency` is the shared-border graph of the regions.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps
from scipy import ndimage

from ..features.pixel_features import EPS_INTENSITY
from ..features.superpixels import COMPACTNESS

#: σ (pixels) of the smoothing before the edge maps of the superpixels are taken.
EDGE_SIGMA = 1.5


def superpixel_edges(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    polarisation_edge_weight: float = 1.0,
) -> np.ndarray:
    """Edge map (H, W), dimensionless: |∇(G * log Î)| / m_log + w · |∇(G * (s1, s2))| / m_s.

    s1 = ρ cos 2φ and s2 = ρ sin 2φ are the Stokes components normalised by S0, G a
    Gaussian of :data:`EDGE_SIGMA` px, each gradient divided by its median m over the
    image (so the two edge maps weigh alike whatever the units) and
    w = ``polarisation_edge_weight`` (0: log Î alone).
    """
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY))
    edges = ndimage.gaussian_gradient_magnitude(log_i, EDGE_SIGMA)
    edges /= max(float(np.median(edges)), 1e-12)
    if polarisation_edge_weight > 0:
        pol = np.hypot(
            ndimage.gaussian_gradient_magnitude(dop * np.cos(2 * phase), EDGE_SIGMA),
            ndimage.gaussian_gradient_magnitude(dop * np.sin(2 * phase), EDGE_SIGMA),
        )
        edges += polarisation_edge_weight * pol / max(float(np.median(pol)), 1e-12)
    return edges


def polarisation_superpixels(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    region_area: int,
    polarisation_edge_weight: float = 1.0,
    edges: np.ndarray | None = None,
) -> np.ndarray:
    """Superpixels (H, W) int32, 0 … n − 1, following intensity and polarisation edges.

    A compact watershed from a grid of ``H·W / region_area`` seeds over the edge map of
    :func:`superpixel_edges` (``edges``, computed when not given).
    """
    from skimage.segmentation import watershed

    if edges is None:
        edges = superpixel_edges(intensity, dop, phase, polarisation_edge_weight)
    n = max(2, int(round(intensity.size / region_area)))
    labels = watershed(edges, markers=n, compactness=COMPACTNESS)
    return relabel(labels)


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


def region_adjacency(regions: np.ndarray) -> sps.csr_matrix:
    """Shared border length (4-neighbour pixel pairs) between every two regions, (n, n)."""
    n = int(regions.max()) + 1
    pairs = []
    for a, b in ((regions[:, :-1], regions[:, 1:]), (regions[:-1], regions[1:])):
        differ = a != b
        pairs.append((a[differ], b[differ]))
    rows = np.concatenate([p[0] for p in pairs])
    cols = np.concatenate([p[1] for p in pairs])
    m = sps.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
    return (m + m.T).tocsr()
