"""Scribbles and class probabilities spread over the surfaces: a random walk with priors.

A pixel classifier trained on a few strokes knows the shading it was shown: elsewhere
on the same fruit, leaf or panel the light differs and the pixels' own features may
point to another class. What the classifier does not use is that a material's surface
is connected: its superpixels border each other across weak edges, while a border
between materials is an edge of intensity or polarisation.

So the class probabilities are taken per node — a superpixel, split in two or more
where the classifier's labels divide it (a superpixel may straddle a material border
that is no edge) — and spread over the graph of the nodes by the random walker with
priors (Grady 2005, "Multilabel random walker image
segmentation using prior models", CVPR, eq. 8–11): for every class k the region
probabilities x_k minimise

    E(x_k) = x_kᵀ L x_k + γ ‖x_k − λ_k‖²,  with x_k = 1 on the nodes seeded k and
    0 on the nodes seeded another class,

where the seeds are the nodes the user scribbled and those whose λ gives one class at
least :data:`CONFIDENT` (so a loaded classifier, without strokes, is not averaged away
over the whole graph; with them the same classifier labels an image nearly as it did
while trained on it), L = D − W is the Laplacian of the edge-aware region graph
(:func:`~napari_polarseg.engine.unsupervised.region_diffusion.edge_aware_adjacency`:
w_ab = L_ab · exp(−(e_ab / τ)²) over the border of nodes a and b, normalised by the
mean weight between superpixels), λ_k the classifier's mean p_k over the node and γ the
weight of the classifier against the graph (dimensionless). Setting the gradient to
zero gives one sparse linear system per class over the unscribbled nodes u,

    (L_uu + γ I) x_k,u = γ λ_k,u − L_us x_k,s,

solved together by one sparse LU factorisation (SciPy). The x_k sum to 1 over k. Small
γ lets a stroke label its whole surface; large γ returns the classifier's own
probabilities. Written here because scikit-image's ``random_walker`` works on the pixel
grid without a prior term, and a pixel-grid solve of a camera frame takes seconds where
the graph of a few thousand nodes takes milliseconds.

Measured with the robot user (``benchmarks/robot_user.py``): the walk is what lets one
stroke label a whole fruit or panel. Its cost: a material border that is neither an
intensity nor a polarisation edge (two textures of one brightness) is found only where
the classifier's labels split the superpixels, so there the labels are coarser than the
classifier's own (``region_walk`` = 0).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sps

from .. import disk_arrays
from ..chunks import N_THREADS, chunk_bounds, in_background, run_chunks
from ..features.pixel_feature_params import MAX_REGION_AREA, PIXELS_PER_REGION_SEED
from ..features.superpixels import auto_region_area, relabel
from ..tiles import row_bands
from ..unsupervised.region_diffusion import border_weights, symmetric
from .pixel_classifier import PixelClassifier, PixelPrediction, most_probable
from .refined_prediction import (
    grid_index,
    grid_probabilities,
    refined_probabilities,
)

#: τ of the graph's edge weights, in units of the median border strength.
EDGE_TAU = 1.0
#: A pixel pair's edge value: the smaller of its two pixels' (the blurred edge map is
#: high on both sides of a border; only the pair straddling it has both pixels on the crest).
EDGE_PAIR = np.minimum
#: Nodes whose mean classifier probability of one class is at least this are seeds of
#: that class too (beside the scribbled ones).
CONFIDENT = 0.8
#: Smallest automatic superpixel area of the walk, pixels (a 240 × 320 scene: 25 px).
MIN_REGION_AREA = 16
#: Rows of the nodes every pixel's answer is looked up for at once
#: (:func:`node_prediction`; bounds the int64 index).
NODE_BAND_ROWS = 512


@dataclass(frozen=True)
class RegionGraph:
    """Superpixels of an image and what weighs the borders between them.

    Attributes
    ----------
    regions : ndarray (H, W) int32
        Superpixel of every pixel, 0 … n − 1.
    edges : ndarray (H, W)
        Edge map the superpixels were grown on (dimensionless).
    scale : float
        τ × the median border strength of the superpixels: e_ab is divided by it.
    norm : float
        Mean weight L_ab · exp(−(e_ab / scale)²) over the superpixels' borders: every
        weight is divided by it (so γ means the same on every image).
    superpixel_adjacency : scipy.sparse.csr_matrix (n, n)
        :meth:`adjacency` of the superpixels themselves (the preview's graph).
    """

    regions: np.ndarray
    edges: np.ndarray
    scale: float
    norm: float
    superpixel_adjacency: sps.csr_matrix

    def nodes(self, labels: np.ndarray, k: int) -> np.ndarray:
        """The walk's nodes (H, W) int32, 0 … m − 1: every superpixel split by the
        classifier's ``labels`` (H, W; 0 … k − 1) into one node per class it holds, so a
        superpixel that straddles a border the watershed missed is not forced into
        one class."""
        return relabel(self.regions.astype(np.int64) * int(k) + labels)

    def adjacency(self, nodes: np.ndarray) -> sps.csr_matrix:
        """Symmetric (m, m) weights w_ab / :attr:`norm` between the ``nodes`` (module
        docstring)."""
        rows, cols, length, strength = banded_border_strength(nodes, self.edges)
        w = border_weights(length, strength, self.scale) / self.norm
        return symmetric(rows, cols, w, int(nodes.max()) + 1)


def pixel_pairs(
    a: np.ndarray, b: np.ndarray, ea: np.ndarray, eb: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(smaller region, larger region, edge value :data:`EDGE_PAIR`) int64, int64,
    float64 of the pixel pairs (``a``, ``b``) of two regions, edge values ``ea``,
    ``eb``, that differ, in raster order."""
    differ = a != b
    a, b = a[differ].astype(np.int64), b[differ].astype(np.int64)
    e = EDGE_PAIR(ea[differ], eb[differ]).astype(np.float64)
    return np.minimum(a, b), np.maximum(a, b), e


def border_pixel_pairs(
    regions: np.ndarray, edges: np.ndarray
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """:func:`pixel_pairs` of the 4-neighbour pixels of ``regions`` (H, W) across their
    borders, :data:`NODE_BAND_ROWS` rows at a time: the pairs along the rows, then those
    along the columns, each in raster order (the order of
    :func:`~..unsupervised.region_diffusion.border_strength`)."""
    h = regions.shape[0]
    for r in row_bands(h, NODE_BAND_ROWS):
        yield pixel_pairs(regions[r, :-1], regions[r, 1:], edges[r, :-1], edges[r, 1:])
    for r in row_bands(h - 1, NODE_BAND_ROWS):
        s = slice(r.start + 1, r.stop + 1)
        yield pixel_pairs(regions[r], regions[s], edges[r], edges[s])


def banded_border_strength(
    regions: np.ndarray, edges: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~..unsupervised.region_diffusion.border_strength` of ``regions`` (H, W;
    0 … n − 1) on the edge map ``edges`` with :data:`EDGE_PAIR`, the pixel pairs read
    band by band (:func:`border_pixel_pairs`), twice: once for the borders, once for
    their lengths and the sums of their pairs' edge values, added pair by pair in the
    same order (the same values to the bit, without the image's full-size pair arrays)."""
    n = int(regions.max()) + 1
    found = [np.unique(lo * n + hi) for lo, hi, _ in border_pixel_pairs(regions, edges)]
    keys = np.unique(np.concatenate(found)) if found else np.zeros(0, dtype=np.int64)
    count = np.zeros(keys.size, dtype=np.int64)
    total = np.zeros(keys.size)
    for lo, hi, e in border_pixel_pairs(regions, edges):
        at = np.searchsorted(keys, lo * n + hi)
        count += np.bincount(at, minlength=keys.size)
        np.add.at(total, at, e)
    length = count.astype(np.float64)
    return keys // n, keys % n, length, total / length


def node_means(nodes: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Mean of every plane (K, H, W) over each node of ``nodes`` (H, W): (m, K)."""
    flat = nodes.ravel()
    m = int(flat.max()) + 1
    counts = np.maximum(np.bincount(flat, minlength=m), 1)
    sums = [np.bincount(flat, weights=p.ravel(), minlength=m) for p in planes]
    return np.stack(sums, axis=1) / counts[:, None]


def node_seeds(nodes: np.ndarray, scribbles: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """(m,) int: for every node the index into ``classes`` of the class most of its
    scribbled pixels hold, −1 where nothing is scribbled (values not in ``classes``,
    e.g. on masked pixels, are ignored)."""
    flat = np.asarray(scribbles).ravel()
    m = int(nodes.max()) + 1
    marked = np.flatnonzero(flat > 0)
    index = np.searchsorted(classes, flat[marked])
    clipped = np.minimum(index, classes.size - 1)
    known = (index < classes.size) & (classes[clipped] == flat[marked])
    votes = np.zeros((m, classes.size))
    np.add.at(votes, (nodes.ravel()[marked[known]], index[known]), 1.0)
    return np.where(votes.sum(axis=1) > 0, votes.argmax(axis=1), -1)


def confident_seeds(prior: np.ndarray, least: float = CONFIDENT) -> np.ndarray:
    """(m,) int: the class index of the nodes whose prior (m, K) gives one class at
    least ``least``, −1 elsewhere."""
    return np.where(prior.max(axis=1) >= least, prior.argmax(axis=1), -1)


def with_scribbles(
    seeds: np.ndarray, nodes: np.ndarray, scribbles: np.ndarray | None, classes: np.ndarray
) -> np.ndarray:
    """``seeds`` (m,) with the nodes holding ``scribbles`` (:func:`node_seeds`; none
    when None) set to their scribbled class."""
    if scribbles is None:
        return seeds
    painted = node_seeds(nodes, scribbles, classes)
    return np.where(painted >= 0, painted, seeds)


def walk_region_area(shape: tuple[int, int]) -> int:
    """The walk's automatic superpixel area (pixels) on an image of ``shape``: the
    pixel features' (:data:`PIXELS_PER_REGION_SEED`-th of the image), but down to
    :data:`MIN_REGION_AREA`."""
    return auto_region_area(shape, PIXELS_PER_REGION_SEED, MIN_REGION_AREA, MAX_REGION_AREA)


def region_graph(regions: np.ndarray, edges: np.ndarray) -> RegionGraph:
    """The :class:`RegionGraph` of superpixels ``regions`` (H, W; 0 … n − 1) grown on
    the edge map ``edges`` (H, W, dimensionless:
    :func:`~napari_polarseg.engine.features.superpixels.superpixel_edges` of a
    polarisation image, summed with every colour's so a border seen in one colour only
    is an edge too), weights of τ = :data:`EDGE_TAU`."""
    rows, cols, length, strength = banded_border_strength(regions, edges)
    n = int(regions.max()) + 1
    if length.size == 0:
        return RegionGraph(regions, edges, 1.0, 1.0, sps.csr_matrix((n, n)))
    scale = max(EDGE_TAU * float(np.median(strength)), 1e-12)
    w = border_weights(length, strength, scale)
    norm = max(float(w.mean()), 1e-12)
    return RegionGraph(regions, edges, scale, norm, symmetric(rows, cols, w / norm, n))


def walk(
    adjacency: sps.csr_matrix,
    prior: np.ndarray,
    seeds: np.ndarray,
    weight: float | np.ndarray,
) -> np.ndarray:
    """Node class probabilities (n, K) of the random walker with priors (module
    docstring): ``prior`` λ (n, K), ``seeds`` (n,) the class index of seeded nodes
    (−1: none), ``weight`` γ > 0, one for every node or (n,) per node (0 where a node
    has no prior: its x is its neighbours' harmonic mean)."""
    from scipy.sparse.linalg import splu

    n, k = prior.shape
    seeded = seeds >= 0
    free = np.flatnonzero(~seeded)
    out = np.zeros((n, k))
    out[seeded, seeds[seeded]] = 1.0
    if free.size == 0:
        return out
    # a node with neither prior nor neighbours keeps a trace of its prior (no 0 pivot)
    gamma = np.maximum(np.broadcast_to(np.asarray(weight, dtype=float), (n,))[free], 1e-9)
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    laplacian = (sps.diags(degree) - adjacency).tocsr()
    system = laplacian[free][:, free] + sps.diags(gamma)
    rhs = gamma[:, None] * prior[free]
    if seeded.any():
        rhs -= laplacian[free][:, np.flatnonzero(seeded)] @ out[seeded]
    out[free] = splu(sps.csc_matrix(system)).solve(np.ascontiguousarray(rhs))
    np.clip(out, 0.0, None, out=out)
    total = out.sum(axis=1, keepdims=True)
    return out / np.where(total > 0, total, 1.0)


def preview_prediction(
    classifier: PixelClassifier,
    features: Any,
    graph: RegionGraph,
    stride: int,
    scribbles: np.ndarray | None = None,
    cancel: Any = None,
    coarse: np.ndarray | None = None,
) -> PixelPrediction:
    """A fast :func:`walked_prediction` to show first: the walk over the superpixels
    themselves (not split), each one's prior λ the mean of the grid samples of
    ``stride`` inside it (``coarse`` when already predicted); a superpixel that holds
    no sample takes its neighbours' answer (γ = 0 there). Every pixel takes its
    superpixel's class."""
    s = max(1, int(stride))
    if coarse is None:
        coarse = grid_probabilities(classifier.model, features, s, cancel)
    rows, cols = grid_index(features.shape, s)
    sampled = graph.regions[rows[:, None], cols[None, :]].ravel()
    n = int(graph.regions.max()) + 1
    counts = np.bincount(sampled, minlength=n).astype(float)
    sums = [np.bincount(sampled, weights=c.ravel(), minlength=n) for c in coarse]
    prior = np.stack(sums, axis=1) / np.maximum(counts, 1)[:, None]
    weight = np.where(counts > 0, classifier.params.region_walk, 0.0)
    confident = np.where(counts > 0, confident_seeds(prior), -1)
    seeds = with_scribbles(confident, graph.regions, scribbles, classifier.classes)
    x = walk(graph.superpixel_adjacency, prior, seeds, weight)
    return node_prediction(x, graph.regions, classifier.classes, int(coarse[0].size))


def node_prediction(
    x: np.ndarray, nodes: np.ndarray, classes: np.ndarray, n_predicted: int
) -> PixelPrediction:
    """Every pixel's probabilities, label and uncertainty 1 − (x_(1) − x_(2)) from its
    node's x (m, K), looked up :data:`NODE_BAND_ROWS` rows of ``nodes`` (H, W) at a time
    (split among the cores) into arrays placed by :func:`~..disk_arrays.empty` (in
    temporary files when the image's full-size arrays do not fit the run's limit)."""
    ordered = np.sort(x, axis=1)
    margin = ordered[:, -1] - (ordered[:, -2] if x.shape[1] > 1 else 0.0)
    planes = [x[:, k].astype(np.float32) for k in range(x.shape[1])]
    best = np.argmax(x, axis=1).astype(np.int32)
    sure = (1.0 - margin).astype(np.float32)
    proba = disk_arrays.empty((x.shape[1], *nodes.shape), dtype=np.float32)
    labels = disk_arrays.empty(nodes.shape, dtype=np.int32)
    uncertainty = disk_arrays.empty(nodes.shape, dtype=np.float32)
    # bands on the cores (np.take frees the GIL), together as many rows as one band
    bands = list(row_bands(nodes.shape[0], max(1, NODE_BAND_ROWS // N_THREADS)))

    def work(first: int, stop: int) -> None:
        for band in bands[first:stop]:
            index = nodes[band].astype(np.intp, copy=False)  # converted once, not per take
            for k, plane in enumerate(planes):  # "clip": "raise" would buffer a copy
                np.take(plane, index, out=proba[k, band], mode="clip")
            np.take(best, index, out=labels[band], mode="clip")
            np.take(sure, index, out=uncertainty[band], mode="clip")
            disk_arrays.release(proba, labels, uncertainty)

    run_chunks(chunk_bounds(len(bands), 1), work, nodes.size)
    return PixelPrediction(labels, proba, uncertainty, classes, n_predicted)


def walked_prediction(
    classifier: PixelClassifier,
    features: Any,
    graph: RegionGraph,
    stride: int,
    scribbles: np.ndarray | None = None,
    cancel: Any = None,
    coarse: np.ndarray | None = None,
) -> PixelPrediction:
    """Every pixel's class from the walk, γ = ``classifier.params.region_walk``.

    The prior: the classifier's probabilities of the grid of ``stride`` (``coarse``
    when already predicted) interpolated to every pixel, and every pixel of the grid
    cells on a border between classes predicted on its own
    (:func:`~.refined_prediction.refined_probabilities`), so the nodes split where the
    pixels' own labels change. The seeds: the confident nodes
    (:func:`confident_seeds`) and those holding ``scribbles`` (None: none, e.g. a loaded
    classifier on a new image). Each pixel takes its node's probabilities, label and
    uncertainty 1 − (x_(1) − x_(2))."""
    refined = refined_probabilities(classifier.model, features, stride, cancel, coarse)
    prior = refined.probabilities
    classes = classifier.classes
    nodes = graph.nodes(most_probable(prior), classes.size)
    adjacency = in_background(lambda: graph.adjacency(nodes))  # beside the means (GIL-free sorts)
    means = node_means(nodes, prior)
    seeds = with_scribbles(confident_seeds(means), nodes, scribbles, classes)
    x = walk(adjacency(), means, seeds, classifier.params.region_walk)
    return node_prediction(x, nodes, classes, refined.n_predicted)
