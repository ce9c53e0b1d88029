"""Polarisation texture of the unsupervised methods: how grainy ρ, the AoLP and log Î are
at the scale of one pixel.

Materials that share their albedo and refractive index can still differ in the relief
of their surface (a lacquer rolled, stippled or spattered; a moulded leaf against a
waxy one): the facets' normals then vary from pixel to pixel, and with them ρ and φ.
How fast they vary is a material cue that does not change with the amount of light.
Each map is a Gaussian-weighted local statistic (σ = :data:`GRAIN_SIGMA` px) of the
semivariogram γ_x = ½ (x(p) − x(q))², q the one of p's four neighbours at the lag that
differs least from it (:func:`neighbour_variogram`: an edge beside p leaves a neighbour
on p's side, so its step does not count); unitless for ρ and the phasor, log Î in
nepers²:

- ``grain_dop``: γ_ρ(1) / (γ_ρ(1) + γ_ρ(2)), at lags 1 and 2 px: about ½ where ρ varies
  from pixel to pixel (a relief finer than a pixel, noise), near 0 where it varies
  smoothly (a coarse relief, shading), whatever the amount of variation;
- ``grain_aolp``: γ(1) of the AoLP phasor e^{2iφ} (its cos and sin averaged), 0 for a
  uniform AoLP and the larger the more the AoLP changes from pixel to pixel;
- ``grain_intensity``: log γ(1) of log Î.

Dark pixels are noisier, so every map rises in the shadows: the node features
(:func:`texture_features`) are the region means less their image-wide cubic fit on the
regions' mean log Î (the same fit as ``log_dop_given_intensity``), so that what is left
is the texture a region has beyond what its brightness gives it.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

#: σ (px) of the Gaussian window of the grain maps: wide enough for a variance of a few
#: dozen pixels, narrow beside the smallest objects of the bench (about 12 px).
GRAIN_SIGMA = 3.0
#: Node features of the texture group, in the order :func:`grain_maps` makes their maps.
TEXTURE_FEATURES = ("dop_grain", "aolp_grain", "intensity_grain")
#: Per-pixel terms the texture features read (keys of :func:`grain_maps`).
GRAIN_TERMS = ("grain_dop", "grain_aolp", "grain_intensity")
#: Floor of γ of log Î before its logarithm.
EPS_GRAIN = 1e-8
#: Pixels each grain map reads each way: the lag-2 neighbours and the Gaussian window
#: (SciPy's default truncation, 4 σ).
GRAIN_REACH = 2 + int(4 * GRAIN_SIGMA + 0.5)


def reads_grain(names: tuple[str, ...]) -> bool:
    """Whether node features ``names`` read the grain maps (any of :data:`TEXTURE_FEATURES`)."""
    return any(name in TEXTURE_FEATURES for name in names)


def neighbour_variogram(a: np.ndarray, lag: int = 1) -> np.ndarray:
    """Per pixel, half the smallest of the squared differences to the four neighbours
    ``lag`` px away (left, right, up, down; the border repeats the edge pixel), float64:
    γ at that lag where the pixel lies inside a surface, and not the step across an
    edge beside it (a straight or staircase edge leaves at least one neighbour on the
    pixel's side). Written with slices: no library gives a per-pixel semivariogram."""
    a = np.asarray(a, dtype=np.float64)
    p = np.pad(a, lag, mode="edge")
    h, w = a.shape
    core = p[lag : lag + h, lag : lag + w]
    out = np.full(a.shape, np.inf)
    for dr, dc in ((0, -lag), (0, lag), (-lag, 0), (lag, 0)):
        shifted = p[lag + dr : lag + dr + h, lag + dc : lag + dc + w]
        np.minimum(out, (core - shifted) ** 2, out=out)
    return 0.5 * out


def grain_maps(
    log_intensity: np.ndarray, dop: np.ndarray, cos2: np.ndarray, sin2: np.ndarray
) -> dict[str, np.ndarray]:
    """The grain maps (module docstring) of log Î, ρ and the AoLP phasor (cos 2φ,
    sin 2φ), float32 (H, W), keyed as :data:`GRAIN_TERMS`."""

    def local(x: np.ndarray) -> np.ndarray:
        return gaussian_filter(x, GRAIN_SIGMA, mode="nearest")

    g1, g2 = local(neighbour_variogram(dop)), local(neighbour_variogram(dop, 2))
    g_aolp = local(0.5 * (neighbour_variogram(cos2) + neighbour_variogram(sin2)))
    g_int = local(neighbour_variogram(log_intensity))
    return {
        "grain_dop": (g1 / (g1 + g2 + EPS_GRAIN)).astype(np.float32),
        "grain_aolp": g_aolp.astype(np.float32),
        "grain_intensity": np.log(g_int + EPS_GRAIN).astype(np.float32),
    }


def texture_features(
    means: dict[str, np.ndarray], weight: np.ndarray, names: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """The texture node features among ``names`` (of :data:`TEXTURE_FEATURES`): the
    regions' means of the grain maps (``means``, keyed as :data:`GRAIN_TERMS`, with
    ``"l"`` the regions' mean log Î) less their fit on it (:func:`given_intensity`,
    weighted by ``weight``, the regions' areas)."""
    return {
        name: given_intensity(means[term], means["l"], weight)
        for name, term in zip(TEXTURE_FEATURES, GRAIN_TERMS, strict=True)
        if name in names
    }


def given_intensity(
    y: np.ndarray, log_intensity: np.ndarray, weight: np.ndarray, degree: int = 3
) -> np.ndarray:
    """y − f(log Î), f the polynomial of ``degree`` fitted over all regions (least
    squares weighted by ``weight``): what of a region's y its brightness does not
    explain."""
    x = log_intensity - np.average(log_intensity, weights=weight)
    scale = max(float(np.sqrt(np.average(x * x, weights=weight))), 1e-12)
    # no higher degree than the distinct brightnesses allow (a flat, noise-free frame)
    degree = max(min(degree, np.unique(np.round(x / scale, 6)).size - 1), 0)
    coef = np.polynomial.polynomial.polyfit(x / scale, y, degree, w=np.sqrt(weight))
    return y - np.polynomial.polynomial.polyval(x / scale, coef)
