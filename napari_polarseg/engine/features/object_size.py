"""The typical object size of a scene, estimated from its polarisation image alone.

Like cellpose's *diameter*: one number, the typical diameter in pixels of an object in
the scene, from which the spatial scales of the segmentation methods (superpixel area,
feature-diffusion reach, smoothing) are derived. No truth is used.

Method: scale selection in a Laplacian-of-Gaussian scale space (Lindeberg 1998,
"Feature detection with automatic scale selection", the scale selection of
scikit-image's ``blob_log``), pooled over three channels of the polarisation image.

1. **Channels** (dimensionless): c₁ = ln Î, c₂ = ρ cos 2φ, c₃ = ρ sin 2φ (the normalised
   Stokes components s₁/s₀, s₂/s₀; φ in radians). The log makes shading a factor and
   both materials' contrasts ratios. Each channel is divided by its noise σₙ
   (:func:`noise_sd`, the robust spread of its 5-point Laplacian), so the channels are in
   noise units and the pooled response weighs each channel by its signal-to-noise ratio;
   and a least-squares plane is removed (:func:`remove_plane`): a linear ramp of shading
   has no Laplacian, but its ends at the frame border would.
2. **Scale space**: the scale-normalised LoG energy, pooled over the channels,

       S(x, σ) = Σ_c (σ² ∇²(G_σ ∗ c)(x))²          (σ in px, ∇² in px⁻²: S dimensionless)

   on a grid of :data:`SCALES_PER_OCTAVE` scales per octave from σ = 1 px up to a quarter
   of the short side of the usable area (an octave pyramid of 2 × 2 block means makes
   the large scales cheap).
3. **Characteristic scale**: at each pixel σ*(x) = argmax_σ S(x, σ), refined by a
   parabola in log σ. At the centre of a disc of diameter D it is σ* = D / (2√2)
   (Lindeberg's blob radius r = √2 σ); a pixel a distance d inside a straight edge has
   σ* ≈ d. A pixel *votes* when its response stands out of the noise,
   S(x, σ*) > k² C N(σ*) with k = :data:`NOISE_FACTOR`, C the number of channels and
   N(σ) the energy of white noise of unit variance at that scale
   (:func:`noise_energy`), and when σ* is not the largest scale of the grid (a response
   still rising there belongs to a region wider than the grid reaches: the floor, the
   sky, a shading trend). Its weight is w(x) = √S(x, σ*), its contrast in noise units:
   flat or noisy areas do not vote, a faint shading gradient votes weakly, material
   edges vote strongly.
4. **Size**: the weighted median of the votes,

       D = 2√2 · median_w σ*(x)       [px of the input image]

Diagnostics (:class:`ObjectSize`): the diameter 2√2 σ of every scale of the grid
(``scales_px``), the share of the votes each scale got (``scores``, summing to 1) and the
share of the usable pixels that voted (``coverage``).

Large images are block-averaged to at most :data:`WORK_PIXELS` pixels first (an integer
factor f; scales and sizes are given back in pixels of the input), so the estimate
takes well under a second on a 1224 × 1024 frame. Invalid pixels (NaN, Î ≤ 0, outside
``mask``) take the value of the nearest usable pixel for the filters and never vote.

Not seen: objects told apart from their surroundings by their micro-texture alone (a
camouflage net in foliage, texture patches): the estimate is then the size of the
texture's grains, not of the patches.

Measured against the truth (the median equivalent diameter of the objects,
:func:`instance_size`, :func:`component_size`) in ``benchmarks/object_size.py``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import ndimage

from ..errors import PolarsegError
from ..physics.pixel_mask import fill_from_nearest

__all__ = [
    "MIN_INSTANCE_AREA",
    "ObjectSize",
    "component_size",
    "estimate_object_size",
    "instance_size",
    "noise_energy",
    "noise_sd",
    "remove_plane",
]

#: Instances (and components) smaller than this many pixels are not counted by
#: :func:`instance_size` and :func:`component_size`.
MIN_INSTANCE_AREA = 9
#: Scales per octave of the scale grid (a quarter octave: 19 % steps).
SCALES_PER_OCTAVE = 4
#: Largest scale σ as a share of the short side of the usable area (diameter 2√2 σ:
#: up to 0.7 of the short side).
MAX_SCALE_SHARE = 0.25
#: A pixel votes when its response exceeds NOISE_FACTOR² times the noise energy.
NOISE_FACTOR = 3.0
#: Most pixels the scale space is computed on; larger images are block-averaged.
WORK_PIXELS = 1 << 17
#: Diameter = DIAMETER_PER_SCALE · σ* (a disc of diameter D peaks at σ = D / (2√2)).
DIAMETER_PER_SCALE = 2.0 * math.sqrt(2.0)
#: Without any vote (no structure above the noise, or too few usable pixels) the size
#: is this share of √(usable area).
FALLBACK_SHARE = 0.25
#: Fewest usable pixels along each side of the working image for an estimate.
MIN_SIDE = 8
#: The channels of the scale space (names as :meth:`ObjectSize.describe` prints them).
CHANNELS = ("log Î", "ρ cos 2φ", "ρ sin 2φ")


@dataclass(frozen=True)
class ObjectSize:
    """The typical object diameter of a scene and how it was found.

    Attributes
    ----------
    size_px : float
        The object diameter D in pixels of the input image.
    estimated : bool
        True when estimated from the image (:func:`estimate_object_size`), False when
        given by the user (:meth:`given`).
    scales_px : tuple of float
        Diameter 2√2 σ (input px) of every scale σ of the scale grid.
    scores : tuple of float
        Share of the votes (weight √S of the pixels whose characteristic scale it is)
        each scale got; sums to 1 when any pixel voted.
    coverage : float
        Share of the usable pixels that voted (response above the noise).
    channels : tuple of str
        The channels that entered the scale space (a constant channel is left out).
    work_factor : int
        Block-averaging factor of the image the scale space was computed on.
    note : str
        Why the size is a fallback (empty for a real estimate or a given size).
    """

    size_px: float
    estimated: bool = True
    scales_px: tuple[float, ...] = ()
    scores: tuple[float, ...] = ()
    coverage: float = 0.0
    channels: tuple[str, ...] = ()
    work_factor: int = 1
    note: str = ""

    @classmethod
    def given(cls, size_px: float) -> ObjectSize:
        """A size the user set (px), not estimated."""
        return cls(size_px=float(size_px), estimated=False)

    @property
    def fallback(self) -> bool:
        """True when the estimate found no structure and gave the fallback size."""
        return self.estimated and bool(self.note)

    def describe(self) -> str:
        """One line for a user, e.g. ``object size 34 px (estimated from ...)``."""
        size = f"object size {self.size_px:.0f} px"
        if not self.estimated:
            return f"{size} (given)"
        if self.note:
            return f"{size} (fallback: {self.note})"
        work = f", on the image reduced {self.work_factor}×" if self.work_factor > 1 else ""
        return (
            f"{size} (estimated from the scale of the strongest Laplacian-of-Gaussian "
            f"response of {', '.join(self.channels)} at {self.coverage:.0%} of the "
            f"pixels{work})"
        )


# --- truth measures -------------------------------------------------------------------


def _median_diameter(areas: np.ndarray) -> float:
    areas = areas[areas >= MIN_INSTANCE_AREA]
    if areas.size == 0:
        return float("nan")
    return float(np.median(np.sqrt(4.0 * areas / np.pi)))


def instance_size(instances: np.ndarray) -> float:
    """Median equivalent diameter √(4A/π) (px) of the labelled instances.

    Parameters
    ----------
    instances : int array (H, W)
        Instance ids; ids > 0 are instances (an id may cover several disjoint parts,
        e.g. an occluded object: its area is the sum), 0 and negative ids are not.

    Returns
    -------
    float
        The median over the instances of at least :data:`MIN_INSTANCE_AREA` px of
        √(4A/π), A the instance's area in px; NaN when there is none.

    Examples
    --------
    >>> ids = np.zeros((10, 10), int); ids[:4, :4] = 1; ids[6:, 6:] = 7; ids[9, 0] = 3
    >>> round(instance_size(ids), 3)  # two 16 px squares; id 3 (1 px) is ignored
    4.514
    """
    ids = np.asarray(instances)
    if not np.issubdtype(ids.dtype, np.integer):
        raise PolarsegError(f"instances must be an integer array, got {ids.dtype}")
    _, areas = np.unique(ids[ids > 0], return_counts=True)
    return _median_diameter(areas)


def component_size(labels: np.ndarray, classes: Iterable[int]) -> float:
    """Median equivalent diameter √(4A/π) (px) of the connected components of the
    pixels whose label is in ``classes`` (truth without instance ids).

    Components are 4-connected (:func:`scipy.ndimage.label`); touching objects of
    these classes form one component. Components under :data:`MIN_INSTANCE_AREA` px
    are ignored; NaN when there is none.

    Examples
    --------
    >>> lab = np.zeros((10, 10), int); lab[:4, :4] = 2; lab[6:, 6:] = 3
    >>> round(component_size(lab, {2, 3}), 3), component_size(lab, {1})
    (4.514, nan)
    """
    comp, n = ndimage.label(np.isin(np.asarray(labels), list(classes)))
    return _median_diameter(np.bincount(comp.ravel(), minlength=n + 1)[1:])


# --- building blocks ------------------------------------------------------------------


def noise_sd(channel: np.ndarray, valid: np.ndarray | None = None) -> float:
    """Robust standard deviation of white noise in ``channel`` (its units).

    The 5-point Laplacian d = 4x − (sum of the 4 neighbours) of white noise of variance
    σₙ² has variance 20 σₙ²; smooth structure hardly enters it. So
    σₙ = 1.4826 MAD(d) / √20 over the pixels whose 5-point stencil is all ``valid``
    (1.2533 × mean absolute deviation when the MAD is 0, e.g. quantised data). 0 when
    the channel is constant or fewer than 9 stencils are usable.
    """
    x = np.asarray(channel, dtype=np.float64)
    if x.shape[0] < 3 or x.shape[1] < 3:
        return 0.0
    d = 4.0 * x[1:-1, 1:-1] - x[:-2, 1:-1] - x[2:, 1:-1] - x[1:-1, :-2] - x[1:-1, 2:]
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        ok = v[1:-1, 1:-1] & v[:-2, 1:-1] & v[2:, 1:-1] & v[1:-1, :-2] & v[1:-1, 2:]
        d = d[ok]
    d = d[np.isfinite(d)]
    if d.size < 9:
        return 0.0
    dev = np.abs(d - np.median(d))
    sd = 1.4826 * float(np.median(dev))
    if sd <= 0.0:
        sd = 1.2533 * float(np.mean(dev))
    return sd / math.sqrt(20.0)


def remove_plane(channel: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``channel`` minus its least-squares plane a + b·row + c·col over the ``valid``
    pixels (same units). A ramp of shading across the frame has no Laplacian inside,
    but the reflection at the frame border would turn its ends into creases."""
    h, w = channel.shape
    rows, cols = np.nonzero(valid)
    design = np.column_stack([np.ones(rows.size), rows / max(h, 1), cols / max(w, 1)])
    coef, *_ = np.linalg.lstsq(design, channel[rows, cols], rcond=None)
    yy, xx = np.mgrid[0:h, 0:w]
    return channel - (coef[0] + coef[1] * yy / max(h, 1) + coef[2] * xx / max(w, 1))


