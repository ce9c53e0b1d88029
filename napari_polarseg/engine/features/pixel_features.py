"""Per-pixel feature stacks from the polarisation image, at several scales.

The thesis segments w × w blocks. A pixel classifier (ilastik, napari-apoc, convpaint)
instead describes every pixel by filters of the image at a few scales, so its labels
follow the material boundaries rather than the block grid. This module computes such a
stack from the polarisation image (Î, ρ, φ) of
:func:`~napari_polarseg.engine.physics.polarimage.polarisation_image`.

The linear Stokes components of eq. 3.14, I(α) = Î (1 + ρ cos(2α − 2φ)), are
``S0 = Î``, ``S1 = Î ρ cos 2φ``, ``S2 = Î ρ sin 2φ`` (units of the input; the S0 of
this module is the *mean* intensity, half the usual total-intensity S0). Smoothing the
Stokes components before taking the degree of linear polarisation,

    DoLP_σ = |(G_σ * S1, G_σ * S2)| / (G_σ * S0),

averages the noise out of the vector before its length is taken, so it carries no
upward noise bias (unlike G_σ * ρ); the two together measure how coherent the
polarisation is inside the window. Feature groups
(:data:`~.pixel_feature_params.GROUPS`; their parameters: :mod:`.pixel_feature_params`),
each at every scale σ (pixels):

- ``intensity``: log(G_σ * Î) and its local contrast √(G_σ(log² Î) − (G_σ log Î)²);
- ``polarisation``: DoLP_σ (above), G_σ * ρ, the local spread of ρ and the AoLP
  coherence |G_σ * e^{2iφ}|;
- ``zenith``: θ, the diffuse zenith (eq. 3.13, radians) of DoLP_σ at the assumed n —
  a monotonic function of DoLP_σ, so it adds nothing to a tree classifier; kept for
  linear models and for reading importances in physical terms;
- ``filters``: the ilastik / APOC filter set on log Î and on ρ — difference of
  Gaussians (G_σ − G_1.6σ), gradient magnitude, Laplacian, the two eigenvalues of the
  structure tensor and of the Hessian;
- ``regions``: the mean of every other feature of σ ≤ 4 over the pixel's superpixel
  (:func:`~.superpixels.polarisation_superpixels`: regions of ``region_area`` px whose
  borders follow intensity and polarisation edges), named
  ``"region:<feature>@<σ>"`` — what the whole patch of surface looks like, not only the
  pixel's neighbourhood, so one material's shades share a description;
- ``invariant``: features that do not change with the shading level — DoLP_σ / G_σ ρ
  (polarisation coherence), spread of ρ / G_σ ρ, the slope and correlation of ρ
  against log Î in the window (within one material the two vary together with the
  zenith, thesis section 6.2), and ρ relative to its surround (G_σ ρ / G_2σ ρ).

At σ ≥ 4 every local mean is taken on a block-averaged grid (factor 2 at σ = 4 and 8,
4 at σ = 16, :func:`pyramid_factor`): 4–16× fewer pixels to filter, within 0.5 % of
the feature's range of full-resolution filtering (tested). The finished features stay
on that grid and are interpolated back only at the pixels a reader asks for
(:mod:`.feature_stack`, :func:`~.feature_stack.upsample`). Every G_σ is
:func:`.gaussian.gaussian_filter` (SciPy's kernel at truncate 3, filtered in float32).
Every feature is float32;
names are ``"<feature>@<σ>"`` with an optional ``"<channel>:"`` prefix for
multi-channel inputs.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from functools import lru_cache
from typing import Any

import numpy as np

from ..errors import PolarsegError
from ..physics.fresnel import zenith_from_diffuse_dop
from .feature_stack import FeatureStack, GridBlock, RegionBlock, upsample
from .gaussian import gaussian_filter
from .pixel_feature_params import PixelFeatureParams
from .superpixels import polarisation_superpixels

#: Scales (σ ≤ this, pixels) whose features the ``regions`` group averages.
REGION_MAX_SIGMA = 4.0
#: Most threads :func:`pixel_features` computes scales on.
MAX_FEATURE_THREADS = 4
#: Below this σ (pixels) a map is filtered at full resolution.
PYRAMID_MIN_SIGMA = 4.0
#: Floor added to ρ and DoLP before a ratio (ρ of a pixel is rarely exactly 0).
EPS_DOP = 1e-4
#: Floor of Î before its logarithm (units of the input).
EPS_INTENSITY = 1e-6


#: Largest block side :func:`block_mean` sums by strided slices (numpy sums fewer than
#: 8 values one after the other, so up to there the slices add in its order).
SLICED_BLOCK = 4


def block_mean(a: np.ndarray, f: int) -> np.ndarray:
    """Mean of f × f blocks (float32); the edge blocks repeat their last row/column.

    Up to :data:`SLICED_BLOCK`, each block row's columns are added, then the rows, as
    strided slices: the order of ``mean(axis=(1, 3))`` on the blocks, so the same values
    to the bit, in a third of its time (numpy's reduction over two strided axes is slow).
    """
    h, w = a.shape
    hh, ww = -(-h // f) * f, -(-w // f) * f
    padded = np.pad(a, ((0, hh - h), (0, ww - w)), mode="edge")
    if f > SLICED_BLOCK:
        return padded.reshape(hh // f, f, ww // f, f).mean(axis=(1, 3), dtype=np.float32)
    padded = padded.astype(np.float32, copy=False)  # added in float32, as the mean does
    total = None
    for i in range(f):
        rows = padded[i::f]
        row = rows[:, 0::f].astype(np.float32)
        for j in range(1, f):
            row += rows[:, j::f]
        total = row if total is None else total + row
    return total / np.float32(f * f)


def pyramid_factor(sigma: float) -> int:
    """Grid coarsening used at scale ``sigma``: 1 below σ = 4, 2 up to σ = 16, then
    2^⌊log2(σ/4)⌋ (keeps the filter at ≥ 2 coarse pixels, error ≤ 0.2 % of the range)."""
    if sigma < PYRAMID_MIN_SIGMA:
        return 1
    return max(2, 2 ** int(math.floor(math.log2(sigma / 4))))


def level_sigma(sigma: float, f: int) -> float:
    """σ to filter with on the f-times coarser grid for an effective σ on the fine one.

    Block averaging and linear interpolation back each blur by about f²/8 px²
    (variance), so the coarse filter supplies the rest: √(σ² − f²/4) / f.
    """
    if f == 1:
        return float(sigma)
    return math.sqrt(max(sigma**2 - f**2 / 4.0, 0.25)) / f


def gaussian_smooth(a: np.ndarray, sigma: float) -> np.ndarray:
    """G_σ * a (float32), through a coarser grid for σ ≥ 8 (module docstring)."""
    f = pyramid_factor(sigma)
    a = np.asarray(a, dtype=np.float32)
    small = a if f == 1 else block_mean(a, f)
    out = gaussian_filter(small, level_sigma(sigma, f))
    return upsample(out, f, a.shape)


def _smooth(a: np.ndarray, s: float) -> np.ndarray:
    return gaussian_filter(a, s)


def _filters(x: np.ndarray, s: float, f: int) -> dict[str, np.ndarray]:
    """The ilastik/APOC filter set of ``x`` at grid scale s, in fine-pixel units.

    Difference of Gaussians (G_σ − G_1.6σ), gradient magnitude |∇G_σ x|, Laplacian
    ∇²G_σ x, the larger and smaller eigenvalues of the structure tensor G_σ(∇x ∇xᵀ)
    (gradients at the inner scale σ/2) and of the Hessian of G_σ x. Derivatives on a
    grid f times coarser are divided by f (first) or f² (second order).
    """
    g = _smooth(x, s)
    gr, gc = np.gradient(g)
    rr, rc = np.gradient(gr)
    cc = np.gradient(gc, axis=1)
    inner = _smooth(x, max(s / 2, 0.5))
    ir, ic = np.gradient(inner)
    jrr, jcc, jrc = (_smooth(v, s) for v in (ir * ir, ic * ic, ir * ic))
    st_mean, st_half = (jrr + jcc) / 2, np.hypot((jrr - jcc) / 2, jrc)
    h_mean, h_half = (rr + cc) / 2, np.hypot((rr - cc) / 2, rc)
    f1, f2 = float(f), float(f * f)
    return {
        "dog": g - _smooth(x, 1.6 * s),
        "gradient": np.hypot(gr, gc) / f1,
        "laplacian": (rr + cc) / f2,
        "structure_max": (st_mean + st_half) / f2,
        "structure_min": (st_mean - st_half) / f2,
        "hessian_max": (h_mean + h_half) / f2,
        "hessian_min": (h_mean - h_half) / f2,
    }


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    return num / (den + EPS_DOP)


def _spread(mean_sq: np.ndarray, mean: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(mean_sq - mean * mean, 0))


#: Per-pixel products whose local means the features need (names used below).
MOMENTS = ("s0", "s1", "s2", "dop", "dop2", "cos2", "sin2", "logi", "logi2", "logi_dop")


#: Moments each group needs.
GROUP_MOMENTS = {
    "intensity": ("s0", "logi", "logi2"),
    "polarisation": ("s0", "s1", "s2", "dop", "dop2", "cos2", "sin2"),
    "zenith": ("s0", "s1", "s2"),
    "filters": ("logi", "dop"),
    "invariant": ("s0", "s1", "s2", "dop", "dop2", "logi", "logi2", "logi_dop"),
    "regions": (),
}


#: Most pixels the log Î centre is the median of (:func:`log_centre_of_logs`).
LOG_CENTRE_SAMPLES = 1 << 23


def centre_sample_step(n_pixels: int) -> int:
    """Every how many pixels (raster order) the log Î centre reads: 1 up to
    :data:`LOG_CENTRE_SAMPLES` pixels (8.4 MP), then ⌈n / that⌉."""
    return max(1, -(-int(n_pixels) // LOG_CENTRE_SAMPLES))


def centre_sample(a: np.ndarray) -> np.ndarray:
    """The pixels of ``a`` (H, W) the log Î centre reads, flat: every
    :func:`centre_sample_step`-th one in raster order (a view where ``a`` is
    contiguous, so a large image's map in a temporary file is read only there)."""
    step = centre_sample_step(a.size)
    flat = np.asarray(a).reshape(-1)
    return flat if step == 1 else flat[::step]


def log_centre_of_logs(log_i: np.ndarray) -> np.float32:
    """The centre of log Î given its values (H, W): the median of their
    :func:`centre_sample` (all of them up to :data:`LOG_CENTRE_SAMPLES` pixels). The
    centre only keeps the float32 moments of log Î near 0 (the features do not depend
    on it but for rounding), so a sample serves, and an image and its tiles share it
    without reading it twice."""
    return np.float32(np.median(centre_sample(log_i)))


def log_intensity_centre(intensity: np.ndarray) -> np.float32:
    """:func:`log_centre_of_logs` of log Î over the image (float32; Î floored at
    :data:`EPS_INTENSITY`, non-finite Î as 0): what :func:`pixel_features` subtracts from
    log Î before taking its moments. Reads only the sampled pixels."""
    i = np.asarray(centre_sample(intensity), dtype=np.float32)
    log_i = np.log(np.maximum(np.where(np.isfinite(i), i, 0), EPS_INTENSITY))
    return np.float32(np.median(log_i))


def _moments(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    groups: Sequence[str],
    log_centre: float | None = None,
) -> dict[str, np.ndarray]:
    """The per-pixel products (:data:`MOMENTS`) the chosen groups need; log Î minus
    ``log_centre`` (default: :func:`log_centre_of_logs` of these pixels)."""
    need = {m for g in groups for m in GROUP_MOMENTS[g]}
    log_i = np.log(np.maximum(intensity, EPS_INTENSITY))
    # centred on the image's median: local variances and covariances of log Î are
    # differences of means, which lose float32 digits when log Î is far from 0
    log_i -= log_centre_of_logs(log_i) if log_centre is None else np.float32(log_centre)
    c, s = np.cos(2 * phase), np.sin(2 * phase)
    make = {
        "s0": lambda: intensity,
        "s1": lambda: intensity * dop * c,
        "s2": lambda: intensity * dop * s,
        "dop": lambda: dop,
        "dop2": lambda: dop * dop,
        "cos2": lambda: c,
        "sin2": lambda: s,
        "logi": lambda: log_i,
        "logi2": lambda: log_i * log_i,
        "logi_dop": lambda: log_i * dop,
    }
    return {k: make[k]() for k in MOMENTS if k in need}


def _level_features(
    m: dict[str, np.ndarray], sigma: float, f: int, params: PixelFeatureParams
) -> dict[str, np.ndarray]:
    """Every feature of the chosen groups at scale σ from the moments on grid level f."""
    s = level_sigma(sigma, f)
    groups = params.groups
    smoothed = {m for g in groups if g != "filters" for m in GROUP_MOMENTS[g]}
    g = {k: _smooth(v, s) for k, v in m.items() if k in smoothed}
    if {"s1", "s2"} <= g.keys():
        dolp = np.hypot(g["s1"], g["s2"]) / np.maximum(g["s0"], EPS_INTENSITY)
    if "logi2" in g:
        var_log = np.maximum(g["logi2"] - g["logi"] ** 2, 0)
    if "dop2" in g:
        rho = g["dop"]
        var_rho = np.maximum(g["dop2"] - rho * rho, 0)
    out: dict[str, np.ndarray] = {}
    if "intensity" in groups:
        out["log_intensity"] = np.log(np.maximum(g["s0"], EPS_INTENSITY))
        out["intensity_contrast"] = np.sqrt(var_log)
    if "polarisation" in groups:
        out["dolp"] = dolp
        out["dop"] = rho
        out["dop_spread"] = np.sqrt(var_rho)
        out["aolp_coherence"] = np.hypot(g["cos2"], g["sin2"])
    if "zenith" in groups:
        out["zenith"] = zenith_from_diffuse_dop(dolp, params.refractive_index).zenith
    if "filters" in groups:
        for source in ("logi", "dop"):
            name = "log_intensity" if source == "logi" else "dop"
            for filt, v in _filters(m[source], s, f).items():
                out[f"{name}_{filt}"] = v
    if "invariant" in groups:
        cov = g["logi_dop"] - g["logi"] * rho
        out["dolp_over_dop"] = _ratio(dolp, rho)
        out["dop_spread_over_dop"] = _ratio(np.sqrt(var_rho), rho)
        out["dop_vs_log_intensity_slope"] = cov / (var_log + 1e-6)
        out["dop_vs_log_intensity_corr"] = cov / np.sqrt(var_log * var_rho + 1e-12)
        out["dop_over_surround"] = _ratio(rho, _smooth(m["dop"], 2 * s))
    return out


def check_maps(intensity: Any, dop: Any, phase: Any) -> tuple[np.ndarray, ...]:
    """Î, ρ, φ as float32 (H, W) of one shape, non-finite values set to 0 (raises
    PolarsegError on other shapes)."""
    maps = [np.array(a, dtype=np.float32) for a in (intensity, dop, phase)]  # copies
    if maps[0].ndim != 2 or any(m.shape != maps[0].shape for m in maps):
        shapes = ", ".join(str(m.shape) for m in maps)
        raise PolarsegError(f"intensity, dop and phase must be 2-D of one shape, got {shapes}")
    for m in maps:
        bad = ~np.isfinite(m)
        if bad.any():
            m[bad] = 0
    return tuple(maps)


def pixel_features(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    params: PixelFeatureParams | None = None,
    *,
    channel: str = "",
    progress: Callable[[float], None] | None = None,
    regions: np.ndarray | Callable[[], np.ndarray] | None = None,
    log_centre: float | None = None,
) -> FeatureStack:
    """The feature stack of one polarisation image.

    Parameters
    ----------
    intensity, dop, phase : array (H, W)
        Î (units of the input), ρ in [0, 1], φ radians (thesis eq. 3.14).
    params : PixelFeatureParams, optional
        Scales and groups (default ``PixelFeatureParams()``).
    channel : str, optional
        Name prefix ``"<channel>:"`` for multi-channel inputs.
    progress : callable(share), optional
        Called with the share of the scales done after each (it may raise to stop).
    regions : array (H, W) int or callable, optional
        The superpixels (0 … n − 1) of the ``regions`` group, or a function giving them
        (called once the other features are made, so a caller may draw them on another
        thread meanwhile). Default: :func:`~.superpixels.polarisation_superpixels` of
        ``params.regions_of`` the image's shape.
    log_centre : float, optional
        Subtracted from log Î (:func:`log_intensity_centre`; a tile passes its image's).

    Returns
    -------
    FeatureStack
        float32 features, ``names[f] = "<feature>@<σ>"``; the σ ≥ 4 features kept on
        their coarse grid, the region means per region (:mod:`.feature_stack`).

    Examples
    --------
    >>> import numpy as np
    >>> f = pixel_features(np.ones((16, 16)), np.full((16, 16), 0.1), np.zeros((16, 16)),
    ...                    PixelFeatureParams(scales=(1.0,), groups=("polarisation",)))
    >>> f.names[:2], round(float(f.plane("dolp@1")[8, 8]), 4)
    (('dolp@1', 'dop@1'), 0.1)
    """
    params = params or PixelFeatureParams()
    i, d, p = check_maps(intensity, dop, phase)
    prefix = f"{channel}:" if channel else ""
    if "regions" not in params.groups:
        labels = None
    elif regions is None:
        labels = _once(lambda: polarisation_superpixels(i, d, p, params.regions_of(i.shape)))
    else:
        labels = _once(regions if callable(regions) else lambda: regions)
    levels = {1: _moments(i, d, p, params.groups, log_centre)}
    # a scale a thread (numpy releases the GIL); its region means there too
    with ThreadPoolExecutor(feature_threads()) as pool:

        def submit(sigma: float) -> Future:
            level = levels[pyramid_factor(sigma)]
            return pool.submit(_scale_block, level, sigma, params, i.shape, labels)

        made = {s: submit(s) for s in params.scales if pyramid_factor(s) == 1}
        # meanwhile the coarser levels, a moment a thread where no full-resolution
        # scale keeps the pool busy
        factors = {pyramid_factor(s) for s in params.scales}
        _add_levels(levels, factors, None if made else pool)
        made.update({s: submit(s) for s in params.scales if s not in made})
        parts = []
        for n, sigma in enumerate(params.scales):
            parts.append(made[sigma].result())
            if progress is not None:
                progress(0.9 * (n + 1) / len(params.scales))
    blocks: list[GridBlock | RegionBlock] = [block for block, _, _ in parts]
    names = [name for _, block_names, _ in parts for name in block_names]
    means = [m for _, _, m in parts if m is not None]
    if means:
        blocks.append(RegionBlock(np.concatenate(means), labels()))
        names += [f"region:{n}" for n in names if _scale_of(n) <= REGION_MAX_SIGMA]
    return FeatureStack(tuple(blocks), tuple(f"{prefix}{n}" for n in names), params)


def _add_levels(
    levels: dict[int, dict[str, np.ndarray]],
    factors: set[int],
    pool: ThreadPoolExecutor | None,
) -> None:
    """Add to ``levels`` (pyramid factor → moments) every factor of ``factors`` it lacks,
    each block-averaged from the finest level already there that divides it; with
    ``pool``, one moment a thread."""
    for f in sorted(factors):
        if f not in levels:
            base = max(q for q in levels if f % q == 0)
            means = (map if pool is None else pool.map)(
                lambda v, n=f // base: block_mean(v, n), levels[base].values()
            )
            levels[f] = dict(zip(levels[base], means, strict=True))


def _once(make: Callable[[], Any]) -> Callable[[], np.ndarray]:
    """``make()`` called once, by whichever thread asks first (the others wait)."""
    lock, box = threading.Lock(), []

    def get() -> np.ndarray:
        with lock:
            if not box:
                box.append(np.asarray(make()))
            return box[0]

    return get


def feature_threads() -> int:
    """Threads :func:`pixel_features` computes the scales on: the cores, at most
    :data:`MAX_FEATURE_THREADS` (each holds a scale's temporaries)."""
    return max(1, min(os.cpu_count() or 1, MAX_FEATURE_THREADS))


def _scale_block(
    level: dict[str, np.ndarray],
    sigma: float,
    params: PixelFeatureParams,
    shape: tuple[int, int],
    regions: Callable[[], np.ndarray] | None,
) -> tuple[GridBlock, list[str], np.ndarray | None]:
    """The features of scale σ (a :class:`GridBlock` on the level's grid), their names
    and, for σ ≤ :data:`REGION_MAX_SIGMA` with ``regions`` (a function giving the
    superpixels), their means over every region (else None), from the moments
    ``level`` of its pyramid factor."""
    f = pyramid_factor(sigma)
    made = _level_features(level, sigma, f, params)
    values = np.empty((len(made), -(-shape[0] // f), -(-shape[1] // f)), dtype=np.float32)
    for j, v in enumerate(made.values()):
        values[j] = v
    block, names = GridBlock(values, f, shape), [f"{name}@{sigma:g}" for name in made]
    means = None
    if regions is not None and sigma <= REGION_MAX_SIGMA:
        means = FeatureStack((block,), tuple(names)).region_means(regions())
    return block, names, means


def _scale_of(name: str) -> float:
    return float(name.rsplit("@", 1)[1])


def _radius(sigma: float) -> int:
    """Pixels each way a Gaussian of ``sigma`` reads (SciPy: ⌊3 σ + ½⌋ at truncate 3)."""
    return int(3.0 * sigma + 0.5)


def feature_reach(params: PixelFeatureParams, largest: float | None = None) -> int:
    """Pixels each way a feature of ``params`` reads: beyond it, no pixel changes any
    feature of the scales σ ≤ ``largest`` (default: all of them).

    At scale σ on the grid of factor f = :func:`pyramid_factor` (σ_f =
    :func:`level_sigma`), the longest chain of filters is the widest of the Gaussian
    of 2 σ_f (the surround of ``dop_over_surround``), of 1.6 σ_f (the difference of
    Gaussians) and of σ_f / 2 then σ_f (the structure tensor), each reading
    r(σ) = ⌊3 σ + ½⌋ cells, plus two cells of gradients; the block means and the
    interpolation back read one more cell each: reach = f · (r + 4) pixels.
    """
    reach = 0
    for sigma in params.scales:
        if largest is not None and sigma > largest:
            continue
        f = pyramid_factor(sigma)
        s = level_sigma(sigma, f)
        chain = max(_radius(2 * s), _radius(1.6 * s), _radius(max(s / 2, 0.5)) + _radius(s) + 1)
        reach = max(reach, f * (chain + 4))
    return reach


def largest_factor(params: PixelFeatureParams) -> int:
    """The coarsest grid of ``params``' scales: max f of :func:`pyramid_factor`."""
    return max(pyramid_factor(s) for s in params.scales)


@lru_cache(maxsize=16)
def feature_names(params: PixelFeatureParams) -> tuple[str, ...]:
    """Names of the features :func:`pixel_features` computes for ``params`` (no prefix),
    in order (found by running the groups on a tiny image, 0.4 ms: kept per ``params``,
    a frozen dataclass of hashable fields, which a large image's every tile asks for)."""
    tiny = np.ones((8, 8), dtype=np.float32)
    m = _moments(tiny, 0.1 * tiny, 0 * tiny, params.groups)
    names = [
        f"{name}@{sigma:g}"
        for sigma in params.scales
        for name in _level_features(m, sigma, 1, params)
    ]
    if "regions" in params.groups:
        names += [f"region:{n}" for n in names if _scale_of(n) <= REGION_MAX_SIGMA]
    return tuple(names)


def multichannel_features(
    images: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    params: PixelFeatureParams | None = None,
    channels: Sequence[str] | None = None,
    regions: np.ndarray | Callable[[], np.ndarray] | None = None,
    log_centres: Sequence[float] | None = None,
) -> FeatureStack:
    """Features of every channel's polarisation image side by side.

    ``images[c] = (Î, ρ, φ)`` of channel c (e.g. each colour of a colour-polarisation
    sensor); names carry the channel name (``channels[c]``, default ``"c0"``, ``"c1"``…).
    ``regions``: the superpixels every channel's ``regions`` group averages over (as in
    :func:`pixel_features`; default: each channel's own). ``log_centres``: each
    channel's ``log_centre`` (:func:`pixel_features`; default each one's median).
    """
    if not images:
        raise PolarsegError("no channels to compute features of")
    if channels is None:
        channels = [""] if len(images) == 1 else [f"c{k}" for k in range(len(images))]
    channels = list(channels)
    if len(channels) != len(images):
        raise PolarsegError(f"{len(images)} channels but {len(channels)} channel names")
    if callable(regions):
        regions = _once(regions)  # the first channel to need them waits
    centres = [None] * len(images) if log_centres is None else list(log_centres)
    stacks = [
        pixel_features(*im, params, channel=c, regions=regions, log_centre=m)
        for im, c, m in zip(images, channels, centres, strict=True)
    ]
    return stacks[0] if len(stacks) == 1 else FeatureStack.joined(stacks)
