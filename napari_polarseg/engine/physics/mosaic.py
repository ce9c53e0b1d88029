"""Raw frames of a division-of-focal-plane polarisation camera.

A polarisation camera (e.g. Sony IMX250MZR) puts a wire-grid polariser over every pixel;
the polariser angles repeat in 2 × 2 super-pixels. Two ways to turn the raw frame into a
four-angle stack (:func:`demosaic`):

- **super-pixel** (:func:`demosaic_superpixel`): each of the four sub-lattices is one
  frame, at half the resolution in each direction; no value is invented, but the four
  frames are sampled half a pixel apart.
- **interpolated** (:func:`demosaic_interpolated`): full resolution; each angle's missing
  pixels are filled by bilinear interpolation of that angle's own samples (normalised
  convolution, so the image borders need no special case).

8-, 12- and 16-bit raw data (uint8/uint16) and float data are accepted; a dark frame or a
constant offset can be subtracted first (:func:`subtract_dark`). Angles are degrees here
(this module meets files and the command line), measured like every angle of the
package: from the image's column axis towards its row axis.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import PolarsegError

#: Polariser angles (degrees) of the 2 × 2 super-pixel of the Sony IMX250MZR, row-major:
#: top-left 90, top-right 45, bottom-left 135, bottom-right 0.
IMX250MZR_LAYOUT = (90.0, 45.0, 135.0, 0.0)
#: Demosaicing methods of :func:`demosaic`.
DEMOSAIC_METHODS = ("superpixel", "interpolated")
#: Bilinear interpolation kernel of one sub-lattice (weights of the 3 × 3 neighbourhood).
_BILINEAR = np.array([[1.0, 2.0, 1.0], [2.0, 4.0, 2.0], [1.0, 2.0, 1.0]]) / 4.0


def check_layout(layout_deg) -> np.ndarray:
    """The 2 × 2 polariser layout as 4 finite floats (degrees, row-major), or
    :class:`PolarsegError`."""
    layout = np.asarray(layout_deg, dtype=float).ravel()
    if layout.size != 4 or not np.all(np.isfinite(layout)):
        raise PolarsegError(
            "a 2 x 2 mosaic layout needs 4 finite angles in degrees (row-major), "
            f"got {list(np.asarray(layout_deg).ravel())}"
        )
    return layout


def check_raw(raw: np.ndarray, period: int = 2) -> tuple[int, int]:
    """Height and width of a raw mosaic frame: 2-D, real numbers, both multiples of the
    pattern's ``period`` (2: a polariser mosaic; 4: a colour-polarisation one)."""
    if raw.ndim != 2:
        raise PolarsegError(
            f"a raw mosaic frame must be 2-D (rows, columns), got shape {raw.shape}"
        )
    h, w = raw.shape
    if h < period or w < period or h % period or w % period:
        if period == 2:
            what = "a 2 x 2 polarisation mosaic needs an even height and width"
        else:
            what = (
                f"a colour-polarisation mosaic ({period} x {period} period) needs a height "
                f"and width that are multiples of {period}"
            )
        raise PolarsegError(f"{what}, got {h} x {w} pixels")
    if raw.dtype != np.bool_ and (
        not np.issubdtype(raw.dtype, np.number) or np.issubdtype(raw.dtype, np.complexfloating)
    ):
        raise PolarsegError(f"a raw mosaic frame must hold real numbers, got dtype {raw.dtype}")
    return h, w


