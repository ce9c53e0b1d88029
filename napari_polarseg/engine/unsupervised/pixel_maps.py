"""What the superpixel clustering reads of the pixels before it draws the superpixels,
whatever their size (:func:`~.segmenter.prepare_regions`): the maps checked and, with a
mask, filled from the nearest valid pixel (``_filled_maps``), the per-pixel terms of
the node features and the superpixels' edge map (:func:`pixel_maps`, :class:`PixelMaps`,
made once when several sizes are drawn from one image).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps

from ..chunks import in_background
from ..errors import PolarsegError
from ..features.pixel_features import check_maps
from ..features.superpixels import border_channels, edge_terms
from ..physics.pixel_mask import nearest_valid
from .params import UnsupervisedParams
from .region_diffusion import edge_aware_adjacency, gated_adjacency
from .region_features import pixel_terms
from .texture import reads_grain


def edge_weight(p: UnsupervisedParams) -> float:
    """The weight of the polarisation edges in the superpixels' edge map (0: log Î alone)."""
    return p.polarisation_edge_weight if p.boundary == "polarisation" else 0.0


@dataclass(frozen=True)
class PixelMaps:
    """What :func:`~.segmenter.prepare_regions` reads of the pixels before it draws the
    superpixels, the same at every superpixel size: :func:`pixel_maps` makes it once for
    several region models of one image (:mod:`.consensus`).

    Attributes
    ----------
    maps : tuple of ndarray (H, W)
        Î, ρ, φ (outside the mask: the nearest valid pixel's values).
    valid : ndarray (H, W) of bool or None
        The pixels the clustering reads (None: every pixel).
    nearest : ndarray (H, W) of int or None
        With a mask, the flat index of the nearest valid pixel of every pixel.
    terms : dict of str to ndarray (H, W)
        The per-pixel maps of the node features (:func:`.region_features.pixel_terms`).
    edge_terms : ndarray (C, H, W)
        The terms of the superpixels' edge map apart
        (:func:`~napari_polarseg.engine.features.superpixels.edge_terms`), the
        polarisation edges weighted ``edge_weight``: their sum is the map the watershed
        follows, the borders may weigh them differently (:func:`border_graph`).
    edge_weight : float
    """

    maps: tuple[np.ndarray, np.ndarray, np.ndarray]
    valid: np.ndarray | None
    nearest: np.ndarray | None
    terms: dict[str, np.ndarray]
    edge_terms: np.ndarray
    edge_weight: float


def _filled_maps(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, valid: np.ndarray | None
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray | None, np.ndarray | None]:
    """((Î, ρ, φ), valid, nearest): the checked maps, outside ``valid`` filled from the
    nearest valid pixel, ``valid`` None when it is every pixel, and the flat index of
    each pixel's nearest valid one (None without a mask)."""
    i, d, ph = check_maps(intensity, dop, phase)
    nearest = None
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != i.shape:
            raise PolarsegError(f"the mask is {valid.shape} but the maps are {i.shape}")
        if valid.all():
            valid = None
        else:
            rows, cols = nearest_valid(valid)
            i, d, ph = i[rows, cols], d[rows, cols], ph[rows, cols]
            nearest = rows * i.shape[1] + cols  # flat: one gather per use, not two
    if min(i.shape) < 2:
        raise PolarsegError(f"image too small to segment: {i.shape}")
    return (i, d, ph), valid, nearest


def pixel_maps(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    params: UnsupervisedParams | None = None,
    valid: np.ndarray | None = None,
) -> PixelMaps:
    """The :class:`PixelMaps` of :func:`~.segmenter.prepare_regions` with these
    arguments, to be given to it as ``pixels`` (so several superpixel sizes share them).
    The node features' per-pixel terms are made in a second thread while the edge map
    is (numpy releases the GIL)."""
    p = params or UnsupervisedParams()
    (i, d, ph), valid, nearest = _filled_maps(intensity, dop, phase, valid)
    # the grain maps only for parameters that read them (the other methods skip their cost)
    grain = reads_grain(p.features + p.texture)
    terms = in_background(lambda: pixel_terms(i, d, ph, texture=grain))
    parts = edge_terms((i, d, ph), edge_weight(p))
    return PixelMaps((i, d, ph), valid, nearest, terms(), parts, edge_weight(p))


def border_graph(
    p: UnsupervisedParams, terms: np.ndarray, regions: np.ndarray, z: np.ndarray
) -> sps.csr_matrix:
    """The edge-aware border weights of the superpixels ``regions`` for the diffusion and
    the merge, τ = ``p.diffusion_tau``, read on the terms of their edge map ``terms``
    (:func:`~napari_polarseg.engine.features.superpixels.edge_terms`): summed, as the
    watershed follows them (:func:`~.region_diffusion.edge_aware_adjacency`), or, where
    :func:`reweighs_borders`, apart, the log Î edges weighed
    ``p.border_intensity_weight`` and gated by the difference of the regions' complex
    polarisation ``z`` (``p.border_gate``; :func:`~.region_diffusion.gated_adjacency`)."""
    if reweighs_borders(p):
        channels = border_channels(terms, p.border_intensity_weight)
        return gated_adjacency(regions, channels, z, p.border_gate, p.diffusion_tau)
    return edge_aware_adjacency(regions, terms.sum(axis=0), p.diffusion_tau)


def reweighs_borders(p: UnsupervisedParams) -> bool:
    """Whether the borders weigh the two terms of the edge map otherwise than the
    superpixels' map does (a log Î weight below 1 or a gate)."""
    return p.border_gate > 0.0 or p.border_intensity_weight != 1.0