@lru_cache(maxsize=64)
def noise_energy(sigma: float) -> float:
    """Mean of (σ² ∇²G_σ ∗ n)² for white noise n of unit variance (dimensionless):
    σ⁴ Σ k² over the taps k of the discrete kernel of
    :func:`scipy.ndimage.gaussian_laplace` (≈ 1 / (2π σ²) for σ ≫ 1 px)."""
    r = int(4.0 * sigma + 0.5) + 1
    delta = np.zeros((2 * r + 1, 2 * r + 1))
    delta[r, r] = 1.0
    kernel = ndimage.gaussian_laplace(delta, sigma, mode="constant")
    return float(sigma**4 * np.sum(kernel**2))


def _raw_channels(
    i: np.ndarray, rho: np.ndarray, phi: np.ndarray, valid: np.ndarray
) -> list[np.ndarray]:
    """ln Î, ρ cos 2φ, ρ sin 2φ on the usable pixels (1, 0, 0 elsewhere), float64
    (computed in float64 whatever the inputs' dtype)."""
    i, rho, phi = (np.asarray(a, dtype=np.float64) for a in (i, rho, phi))
    with np.errstate(invalid="ignore"):
        return [
            np.log(np.where(valid, i, 1.0)),
            np.where(valid, rho * np.cos(2.0 * phi), 0.0),
            np.where(valid, rho * np.sin(2.0 * phi), 0.0),
        ]


