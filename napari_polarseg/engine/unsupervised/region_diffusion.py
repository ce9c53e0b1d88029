"""Edge-aware diffusion of superpixel features over the region adjacency graph.

A superpixel holds a few dozen pixels: its mean ρ and its ρ–shading slope follow the
tilt of that small patch as much as its material. Averaging each superpixel's features
with its neighbours' — but not across an edge of the polarisation image — gives every
superpixel the features of the surface it lies on (a whole leaf, a whole fruit), over
which the tilt varies and the material does not.

The graph: regions a, b that share a border of L_ab pixel pairs, whose edge strength
e_ab is the mean, over those pairs, of the larger of the two pixels' values of the edge
map (the map the superpixels were grown on, dimensionless: gradients in units of their
image median). Weights w_ab = L_ab · exp(−(e_ab / τ)²), τ = ``tau`` × the median
e_ab over the graph. The diffusion is the lazy random walk
x ← (1 − λ) x + λ D⁻¹ W x (D the row sums of W), ``iterations`` times, with λ the
``strength``: after t steps a feature is averaged over about √t regions across weak
borders and hardly at all across strong ones.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.sparse as sps


def border_strength(
    regions: np.ndarray, edges: np.ndarray, pair: Callable[..., np.ndarray] = np.maximum
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Shared borders of neighbouring regions and their edge strength.

    Parameters
    ----------
    regions : int array (H, W)
        Region of every pixel, 0 … n − 1.
    edges : float array (H, W) or (C, H, W)
        Edge map (any non-negative units), or C of them read along the same borders.
    pair : ufunc
        How a pixel pair's edge value is made of its two pixels' (``np.maximum``: the
        larger; ``np.minimum``: the smaller, which places a blurred edge between the
        two pixels that both lie on its crest).

    Returns
    -------
    rows, cols : int arrays (m,)
        The two regions of each border, rows < cols.
    length : float array (m,)
        4-neighbour pixel pairs across the border.
    strength : float array (m,) or (m, C)
        Mean over those pairs of the pair's edge value (``pair``), one column per map.
    """
    maps = edges[None] if edges.ndim == 2 else edges
    a_parts, b_parts, e_parts = [], [], []
    for sl_a, sl_b in (
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
    ):
        a, b = regions[sl_a], regions[sl_b]
        differ = a != b
        a_parts.append(a[differ])
        b_parts.append(b[differ])
        e_parts.append(
            pair(maps[(slice(None), *sl_a)][:, differ], maps[(slice(None), *sl_b)][:, differ])
        )
    a = np.concatenate(a_parts).astype(np.int64)
    b = np.concatenate(b_parts).astype(np.int64)
    e = np.concatenate(e_parts, axis=1).astype(np.float64)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    n = int(regions.max()) + 1
    pair, inverse = np.unique(lo * n + hi, return_inverse=True)
    length = np.bincount(inverse).astype(np.float64)
    strength = np.stack([np.bincount(inverse, weights=c) for c in e], axis=1) / length[:, None]
    strength = strength[:, 0] if edges.ndim == 2 else strength
    return (pair // n).astype(np.int64), (pair % n).astype(np.int64), length, strength


def edge_aware_adjacency(
    regions: np.ndarray, edges: np.ndarray, tau: float = 1.0
) -> sps.csr_matrix:
    """Symmetric (n, n) weights L_ab · exp(−(e_ab / τ)²) of the module docstring,
    τ = ``tau`` × the median border strength."""
    rows, cols, length, strength = border_strength(regions, edges)
    return weighted_graph(rows, cols, length, strength, int(regions.max()) + 1, tau)


def weighted_graph(
    rows: np.ndarray,
    cols: np.ndarray,
    length: np.ndarray,
    strength: np.ndarray,
    n: int,
    tau: float,
) -> sps.csr_matrix:
    """The symmetric (n, n) weights L_ab · exp(−(e_ab / τ)²) of the borders (rows,
    cols) of ``length`` and ``strength``, τ = ``tau`` × their median strength."""
    if rows.size == 0:
        return sps.csr_matrix((n, n))
    scale = max(float(tau) * float(np.median(strength)), 1e-12)
    return symmetric(rows, cols, border_weights(length, strength, scale), n)


def gated_strength(strength: np.ndarray, dz: np.ndarray, gate: float) -> np.ndarray:
    """Border strengths e_ab = p_ab + c_ab · i_ab from the two columns of ``strength``
    (m, 2), the log Î edges i and the Stokes edges p along each border, with
    c_ab = 1 − exp(−(Δz_ab / (``gate`` · median Δz))²) and Δz_ab = |z_a − z_b| the
    difference of the two superpixels' complex polarisation z = (S1 + iS2) / S0
    (dimensionless). A step of Î across which the polarisation runs on (a cast shadow's
    edge, Δz ≈ 0) weighs as a border only by its Stokes edges; one between superpixels
    of differing polarisation keeps its log Î edges; ``gate`` <= 0: c_ab = 1, the two
    summed. Written here: the gate is this package's own rule, no library has it."""
    if gate <= 0.0:
        return strength[:, 1] + strength[:, 0]
    t = max(float(gate) * float(np.median(dz)), 1e-12) if dz.size else 1.0
    c = 1.0 - np.exp(-np.minimum((dz / t) ** 2, 50.0))
    return strength[:, 1] + c * strength[:, 0]


def gated_adjacency(
    regions: np.ndarray, channels: np.ndarray, z: np.ndarray, gate: float, tau: float = 1.0
) -> sps.csr_matrix:
    """:func:`edge_aware_adjacency` with the strengths of :func:`gated_strength`:
    ``channels`` (2, H, W) the log Î and the Stokes edge maps
    (:func:`~napari_polarseg.engine.features.superpixels.border_channels`), ``z`` (n,)
    the regions' complex polarisation."""
    rows, cols, length, both = border_strength(regions, channels)
    strength = gated_strength(both, np.abs(z[rows] - z[cols]), gate)
    return weighted_graph(rows, cols, length, strength, int(regions.max()) + 1, tau)


def border_weights(length: np.ndarray, strength: np.ndarray, scale: float) -> np.ndarray:
    """w_ab = L_ab · exp(−(e_ab / ``scale``)²) of every border (module docstring)."""
    # capped at e^-50 so that every row keeps a normalisable (non-denormal) sum
    return length * np.exp(-np.minimum((strength / scale) ** 2, 50.0))


def symmetric(rows: np.ndarray, cols: np.ndarray, weights: np.ndarray, n: int) -> sps.csr_matrix:
    """The symmetric (n, n) matrix with ``weights`` at (rows, cols) and (cols, rows)."""
    half = sps.coo_matrix((weights, (rows, cols)), shape=(n, n)).tocsr()
    return (half + half.T).tocsr()


#: Most diffusion steps, whatever the image (bounds the time on very large frames).
MAX_STEPS = 200


def diffusion_steps(reach: float, n_regions: int, strength: float) -> int:
    """Steps t = ⌈reach² · n / λ⌉ (at most :data:`MAX_STEPS`) that spread a feature over
    a share ``reach`` of the side of an image tiled by ``n_regions`` regions (a lazy walk
    of t steps moves √(λ t) regions, each of side √(H·W / n)); 0 when λ or reach is 0."""
    if strength <= 0 or reach <= 0:
        return 0
    return int(min(MAX_STEPS, math.ceil(reach * reach * n_regions / strength)))


def diffuse(
    x: np.ndarray, adjacency: sps.csr_matrix, strength: float, iterations: int
) -> np.ndarray:
    """Node features (n, c) after ``iterations`` lazy random-walk steps
    x ← (1 − λ) x + λ D⁻¹ W x over ``adjacency`` W (λ = ``strength`` in [0, 1]);
    an isolated node keeps its features."""
    if strength <= 0 or iterations <= 0:
        return x
    deg = np.asarray(adjacency.sum(axis=1)).ravel()
    walk = sps.diags(1.0 / np.where(deg > 0, deg, 1.0)) @ adjacency
    keep = np.where(deg > 0, 1.0 - strength, 1.0)[:, None]
    for _ in range(int(iterations)):
        x = keep * x + strength * (walk @ x)
    return x
