"""Scribbles and class probabilities spread over the surfaces: a random walk with priors.

A pixel classifier trained on a few strokes knows the shading it was shown: elsewhere
on the same fruit, leaf or panel the light differs and the pixels' own features may
point to another class. What the classifier does not use is that a material's surface
is connected: its superpixels border each other across weak edges, while a border
between materials is an edge of intensity or polarisation.

So the class probabilities are taken per superpixel and spread over the region graph
by the random walker with priors (Grady 2005, "Multilabel random walker image
segmentation using prior models", CVPR, eq. 8–11): for every class k the region
probabilities x_k minimise

    E(x_k) = x_kᵀ L x_k + γ ‖x_k − λ_k‖²,  with x_k = 1 on the regions scribbled k and
    0 on the regions scribbled another class,

where L = D − W is the Laplacian of the edge-aware region graph
(:func:`~napari_polarseg.engine.unsupervised.region_diffusion.edge_aware_adjacency`:
w_ab = L_ab · exp(−(e_ab / τ)²) over the border of regions a and b, normalised to mean
1), λ_k the classifier's mean p_k over the region and γ the weight of the classifier
against the graph (dimensionless). Setting the gradient to zero gives one sparse linear
system per class over the unscribbled regions u,

    (L_uu + γ I) x_k,u = γ λ_k,u − L_us x_k,s,

solved together by one sparse LU factorisation (SciPy). The x_k sum to 1 over k. Small
γ lets a stroke label its whole surface; large γ returns the classifier's own
probabilities. Written here because scikit-image's ``random_walker`` works on the pixel
grid without a prior term, and a pixel-grid solve of a camera frame takes seconds where
the region graph of a few thousand nodes takes milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sps

from ..features.pixel_features import (
    MAX_REGION_AREA,
    MIN_REGION_AREA,
    PIXELS_PER_REGION_SEED,
)
from ..features.superpixels import auto_region_area
from ..unsupervised.region_diffusion import edge_aware_adjacency
from ..unsupervised.region_graph import polarisation_superpixels, superpixel_edges
from .pixel_classifier import PixelClassifier, PixelPrediction
from .refined_prediction import grid_probabilities, upsampled

#: τ of the graph's edge weights, in units of the median border strength.
EDGE_TAU = 1.0


@dataclass(frozen=True)
class RegionGraph:
    """Superpixels of an image and the edge-aware graph between them.

    Attributes
    ----------
    regions : ndarray (H, W) int32
        Region of every pixel, 0 … n − 1.
    adjacency : scipy.sparse.csr_matrix (n, n)
        Symmetric weights w_ab (module docstring), mean 1 over the borders.
    counts : ndarray (n,) float64
        Pixels of every region.
    """

    regions: np.ndarray
    adjacency: sps.csr_matrix
    counts: np.ndarray

    @property
    def n(self) -> int:
        """Number of regions."""
        return int(self.counts.size)

    def means(self, planes: np.ndarray) -> np.ndarray:
        """Mean of every plane (K, H, W) over each region: (n, K) float64."""
        flat = self.regions.ravel()
        sums = [np.bincount(flat, weights=p.ravel(), minlength=self.n) for p in planes]
        return np.stack(sums, axis=1) / np.maximum(self.counts, 1)[:, None]

    def seeds(self, scribbles: np.ndarray, classes: np.ndarray) -> np.ndarray:
        """(n,) int: for every region the index into ``classes`` of the class most of its
        scribbled pixels hold, −1 where nothing is scribbled (values not in ``classes``,
        e.g. on masked pixels, are ignored)."""
        flat = np.asarray(scribbles).ravel()
        marked = np.flatnonzero(flat > 0)
        index = np.searchsorted(classes, flat[marked])
        known = (index < classes.size) & (
            classes[np.minimum(index, classes.size - 1)] == flat[marked]
        )
        votes = np.zeros((self.n, classes.size))
        np.add.at(votes, (self.regions.ravel()[marked[known]], index[known]), 1.0)
        return np.where(votes.sum(axis=1) > 0, votes.argmax(axis=1), -1)


def region_graph(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, region_area: int = 0
) -> RegionGraph:
    """The :class:`RegionGraph` of a polarisation image (Î, ρ, φ radians): superpixels
    following intensity and polarisation edges
    (:func:`~napari_polarseg.engine.unsupervised.region_graph.polarisation_superpixels`)
    of ``region_area`` pixels (0: the pixel features' automatic area), weights of
    τ = :data:`EDGE_TAU`."""
    shape = np.shape(intensity)
    area = int(region_area) or auto_region_area(
        shape, PIXELS_PER_REGION_SEED, MIN_REGION_AREA, MAX_REGION_AREA
    )
    edges = superpixel_edges(intensity, dop, phase)
    regions = polarisation_superpixels(intensity, dop, phase, area, edges=edges)
    adjacency = edge_aware_adjacency(regions, edges, EDGE_TAU)
    if adjacency.nnz:
        adjacency = adjacency / float(adjacency.data.mean())
    counts = np.bincount(regions.ravel()).astype(np.float64)
    return RegionGraph(regions, sps.csr_matrix(adjacency), counts)


def walk(
    adjacency: sps.csr_matrix, prior: np.ndarray, seeds: np.ndarray, weight: float
) -> np.ndarray:
    """Region class probabilities (n, K) of the random walker with priors (module
    docstring): ``prior`` λ (n, K), ``seeds`` (n,) the class index of scribbled regions
    (−1: none), ``weight`` γ > 0."""
    from scipy.sparse.linalg import splu

    n, k = prior.shape
    seeded = seeds >= 0
    free = np.flatnonzero(~seeded)
    out = np.zeros((n, k))
    out[seeded, seeds[seeded]] = 1.0
    if free.size == 0:
        return out
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    laplacian = (sps.diags(degree) - adjacency).tocsr()
    system = laplacian[free][:, free] + float(weight) * sps.identity(free.size)
    rhs = float(weight) * prior[free]
    if seeded.any():
        rhs -= laplacian[free][:, np.flatnonzero(seeded)] @ out[seeded]
    out[free] = splu(sps.csc_matrix(system)).solve(np.ascontiguousarray(rhs))
    np.clip(out, 0.0, None, out=out)
    total = out.sum(axis=1, keepdims=True)
    return out / np.where(total > 0, total, 1.0)


def walked_regions(
    graph: RegionGraph,
    probabilities: np.ndarray,
    weight: float,
    scribbles: np.ndarray | None = None,
    classes: np.ndarray | None = None,
) -> np.ndarray:
    """Region probabilities x (n, K) after the walk: the classifier's ``probabilities``
    (K, H, W) averaged per region as the prior λ, the regions holding ``scribbles``
    (values ``classes``; no seeds when None) as seeds."""
    prior = graph.means(probabilities)
    if scribbles is None or classes is None:
        seeds = np.full(graph.n, -1)
    else:
        seeds = graph.seeds(scribbles, np.asarray(classes))
    return walk(graph.adjacency, prior, seeds, weight)


def walked_prediction(
    classifier: PixelClassifier,
    features: Any,
    graph: RegionGraph,
    stride: int,
    scribbles: np.ndarray | None = None,
    cancel: Any = None,
    coarse: np.ndarray | None = None,
) -> PixelPrediction:
    """Every pixel's class from the walk: the classifier predicts the grid of
    ``stride`` (:func:`~.refined_prediction.grid_probabilities`, or ``coarse`` when
    already predicted), interpolated to every pixel as the prior, walked with
    γ = ``classifier.params.region_walk`` from the ``scribbles`` (None: from the prior
    alone, e.g. a loaded classifier on a new image); each pixel takes its region's
    probabilities, label and uncertainty 1 − (x_(1) − x_(2)).

    The borders are the superpixels' (they follow intensity and polarisation edges),
    so no pixel is predicted on its own beyond the grid."""
    s = max(1, int(stride))
    if coarse is None:
        coarse = grid_probabilities(classifier.model, features, s, cancel)
    prior = upsampled(coarse, s, features.shape)
    x = walked_regions(graph, prior, classifier.params.region_walk, scribbles, classifier.classes)
    ordered = np.sort(x, axis=1)
    margin = ordered[:, -1] - (ordered[:, -2] if x.shape[1] > 1 else 0.0)
    regions = graph.regions
    proba = np.empty(prior.shape, dtype=np.float32)
    for k in range(x.shape[1]):
        np.take(x[:, k].astype(np.float32), regions, out=proba[k])
    labels = np.take(np.argmax(x, axis=1).astype(np.int32), regions)
    uncertainty = np.take((1.0 - margin).astype(np.float32), regions)
    return PixelPrediction(labels, proba, uncertainty, classifier.classes, int(coarse[0].size))