#: Pixels of one band of rows whose channels are made and block-averaged at once in
#: :func:`_reduced_channels` (bounds their float64 temporaries on large images).
BAND_PIXELS = 1 << 21


def _reduced_channels(
    i: np.ndarray, rho: np.ndarray, phi: np.ndarray, valid: np.ndarray, f: int
) -> tuple[list[np.ndarray], np.ndarray]:
    """The channels of :func:`_raw_channels` block-averaged by f (:func:`_block_mean`)
    and the blocks that are mostly usable, made band by band of whole block rows: the
    same values as on the whole image, without its full-size float64 temporaries."""
    rows = max(1, BAND_PIXELS // max(valid.shape[1] * f, 1)) * f
    parts: list[list[np.ndarray]] = [[], [], []]
    weights = []
    for r0 in range(0, (valid.shape[0] // f) * f, rows):
        band = slice(r0, min(r0 + rows, (valid.shape[0] // f) * f))
        v = valid[band]
        weight = v.astype(np.float64)
        for part, c in zip(parts, _raw_channels(i[band], rho[band], phi[band], v), strict=True):
            mean, share = _block_mean(c, weight, f)
            part.append(mean)
        weights.append(share)
    return [np.concatenate(p) for p in parts], np.concatenate(weights) >= 0.5


def _block_mean(x: np.ndarray, weight: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    """Weighted f × f block means of ``x`` and the blocks' mean weight (edge rows and
    columns that do not fill a block are dropped). Written by hand: a reshape-mean is
    the vectorised block average, and skimage's ``block_reduce`` has no weights."""
    h, w = (x.shape[0] // f) * f, (x.shape[1] // f) * f
    xw = (x[:h, :w] * weight[:h, :w]).reshape(h // f, f, w // f, f).sum(axis=(1, 3))
    ww = weight[:h, :w].reshape(h // f, f, w // f, f).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ww > 0, xw / np.where(ww > 0, ww, 1.0), 0.0)
    return mean, ww / (f * f)


def _scale_grid(max_sigma: float) -> np.ndarray:
    n = int(math.floor(SCALES_PER_OCTAVE * math.log2(max(max_sigma, 1.0)))) + 1
    return 2.0 ** (np.arange(max(n, 1)) / SCALES_PER_OCTAVE)


def _level_of(j: int) -> int:
    """Pyramid level of the j-th scale: σ < 2.5 px on the full grid, then one level
    per octave so that σ on the level stays in [1.4, 2.4) px (small blur error)."""
    return 0 if j < 6 else (j - 2) // SCALES_PER_OCTAVE


def _scale_space(channels: list[np.ndarray], sigmas: np.ndarray) -> np.ndarray:
    """S(x, σ) = Σ_c (σ² ∇²G_σ ∗ c)² (J, H, W) float32 on the grid of ``channels``,
    each scale computed on the pyramid level of :func:`_level_of` and repeated back."""
    h, w = channels[0].shape
    out = np.empty((sigmas.size, h, w), dtype=np.float32)
    levels = [channels]
    for j, sigma in enumerate(sigmas):
        lev = _level_of(j)
        while len(levels) <= lev:
            levels.append([_block_mean(c, np.ones(c.shape), 2)[0] for c in levels[-1]])
        f = 2**lev
        # the 2 × 2 block means already blurred by a box of variance (f² − 1) / 12 px²
        s = math.sqrt(max(sigma**2 - (f * f - 1) / 12.0, 0.25)) / f
        acc = np.zeros(levels[lev][0].shape)
        for c in levels[lev]:
            acc += (s * s * ndimage.gaussian_laplace(c, s, mode="reflect")) ** 2
        if f > 1:
            acc = np.repeat(np.repeat(acc, f, axis=0), f, axis=1)
            pad = ((0, max(h - acc.shape[0], 0)), (0, max(w - acc.shape[1], 0)))
            acc = np.pad(acc, pad, mode="edge")[:h, :w]
        out[j] = acc
    return out


def _level_noise(sigmas: np.ndarray) -> np.ndarray:
    """Noise energy N(σ) per unit-variance channel at each scale of the pyramid: a
    level-L block mean divides the noise variance by 4^L."""
    out = np.empty(sigmas.size)
    for j, sigma in enumerate(sigmas):
        f = 2 ** _level_of(j)
        s = math.sqrt(max(sigma**2 - (f * f - 1) / 12.0, 0.25)) / f
        out[j] = noise_energy(round(s, 6)) / (f * f)
    return out


def _check(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, mask: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    # kept in their own dtype: the channels convert to float64 band by band
    # (:func:`_raw_channels`), without full-size float64 copies of a large image
    arrays = [np.asarray(a) for a in (intensity, dop, phase)]
    shape = arrays[0].shape
    if len(shape) != 2 or any(a.shape != shape for a in arrays):
        raise PolarsegError(
            "intensity, dop and phase must be (H, W) arrays of one shape, got "
            + ", ".join(str(a.shape) for a in arrays)
        )
    i, rho, phi = arrays
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(i) & np.isfinite(rho) & np.isfinite(phi) & (i > 0)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != shape:
            raise PolarsegError(f"mask must have the image's shape {shape}, got {m.shape}")
        valid &= m.astype(bool)
    return i, rho, phi, valid


def _fallback(valid_pixels: int, shape: tuple[int, int], note: str) -> ObjectSize:
    area = valid_pixels if valid_pixels > 0 else shape[0] * shape[1]
    return ObjectSize(
        size_px=max(FALLBACK_SHARE * math.sqrt(area), 1.0), channels=CHANNELS, note=note
    )


def estimate_object_size(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    mask: np.ndarray | None = None,
) -> ObjectSize:
    """Estimate the typical object diameter (px) of a scene from its polarisation image.

    D = 2√2 · median_w σ*(x), the weighted median over the pixels of the scale σ*(x)
    (px) that maximises the scale-normalised LoG energy S(x, σ) = Σ_c (σ² ∇²G_σ ∗ c)²
    of the noise-normalised channels c = ln Î, ρ cos 2φ, ρ sin 2φ, with weight
    √S(x, σ*) where it exceeds 3² times the noise energy (module docstring).

    Parameters
    ----------
    intensity : float array (H, W)
        Mean intensity Î (any units > 0; Î ≤ 0 or NaN pixels are not used).
    dop : float array (H, W)
        Degree of linear polarisation ρ in [0, 1].
    phase : float array (H, W)
        Angle of polarisation φ, radians (only 2φ enters).
    mask : bool array (H, W), optional
        The pixels to use (None: all finite ones).

    Returns
    -------
    ObjectSize
        ``size_px`` in pixels of the input, the per-scale votes behind it and a line
        for the user (:meth:`ObjectSize.describe`). When no pixel rises above the
        noise, or fewer than 8 × 8 usable pixels remain, the fallback
        :data:`FALLBACK_SHARE` · √(usable area) with a ``note`` saying why.

    Raises
    ------
    PolarsegError
        When the arrays (or the mask) do not share one (H, W) shape.

    Examples
    --------
    >>> yy, xx = np.mgrid[:128, :128]
    >>> discs = ((yy % 32 - 16) ** 2 + (xx % 32 - 16) ** 2 < 8**2).astype(float)
    >>> noise = np.random.default_rng(0).normal(0, 0.01, discs.shape)
    >>> est = estimate_object_size(1 + discs + noise, 0.1 + 0 * discs, 0 * discs)
    >>> 16 / 1.5 < est.size_px < 16 * 1.5
    True
    """
    i, rho, phi, valid = _check(intensity, dop, phase, mask)
    shape = valid.shape
    n_valid = int(valid.sum())
    if n_valid == 0:
        return _fallback(0, shape, "no usable pixel")
    work = _work_channels(i, rho, phi, valid)
    if isinstance(work, str):
        return _fallback(n_valid, shape, work)
    channels, names, work_valid, f = work
    h, w = work_valid.shape
    sigmas = _scale_grid(MAX_SCALE_SHARE * min(h, w))
    votes = _votes(_scale_space(channels, sigmas), _level_noise(sigmas) * len(channels), work_valid)
    if votes is None:
        return _fallback(n_valid, shape, "no structure above the noise")
    j, log_sigma, vote_w, coverage = votes
    order = np.argsort(log_sigma)
    cum = np.cumsum(vote_w[order])
    median_log_sigma = float(log_sigma[order][np.searchsorted(cum, 0.5 * cum[-1])])
    scores = np.bincount(j, weights=vote_w, minlength=sigmas.size) / cum[-1]
    return ObjectSize(
        size_px=float(DIAMETER_PER_SCALE * f * 2.0**median_log_sigma),
        estimated=True,
        scales_px=tuple(float(v) for v in DIAMETER_PER_SCALE * f * sigmas),
        scores=tuple(float(v) for v in scores),
        coverage=coverage,
        channels=tuple(names),
        work_factor=f,
    )


def scene_object_size(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    invalid: np.ndarray,
    given: float = 0.0,
    region: np.ndarray | None = None,
) -> ObjectSize:
    """The object size a run uses: ``given`` px when it is set (> 0), else
    :func:`estimate_object_size` on the pixels that are not ``invalid`` (H, W bool) and
    lie in ``region`` (H, W bool; None: everywhere)."""
    if given > 0:
        return ObjectSize.given(float(given))
    return estimate_object_size(intensity, dop, phase, usable_pixels(invalid, region))


def usable_pixels(invalid: np.ndarray, region: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool: the pixels that are not ``invalid`` and lie in ``region`` (None:
    everywhere), the ones an object size is estimated on."""
    usable = ~np.asarray(invalid, dtype=bool)
    if region is not None:
        usable &= np.asarray(region, dtype=bool)
    return usable


def work_box(valid: np.ndarray) -> tuple[tuple[slice, slice], int]:
    """The bounding box of the usable pixels ``valid`` (H, W bool, at least one True)
    and the integer factor f that block-averages it to at most :data:`WORK_PIXELS`."""
    rows, cols = np.nonzero(valid.any(axis=1))[0], np.nonzero(valid.any(axis=0))[0]
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    n = (rows[-1] + 1 - rows[0]) * (cols[-1] + 1 - cols[0])
    return box, max(1, math.ceil(math.sqrt(n / WORK_PIXELS)))


def smallest_estimate(valid: np.ndarray) -> float:
    """The smallest diameter (px) :func:`estimate_object_size` can give on the usable
    pixels ``valid`` (H, W bool): 2√2 f, the smallest scale of its grid (σ = 1 px of the
    work grid, block-averaged by f) as a diameter. 0 when no pixel is usable."""
    if not valid.any():
        return 0.0
    return float(DIAMETER_PER_SCALE * work_box(valid)[1])


def _work_channels(
    i: np.ndarray, rho: np.ndarray, phi: np.ndarray, valid: np.ndarray
) -> tuple[list[np.ndarray], list[str], np.ndarray, int] | str:
    """The noise-normalised, plane-removed channels ln Î, ρ cos 2φ, ρ sin 2φ on the
    usable pixels' bounding box, block-averaged by f to at most :data:`WORK_PIXELS`:
    (channels, their names, the usable pixels there, f), or why there are none."""
    box, f = work_box(valid)
    i, rho, phi, valid = i[box], rho[box], phi[box], valid[box]
    if min(valid.shape) // f < MIN_SIDE:
        return "too few usable pixels for a scale space"
    if f > 1:
        raw, work_valid = _reduced_channels(i, rho, phi, valid, f)
    else:
        raw, work_valid = _raw_channels(i, rho, phi, valid), valid
    if min(work_valid.shape) < MIN_SIDE or work_valid.sum() < MIN_SIDE * MIN_SIDE:
        return "too few usable pixels for a scale space"
    # invalid pixels take the nearest usable pixel's value (one distance transform for
    # the three channels); the noise and spread below read the usable pixels only
    raw = fill_from_nearest(work_valid, *raw)
    channels, names = [], []
    for name, c in zip(CHANNELS, raw, strict=True):
        sd = noise_sd(c, work_valid)
        spread = float(np.ptp(c[work_valid]))
        if not (sd > 0.0 and spread > 0.0 and math.isfinite(sd)):
            continue  # a constant channel (e.g. ρ = 0 everywhere) carries no edge
        channels.append(remove_plane(c, work_valid) / sd)
        names.append(name)
    if not channels:
        return "every channel is constant"
    return channels, names, work_valid, f


def _votes(
    energy: np.ndarray, noise: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    """The voting pixels' scale index j, refined log₂ σ* (in grid units, parabola
    through the three scales around the maximum), weight √S(x, σ*) and the share of the
    usable pixels that vote; None when none does."""
    best_j = np.argmax(energy, axis=0)
    best = np.take_along_axis(energy, best_j[None], axis=0)[0].astype(np.float64)
    # a pixel votes when its response stands out of the noise and peaks inside the
    # grid: still rising at the largest scale, it lies in a region wider than the grid
    # reaches (floor, sky, a shading trend) and has no characteristic scale
    votes = valid & (best > NOISE_FACTOR**2 * noise[best_j])
    votes &= best_j < energy.shape[0] - 1
    if not votes.any():
        return None
    rows, cols = np.nonzero(votes)
    j = best_j[rows, cols]
    s0 = best[rows, cols]
    lo = energy[np.maximum(j - 1, 0), rows, cols].astype(np.float64)
    hi = energy[j + 1, rows, cols].astype(np.float64)
    curv = lo - 2.0 * s0 + hi
    inner = (j > 0) & (curv < 0)
    shift = np.zeros(j.size)
    shift[inner] = np.clip(0.5 * (lo[inner] - hi[inner]) / curv[inner], -0.5, 0.5)
    log_sigma = (j + shift) / SCALES_PER_OCTAVE
    return j, log_sigma, np.sqrt(s0), float(votes.sum() / valid.sum())
