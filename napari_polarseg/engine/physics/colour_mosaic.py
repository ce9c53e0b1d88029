"""Raw frames of a colour-polarisation camera (Sony IMX250MYR / IMX253MYR).

A colour-polarisation sensor puts a 2 × 2 polariser super-pixel (the layout of the mono
sensor, :mod:`.mosaic`) under every colour filter of a Bayer pattern whose cells are
those super-pixels, so the pattern repeats every 4 × 4 pixels. Raw pixel (r, c) sits
behind

- the polariser of super-pixel cell ``(r mod 2, c mod 2)``: ``layout_deg[2 (r mod 2) +
  (c mod 2)]`` (row-major, as in :mod:`.mosaic`);
- the colour filter of Bayer cell ``(⌊r/2⌋ mod 2, ⌊c/2⌋ mod 2)``: letter ``2 (⌊r/2⌋ mod 2)
  + (⌊c/2⌋ mod 2)`` of the Bayer order (``"RGGB"``: R top-left, B bottom-right).

For the RGGB order and the layout 90, 45, 135, 0 of the Sony sensors, the first period is::

    R90  R45  G90  G45
    R135 R0   G135 G0
    G90  G45  B90  B45
    G135 G0   B135 B0

Two decodings into a (colour, angle, H, W) stack, colours R, G, B and angles increasing
(:func:`demosaic_colour`):

- **super-pixel** (:func:`demosaic_colour_superpixel`): one output pixel per 4 × 4
  period (a quarter of the resolution in each direction); R and B are their samples as
  recorded, G the mean of the period's two G samples. No value is invented.
- **interpolated** (:func:`demosaic_colour_interpolated`): full resolution; each colour
  and angle is filled by bilinear interpolation of its own samples (normalised
  convolution with the separable tent of half-width 4, scipy.ndimage; no OpenCV). R
  and B samples form one lattice of period 4, G two such lattices offset by (2, 2),
  whose bilinear interpolations are averaged. Measured samples keep their values.

The segmentation runs on the **luminance** stack (:func:`luminance`), the Rec. 601 luma
weights :data:`LUMINANCE_WEIGHTS` = 0.299 R + 0.587 G + 0.114 B (the weights
:mod:`napari_polarseg.io` uses for colour pictures). The polarisation model is linear in
the intensities, I(θ) = Î (1 + ρ cos(2θ − 2φ)) in every colour (thesis eq. 3.14, Î the
mean over θ, i.e. S0/2), so the luminance stack is itself a polarisation stack, with
Î_Y = Σ w_c Î_c and Stokes vector Σ w_c S_c. The
per-colour stacks feed the pixel classifier (:func:`colour_polarisation_images`).

Angles are degrees here (this module meets files and the command line); they are
measured, like every angle of the package, from the image's column axis towards its
row axis.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import PolarsegError
from .mosaic import DEMOSAIC_METHODS, IMX250MZR_LAYOUT, check_layout, check_raw
from .polarimage import PolarisationImage, polarisation_image

#: Colours of the decoded stack, in order.
COLOURS = ("R", "G", "B")
#: Bayer orders: the colours of the 2 × 2 Bayer cell, row-major.
BAYER_ORDERS = ("RGGB", "BGGR", "GRBG", "GBRG")
#: Polariser layout of the Sony IMX250MYR / IMX253MYR super-pixel (as the mono IMX250MZR).
IMX250MYR_LAYOUT = IMX250MZR_LAYOUT
#: Bayer order of the Sony IMX250MYR / IMX253MYR.
IMX250MYR_BAYER = "RGGB"
#: Rec. 601 luma weights of R, G, B (sum 1): the luminance the segmentation runs on.
LUMINANCE_WEIGHTS = (0.299, 0.587, 0.114)
#: 1-D bilinear (tent) kernel of a lattice of period 4: weight 1 − |d|/4 at distance d.
TENT4 = np.array([1.0, 2.0, 3.0, 4.0, 3.0, 2.0, 1.0]) / 4.0


def check_bayer(bayer: str) -> str:
    """The Bayer order in upper case, or :class:`PolarsegError` if it is not one of
    :data:`BAYER_ORDERS`."""
    order = str(bayer).strip().upper()
    if order not in BAYER_ORDERS:
        raise PolarsegError(
            f"the Bayer order must be one of {', '.join(BAYER_ORDERS)}; got {bayer!r}"
        )
    return order


def check_colour_raw(raw: np.ndarray) -> tuple[int, int]:
    """Height and width of a raw colour-polarisation frame (2-D, both multiples of 4)."""
    return check_raw(raw, period=4)


def bayer_cells(bayer: str) -> list[list[int]]:
    """For each colour of :data:`COLOURS`, its Bayer cells (row-major index 0..3)."""
    order = check_bayer(bayer)
    return [[k for k, letter in enumerate(order) if letter == colour] for colour in COLOURS]


def period_cells(raw: np.ndarray) -> np.ndarray:
    """The raw frame as (Bayer cell, polariser cell, H/4, W/4).

    Sample ``[b, p, i, j]`` is raw pixel ``(4i + 2 (b // 2) + p // 2, 4j + 2 (b % 2) + p % 2)``.
    """
    h, w = raw.shape
    blocks = raw.reshape(h // 4, 2, 2, w // 4, 2, 2)  # (i, br, pr, j, bc, pc)
    return blocks.transpose(1, 4, 2, 5, 0, 3).reshape(4, 4, h // 4, w // 4)


def demosaic_colour_superpixel(
    raw: np.ndarray, layout_deg=IMX250MYR_LAYOUT, bayer: str = IMX250MYR_BAYER
) -> tuple[np.ndarray, np.ndarray]:
    """Split a raw colour-polarisation frame into a (colour, angle) stack, one pixel per
    4 × 4 period.

    Parameters
    ----------
    raw : array (H, W)
        The raw frame; H and W must be multiples of 4.
    layout_deg : sequence of 4 floats
        Polariser angles in degrees of the 2 × 2 super-pixel, row-major (default: Sony
        IMX250MYR, (90, 45, 135, 0)).
    bayer : {"RGGB", "BGGR", "GRBG", "GBRG"}
        Colours of the 2 × 2 Bayer cell (whose cells are polariser super-pixels), row-major.

    Returns
    -------
    stack : ndarray (3, 4, H/4, W/4) float64
        ``stack[c, k]``: colour ``COLOURS[c]`` at the k-th angle (G: mean of the two G
        samples of the period).
    angles_deg : ndarray (4,)
        The polariser angles in degrees, increasing.

    Examples
    --------
    >>> raw = np.arange(16.0).reshape(4, 4)
    >>> stack, angles = demosaic_colour_superpixel(raw)
    >>> angles.tolist(), stack[:, 0, 0, 0].tolist()  # 0 degrees: R, mean of G, B
    ([0.0, 45.0, 90.0, 135.0], [5.0, 10.0, 15.0])
    """
    raw = np.asarray(raw)
    layout = check_layout(layout_deg)
    check_colour_raw(raw)
    cells = period_cells(raw.astype(np.float64))
    order = np.argsort(layout, kind="stable")
    stack = np.stack([cells[b].mean(axis=0) for b in bayer_cells(bayer)])
    return np.ascontiguousarray(stack[:, order]), layout[order]


def colour_mosaic(
    stack: np.ndarray, layout_deg=IMX250MYR_LAYOUT, bayer: str = IMX250MYR_BAYER
) -> np.ndarray:
    """Raw colour-polarisation frame of a (colour, angle) stack (inverse of
    :func:`demosaic_colour_superpixel`; both G cells of a period get the G value).

    Parameters
    ----------
    stack : array (3, 4, h, w)
        Colours R, G, B at the layout's angles sorted increasingly.
    layout_deg, bayer
        As :func:`demosaic_colour_superpixel`.

    Returns
    -------
    ndarray (4h, 4w)
    """
    stack = np.asarray(stack)
    layout = check_layout(layout_deg)
    if stack.ndim != 4 or stack.shape[:2] != (3, 4):
        raise PolarsegError(f"a colour mosaic needs a (3, 4, h, w) stack, got shape {stack.shape}")
    _, _, h, w = stack.shape
    rank = np.argsort(np.argsort(layout, kind="stable"), kind="stable")  # cell -> sorted index
    cells = np.empty((4, 4, h, w), dtype=stack.dtype)
    for c, bs in enumerate(bayer_cells(bayer)):
        for b in bs:
            cells[b] = stack[c, rank]
    blocks = cells.reshape(2, 2, 2, 2, h, w)  # (br, bc, pr, pc, i, j)
    return blocks.transpose(4, 0, 2, 5, 1, 3).reshape(4 * h, 4 * w)


def site_origin(bayer_cell: int, polariser_cell: int) -> tuple[int, int]:
    """Row and column, within the 4 × 4 period, of one Bayer cell's polariser cell."""
    return 2 * (bayer_cell // 2) + polariser_cell // 2, 2 * (bayer_cell % 2) + polariser_cell % 2


def tent_spread(samples: np.ndarray, origin: tuple[int, int], shape: tuple[int, int]) -> np.ndarray:
    """Σ of the tent-weighted samples of one period-4 lattice at every pixel of ``shape``.

    ``samples[i, j]`` sits at pixel ``(origin[0] + 4i, origin[1] + 4j)``; the result is the
    correlation of the zero-filled full-size plane with :data:`TENT4` ⊗ :data:`TENT4`
    (zero padding), computed separably: along the rows on the lattice's columns only,
    then along the columns.
    """
    h, w = shape
    r0, c0 = origin
    columns = np.zeros((h, samples.shape[1]))
    columns[r0::4] = samples
    columns = ndimage.correlate1d(columns, TENT4, axis=0, mode="constant", cval=0.0)
    plane = np.zeros((h, w))
    plane[:, c0::4] = columns
    return ndimage.correlate1d(plane, TENT4, axis=1, mode="constant", cval=0.0)


def tent_weight_sum(origin: tuple[int, int], shape: tuple[int, int]) -> np.ndarray:
    """:func:`tent_spread` of an all-ones lattice (the normaliser; separable: an outer
    product of the two 1-D sums)."""
    h, w = shape
    rows = np.zeros(h)
    rows[origin[0] :: 4] = 1.0
    cols = np.zeros(w)
    cols[origin[1] :: 4] = 1.0
    along = ndimage.correlate1d(rows, TENT4, mode="constant", cval=0.0)
    across = ndimage.correlate1d(cols, TENT4, mode="constant", cval=0.0)
    return np.outer(along, across)


def demosaic_colour_interpolated(
    raw: np.ndarray, layout_deg=IMX250MYR_LAYOUT, bayer: str = IMX250MYR_BAYER
) -> tuple[np.ndarray, np.ndarray]:
    """Full-resolution (colour, angle) stack of a raw colour-polarisation frame.

    Each colour c and angle k is a normalised convolution of its samples,
    ``(T * samples) / (T * indicator)`` with the separable tent T = :data:`TENT4` ⊗
    :data:`TENT4` (weight (1 − |dr|/4)(1 − |dc|/4)): bilinear interpolation on R's and B's
    period-4 lattice, the mean of the two lattices' bilinear interpolations for G. Pixels
    on the border use the samples they have; measured samples keep their values.

    Parameters
    ----------
    raw : array (H, W)
        The raw frame; H and W must be multiples of 4.
    layout_deg, bayer
        As :func:`demosaic_colour_superpixel`.

    Returns
    -------
    stack : ndarray (3, 4, H, W) float64
    angles_deg : ndarray (4,)
        Increasing.
    """
    raw = np.asarray(raw)
    layout = check_layout(layout_deg)
    h, w = check_colour_raw(raw)
    data = raw.astype(np.float64)
    order = np.argsort(layout, kind="stable")
    out = np.empty((3, 4, h, w))
    for c, bs in enumerate(bayer_cells(bayer)):
        for k, p in enumerate(order):
            origins = [site_origin(b, int(p)) for b in bs]
            num = sum(tent_spread(data[r0::4, c0::4], (r0, c0), (h, w)) for r0, c0 in origins)
            den = sum(tent_weight_sum(o, (h, w)) for o in origins)
            frame = num / den
            for r0, c0 in origins:  # measured samples exactly as they were
                frame[r0::4, c0::4] = data[r0::4, c0::4]
            out[c, k] = frame
    return out, layout[order]


def demosaic_colour(
    raw: np.ndarray,
    layout_deg=IMX250MYR_LAYOUT,
    bayer: str = IMX250MYR_BAYER,
    method: str = "superpixel",
) -> tuple[np.ndarray, np.ndarray]:
    """(colour, angle, H, W) stack of a raw colour-polarisation frame.

    ``method`` is ``"superpixel"`` (:func:`demosaic_colour_superpixel`, H/4 × W/4) or
    ``"interpolated"`` (:func:`demosaic_colour_interpolated`, H × W); both float64.
    """
    if method == "superpixel":
        return demosaic_colour_superpixel(raw, layout_deg, bayer)
    if method == "interpolated":
        return demosaic_colour_interpolated(raw, layout_deg, bayer)
    raise PolarsegError(
        f"demosaic method must be one of {', '.join(DEMOSAIC_METHODS)}; got {method!r}"
    )


def demosaic_colour_flags(
    flags: np.ndarray,
    layout_deg=IMX250MYR_LAYOUT,
    bayer: str = IMX250MYR_BAYER,
    method: str = "superpixel",
) -> np.ndarray:
    """Which decoded samples of :func:`demosaic_colour` draw on a flagged raw pixel
    (e.g. a saturated one): (3, 4, h, w) of bool."""
    flags = np.asarray(flags, dtype=bool)
    layout = check_layout(layout_deg)
    h, w = check_colour_raw(flags)
    order = np.argsort(layout, kind="stable")
    if method == "superpixel":
        cells = period_cells(flags)
        out = np.stack([cells[b].any(axis=0) for b in bayer_cells(bayer)])
        return np.ascontiguousarray(out[:, order])
    if method != "interpolated":
        raise PolarsegError(
            f"demosaic method must be one of {', '.join(DEMOSAIC_METHODS)}; got {method!r}"
        )
    out = np.zeros((3, 4, h, w), dtype=bool)
    for c, bs in enumerate(bayer_cells(bayer)):
        for k, p in enumerate(order):
            origins = [site_origin(b, int(p)) for b in bs]
            spread = sum(
                tent_spread(flags[r0::4, c0::4].astype(float), (r0, c0), (h, w))
                for r0, c0 in origins
            )
            out[c, k] = spread > 0
    return out


def luminance(colour_stack: np.ndarray, weights=LUMINANCE_WEIGHTS) -> np.ndarray:
    """Luminance stack Σ_c w_c · stack[c] of a (colour, angle, H, W) stack.

    Parameters
    ----------
    colour_stack : array (3, N, H, W)
        Colours R, G, B (units of the input).
    weights : 3 floats
        Weights of R, G, B (default: Rec. 601 luma, :data:`LUMINANCE_WEIGHTS`).

    Returns
    -------
    ndarray (N, H, W) float64
    """
    stack = np.asarray(colour_stack, dtype=np.float64)
    wts = np.asarray(weights, dtype=float).ravel()
    if stack.ndim != 4 or stack.shape[0] != wts.size:
        raise PolarsegError(
            f"a luminance needs a (colour, angle, H, W) stack with {wts.size} colours, "
            f"got shape {stack.shape}"
        )
    return np.tensordot(wts, stack, axes=1)


def colour_polarisation_images(
    colour_stack: np.ndarray,
    angles_rad: np.ndarray,
    robust: bool = False,
    weights: np.ndarray | None = None,
) -> list[PolarisationImage]:
    """The polarisation image (Î, ρ, φ; thesis eq. 3.14) of every colour.

    Parameters
    ----------
    colour_stack : array (C, N, H, W)
    angles_rad : array (N,)
        Polariser angles, radians.
    robust : bool
        Robust fit (:func:`~.polarimage.polarisation_image`).
    weights : array (N, H, W), optional
        Sample weights shared by every colour (e.g. the luminance stack's validity mask).

    Returns
    -------
    list of PolarisationImage, one per colour
    """
    stack = np.asarray(colour_stack)
    if stack.ndim != 4:
        raise PolarsegError(f"a colour stack must be (colour, angle, H, W), got {stack.shape}")
    return [polarisation_image(s, angles_rad, robust, weights=weights) for s in stack]
