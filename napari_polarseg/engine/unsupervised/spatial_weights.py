"""Node features weighed per scene by how spatially coherent each is (Moran's I).

A material covers regions: a feature that tells materials apart takes like values on
neighbouring superpixels and changes at a few borders. A feature that follows what
changes from object to object within one material (the light on each leaf, its tilt)
or from pixel to pixel (noise) is less alike between neighbours. Moran's I of each
standardised node feature x over the superpixels' border graph,

    I = (n / Σ_ab L_ab) · Σ_ab L_ab x_a x_b / Σ_a x_a²,

with L_ab the border length between superpixels a and b (``RegionModel.adjacency``),
measures that without truth: 1 for a feature constant within large patches, 0 for
one with no relation between neighbours. Each column is multiplied by
(max(I, 0) / max_j I_j)^p, so the most coherent feature keeps its weight and the others
are weighed down by how much less coherent they are in this scene. On the development
halves of the scene families, a feature's I tracked how much of its spread the
materials explain (Spearman +0.59 over the diffuse family's features, +0.15 to +0.44
over the others'; ``benchmarks/feature_separation.py``): where the materials share
their albedo (the diffuse family) log Î's I falls below that of the AoLP and ρ
features, on large objects of differing albedo it is the highest. As weights
(``UnsupervisedParams.coherence_power``) they were level with the default there at
p = 1 and cost the real frames 0.06, so the default leaves them off
(docs/quality.md, *Which node features carry the materials*).

Written with scipy.sparse: no library gives Moran's I on a region graph.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps


def morans_i(xs: np.ndarray, adjacency: sps.csr_matrix) -> np.ndarray:
    """(c,) Moran's I of each column of ``xs`` (n, c) over the symmetric border-length
    graph ``adjacency`` (n, n), the columns centred on their means; 0 for a constant
    column or a graph without borders."""
    graph = adjacency.tocsr(copy=True)
    graph.setdiag(0)
    graph.eliminate_zeros()
    total = float(graph.sum())
    v = xs - xs.mean(axis=0)
    norm = (v * v).sum(axis=0)
    if total <= 0:
        return np.zeros(xs.shape[1])
    cross = (v * (graph @ v)).sum(axis=0)
    return np.where(norm > 1e-12, xs.shape[0] / total * cross / np.maximum(norm, 1e-12), 0.0)


def coherence_weights(xs: np.ndarray, adjacency: sps.csr_matrix, power: float) -> np.ndarray:
    """(c,) the weight of each column of ``xs``: (max(I, 0) / max I)^``power`` of its
    :func:`morans_i`; ones when ``power`` is 0 or no column is coherent."""
    if power <= 0:
        return np.ones(xs.shape[1])
    i = np.maximum(morans_i(xs, adjacency), 0.0)
    top = i.max() if i.size else 0.0
    if top <= 0:
        return np.ones(xs.shape[1])
    return (i / top) ** power