def demosaic_superpixel(
    raw: np.ndarray, layout_deg=IMX250MZR_LAYOUT
) -> tuple[np.ndarray, np.ndarray]:
    """Split a raw polarisation-camera frame into a four-angle stack at half resolution.

    Each 2 × 2 super-pixel becomes one output pixel; no interpolation is done, so the four
    frames are sampled half a pixel apart (negligible for the block statistics of the
    segmentation, which uses w × w blocks).

    Parameters
    ----------
    raw : array (H, W)
        The raw mosaic frame; H and W must both be even.
    layout_deg : sequence of 4 floats
        Polariser angles in degrees of the super-pixel in row-major order: top-left,
        top-right, bottom-left, bottom-right. Default: Sony IMX250MZR, (90, 45, 135, 0).

    Returns
    -------
    stack : ndarray (4, H/2, W/2)
        The four sub-lattices, same dtype as ``raw``, ordered by increasing angle.
    angles_deg : ndarray (4,)
        Their polariser angles in degrees (float64), increasing.

    Raises
    ------
    PolarsegError
        If ``raw`` is not 2-D, a side is odd or smaller than 2, or the layout is not four
        finite numbers.

    Examples
    --------
    >>> import numpy as np
    >>> raw = np.array([[90, 45], [135, 0]])
    >>> stack, angles = demosaic_superpixel(raw)
    >>> angles.tolist(), stack[:, 0, 0].tolist()
    ([0.0, 45.0, 90.0, 135.0], [0, 45, 90, 135])
    """
    raw = np.asarray(raw)
    layout = check_layout(layout_deg)
    h, w = check_raw(raw)
    # (H/2, 2, W/2, 2) -> (2, 2, H/2, W/2) -> (4, H/2, W/2): sub-lattice (i, j) is raw[i::2, j::2]
    lattices = raw.reshape(h // 2, 2, w // 2, 2).transpose(1, 3, 0, 2).reshape(4, h // 2, w // 2)
    order = np.argsort(layout, kind="stable")
    return np.ascontiguousarray(lattices[order]), layout[order]


def mosaic_superpixel(
    stack: np.ndarray, layout_deg=IMX250MZR_LAYOUT, angles_deg=None
) -> np.ndarray:
    """Interleave four frames into a raw 2 × 2 mosaic (inverse of :func:`demosaic_superpixel`).

    Parameters
    ----------
    stack : array (4, h, w)
        Frames at the polariser angles ``angles_deg``.
    layout_deg : sequence of 4 floats
        Angles of the super-pixel in row-major order (see :func:`demosaic_superpixel`).
    angles_deg : sequence of 4 floats, optional
        Angle of each frame of ``stack``; default: the layout sorted increasingly (the
        order :func:`demosaic_superpixel` returns).

    Returns
    -------
    ndarray (2h, 2w)
        The raw mosaic frame.
    """
    stack = np.asarray(stack)
    layout = check_layout(layout_deg)
    if stack.ndim != 3 or stack.shape[0] != 4:
        raise PolarsegError(f"a mosaic needs a stack of 4 frames, got shape {stack.shape}")
    angles = np.sort(layout) if angles_deg is None else check_layout(angles_deg)
    frame_of = []
    for a in layout:
        hits = np.flatnonzero(np.isclose(angles, a))
        if hits.size == 0:
            raise PolarsegError(f"no frame at the layout angle {a:g} degrees")
        frame_of.append(hits[0])
    _, h, w = stack.shape
    lattices = stack[frame_of].reshape(2, 2, h, w)
    return lattices.transpose(2, 0, 3, 1).reshape(2 * h, 2 * w)


def demosaic_interpolated(
    raw: np.ndarray, layout_deg=IMX250MZR_LAYOUT
) -> tuple[np.ndarray, np.ndarray]:
    """Full-resolution four-angle stack from a raw frame by bilinear interpolation.

    Every angle keeps its own samples where it was measured; its missing pixels get the
    mean of its nearest samples (2 neighbours along a row or column, or 4 diagonal ones),
    i.e. bilinear interpolation. This is computed as a normalised convolution,
    ``(K * samples) / (K * indicator)`` with the 3 × 3 kernel ``[[1, 2, 1], [2, 4, 2],
    [1, 2, 1]] / 4`` and zero padding, so pixels on the border use the samples they have.

    Parameters
    ----------
    raw : array (H, W)
        The raw mosaic frame; H and W must both be even.
    layout_deg : sequence of 4 floats
        Polariser angles in degrees of the super-pixel in row-major order (see
        :func:`demosaic_superpixel`).

    Returns
    -------
    stack : ndarray (4, H, W) float64
        One full-resolution frame per angle, ordered by increasing angle.
    angles_deg : ndarray (4,)
        Their polariser angles in degrees, increasing.

    Raises
    ------
    PolarsegError
        As :func:`demosaic_superpixel`.

    Examples
    --------
    >>> raw = np.tile(np.array([[90.0, 45.0], [135.0, 0.0]]), (2, 2))
    >>> stack, angles = demosaic_interpolated(raw)
    >>> stack.shape, bool(np.all(stack[1] == 45.0))
    ((4, 4, 4), True)
    """
    raw = np.asarray(raw)
    layout = check_layout(layout_deg)
    h, w = check_raw(raw)
    data = raw.astype(np.float64)
    order = np.argsort(layout, kind="stable")
    out = np.empty((4, h, w))
    for k, cell in enumerate(order):
        di, dj = divmod(int(cell), 2)
        sites = np.zeros((h, w))
        sites[di::2, dj::2] = 1.0
        values = np.zeros((h, w))
        values[di::2, dj::2] = data[di::2, dj::2]
        num = ndimage.correlate(values, _BILINEAR, mode="constant", cval=0.0)
        den = ndimage.correlate(sites, _BILINEAR, mode="constant", cval=0.0)
        frame = num / den
        frame[di::2, dj::2] = data[di::2, dj::2]  # measured samples exactly as they were
        out[k] = frame
    return out, layout[order]


def spread_flags_interpolated(flags: np.ndarray, layout_deg=IMX250MZR_LAYOUT) -> np.ndarray:
    """Which interpolated samples draw on a flagged raw pixel (e.g. a saturated one).

    Parameters
    ----------
    flags : array (H, W) of bool
        Flagged raw pixels.
    layout_deg : sequence of 4 floats
        Super-pixel layout (see :func:`demosaic_superpixel`).

    Returns
    -------
    ndarray (4, H, W) of bool
        Per angle (increasing), the samples of :func:`demosaic_interpolated` that use a
        flagged raw pixel.
    """
    flags = np.asarray(flags, dtype=bool)
    layout = check_layout(layout_deg)
    h, w = check_raw(flags)
    out = np.zeros((4, h, w), dtype=bool)
    for k, cell in enumerate(np.argsort(layout, kind="stable")):
        di, dj = divmod(int(cell), 2)
        plane = np.zeros((h, w))
        plane[di::2, dj::2] = flags[di::2, dj::2]
        out[k] = ndimage.correlate(plane, _BILINEAR, mode="constant", cval=0.0) > 0
    return out


def demosaic(
    raw: np.ndarray, layout_deg=IMX250MZR_LAYOUT, method: str = "superpixel"
) -> tuple[np.ndarray, np.ndarray]:
    """Four-angle stack from a raw polarisation-camera frame.

    Parameters
    ----------
    raw : array (H, W)
        The raw mosaic frame (any real dtype); H and W must both be even.
    layout_deg : sequence of 4 floats
        Polariser angles in degrees of the 2 × 2 super-pixel, row-major (default: Sony
        IMX250MZR, (90, 45, 135, 0)).
    method : {"superpixel", "interpolated"}
        Half resolution without interpolation (:func:`demosaic_superpixel`, keeps the
        dtype) or full resolution by bilinear interpolation
        (:func:`demosaic_interpolated`, float64).

    Returns
    -------
    stack : ndarray (4, h, w)
        Frames ordered by increasing angle: (H/2, W/2) or (H, W).
    angles_deg : ndarray (4,)
        Their polariser angles in degrees.
    """
    if method == "superpixel":
        return demosaic_superpixel(raw, layout_deg)
    if method == "interpolated":
        return demosaic_interpolated(raw, layout_deg)
    raise PolarsegError(
        f"demosaic method must be one of {', '.join(DEMOSAIC_METHODS)}; got {method!r}"
    )


def demosaic_flags(
    flags: np.ndarray, layout_deg=IMX250MZR_LAYOUT, method: str = "superpixel"
) -> np.ndarray:
    """Per-sample flags of the stack :func:`demosaic` makes from flagged raw pixels."""
    if method == "interpolated":
        return spread_flags_interpolated(flags, layout_deg)
    return demosaic_superpixel(np.asarray(flags, dtype=bool), layout_deg)[0]


def subtract_dark(
    data: np.ndarray, dark: np.ndarray | None = None, offset: float | None = None
) -> np.ndarray:
    """Subtract a dark frame and/or a constant offset; negative results become 0.

    Parameters
    ----------
    data : array (H, W) or (N, H, W)
        Raw frame(s).
    dark : array (H, W), optional
        Dark frame (the same camera with the lens capped), subtracted from every frame.
    offset : float, optional
        Constant black level subtracted as well (e.g. a camera's pedestal).

    Returns
    -------
    ndarray, float64, same shape as ``data``
        ``max(data − dark − offset, 0)``. Values clipped to 0 count as black for
        :func:`~napari_polarseg.engine.physics.pixel_mask.validity_mask`.

    Raises
    ------
    PolarsegError
        If the dark frame's size differs from the frames' or a value is not finite.
    """
    out = np.asarray(data, dtype=np.float64)
    if dark is not None:
        dark = np.asarray(dark, dtype=np.float64)
        if dark.shape != out.shape[-2:]:
            raise PolarsegError(
                f"the dark frame is {' x '.join(map(str, dark.shape))} pixels but the frames "
                f"are {out.shape[-2]} x {out.shape[-1]}"
            )
        if not np.all(np.isfinite(dark)):
            raise PolarsegError("the dark frame has NaN or infinite values")
        out = out - dark
    if offset is not None:
        if not np.isfinite(offset):
            raise PolarsegError(f"the offset must be a finite number, got {offset!r}")
        out = out - float(offset)
    if dark is None and offset is None:
        return out.copy() if out is data else out
    with np.errstate(invalid="ignore"):
        return np.where(out < 0, 0.0, out)
