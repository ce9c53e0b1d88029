"""Where to paint next: the largest region the pixel classifier is least sure of.

Active learning by uncertainty sampling (Settles 2009, "Active learning literature
survey", section 3.1), region-wise as ilastik's users do it by eye: a stroke where the
classifier hesitates teaches it most. :func:`paint_here_next` smooths the uncertainty map
u (1 − max probability, or the margin's 1 − (p₁ − p₂); 0 sure … 1 a tie) with a Gaussian of
σ ``smoothing`` pixels over the allowed pixels only (single uncertain pixels are noise,
not a region), keeps the pixels whose smoothed u is at least halfway between its median
and its highest values (the 1 − ``top_share`` quantile) and at least
``min_uncertainty``, leaves out the pixels already painted and those not used, and
returns the connected region (8-neighbours) with the largest summed uncertainty
Σ u over its pixels — large and unsure beats small and slightly more unsure — with its
deepest point (the pixel farthest from its border, so it lies inside the region even
when the region is not convex) for the view to centre on. Plain numpy and scipy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import PolarsegError


@dataclass(frozen=True)
class SuggestionParams:
    """How :func:`paint_here_next` picks the region.

    Attributes
    ----------
    smoothing : float
        σ (pixels) of the Gaussian applied to the uncertainty before thresholding.
    top_share : float
        The threshold is halfway between the median smoothed uncertainty of the used,
        unpainted pixels and its (1 − ``top_share``) quantile (the highest, robustly):
        a pixel at least that unsure may be in the region.
    min_uncertainty : float
        Pixels whose smoothed uncertainty is below this are never suggested (a classifier
        sure everywhere has nothing to suggest).
    min_pixels : int
        Smaller regions are not suggested.
    """

    smoothing: float = 2.0
    top_share: float = 0.005
    min_uncertainty: float = 0.2
    min_pixels: int = 16

    def __post_init__(self) -> None:
        if not (self.smoothing >= 0 and 0 < self.top_share <= 1):
            raise PolarsegError("smoothing must be >= 0 and top_share in (0, 1]")
        if not (0 <= self.min_uncertainty <= 1 and self.min_pixels >= 1):
            raise PolarsegError("min_uncertainty must be in [0, 1] and min_pixels >= 1")


@dataclass(frozen=True)
class Suggestion:
    """The region to paint next.

    Attributes
    ----------
    region : ndarray (H, W) bool
        Its pixels.
    centre : tuple of int
        (row, column) of its deepest pixel: inside the region, where the view centres.
    pixels : int
        Its size.
    mean_uncertainty : float
        Mean (unsmoothed) uncertainty over it.
    bbox : tuple of int
        (row0, col0, row1, col1), the end exclusive.
    """

    region: np.ndarray
    centre: tuple[int, int]
    pixels: int
    mean_uncertainty: float
    bbox: tuple[int, int, int, int]


def _smoothed(u: np.ndarray, allowed: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian mean of ``u`` over the allowed pixels only (normalised convolution:
    G * (u·a) / G * a), so left-out pixels do not leak into their neighbours."""
    if sigma <= 0:
        return u
    weight = allowed.astype(np.float32)
    num = ndimage.gaussian_filter(u * weight, sigma)
    den = ndimage.gaussian_filter(weight, sigma)
    return np.where(den > 1e-6, num / np.maximum(den, 1e-6), np.float32(0.0))


def paint_here_next(
    uncertainty: np.ndarray,
    painted: np.ndarray | None = None,
    valid: np.ndarray | None = None,
    params: SuggestionParams | None = None,
) -> Suggestion | None:
    """The connected region of highest summed uncertainty (module docstring).

    Parameters
    ----------
    uncertainty : array (H, W) in [0, 1]
        The classifier's uncertainty per pixel.
    painted : array (H, W), optional
        The scribbles: non-zero pixels are never suggested (nor are their 2-pixel
        neighbours: a stroke's edge is not a new place to paint).
    valid : array (H, W) bool, optional
        The used pixels (others are never suggested).
    params : SuggestionParams, optional

    Returns
    -------
    Suggestion or None
        None when no region of ``min_pixels`` pixels is uncertain enough.
    """
    params = params or SuggestionParams()
    u = np.asarray(uncertainty, dtype=np.float32)
    if u.ndim != 2:
        raise PolarsegError(f"the uncertainty must be one 2-D map, got shape {u.shape}")
    finite = np.isfinite(u)
    u = np.where(finite, u, np.float32(0.0))
    allowed = finite.copy()
    if valid is not None:
        allowed &= np.asarray(valid, dtype=bool)
    if painted is not None:
        allowed &= ~ndimage.binary_dilation(np.asarray(painted) != 0, iterations=2)
    if not allowed.any():
        return None
    smooth = _smoothed(u, allowed, params.smoothing)
    typical, high = np.quantile(smooth[allowed], [0.5, 1.0 - params.top_share])
    level = max(0.5 * (typical + high), params.min_uncertainty)
    candidates = allowed & (smooth >= level)
    regions, n = ndimage.label(candidates, structure=np.ones((3, 3), bool))
    if n == 0:
        return None
    index = np.arange(1, n + 1)
    sizes = ndimage.sum_labels(np.ones_like(u), regions, index)
    totals = np.where(sizes >= params.min_pixels, ndimage.sum_labels(u, regions, index), -1.0)
    best = int(np.argmax(totals))
    if totals[best] < 0:
        return None
    region = regions == best + 1
    box = ndimage.find_objects(regions, max_label=best + 1)[best]
    assert box is not None
    # the deepest pixel, on the region's bounding box only (padded: its edge is outside)
    depth = ndimage.distance_transform_edt(np.pad(region[box], 1))[1:-1, 1:-1]
    r, c = np.unravel_index(int(np.argmax(depth)), depth.shape)
    centre = (int(r) + box[0].start, int(c) + box[1].start)
    bbox = (box[0].start, box[1].start, box[0].stop, box[1].stop)
    mean = float(u[region].mean())
    return Suggestion(region, centre, int(sizes[best]), mean, bbox)
