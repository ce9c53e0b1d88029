"""Raw frames of a division-of-focal-plane polarisation camera.

A polarisation camera (e.g. Sony IMX250MZR) puts a wire-grid polariser over every pixel;
the polariser angles repeat in 2 × 2 super-pixels. Splitting the raw frame into its four
sub-lattices gives a four-angle stack at half the resolution in each direction. Angles are
degrees here (this module meets files and the command line), measured like every angle of
the package: from the image's column axis towards its row axis.
"""

from __future__ import annotations

import numpy as np

from .errors import PolarsegError

#: Polariser angles (degrees) of the 2 × 2 super-pixel of the Sony IMX250MZR, row-major:
#: top-left 90, top-right 45, bottom-left 135, bottom-right 0.
IMX250MZR_LAYOUT = (90.0, 45.0, 135.0, 0.0)


def _check_layout(layout_deg) -> np.ndarray:
    layout = np.asarray(layout_deg, dtype=float).ravel()
    if layout.size != 4 or not np.all(np.isfinite(layout)):
        raise PolarsegError(
            "a 2 x 2 mosaic layout needs 4 finite angles in degrees (row-major), "
            f"got {list(np.asarray(layout_deg).ravel())}"
        )
    return layout


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
    layout = _check_layout(layout_deg)
    if raw.ndim != 2:
        raise PolarsegError(
            f"a raw mosaic frame must be 2-D (rows, columns), got shape {raw.shape}"
        )
    h, w = raw.shape
    if h < 2 or w < 2 or h % 2 or w % 2:
        raise PolarsegError(
            f"a 2 x 2 polarisation mosaic needs an even height and width, got {h} x {w} pixels"
        )
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
    layout = _check_layout(layout_deg)
    if stack.ndim != 3 or stack.shape[0] != 4:
        raise PolarsegError(f"a mosaic needs a stack of 4 frames, got shape {stack.shape}")
    angles = np.sort(layout) if angles_deg is None else _check_layout(angles_deg)
    frame_of = []
    for a in layout:
        hits = np.flatnonzero(np.isclose(angles, a))
        if hits.size == 0:
            raise PolarsegError(f"no frame at the layout angle {a:g} degrees")
        frame_of.append(hits[0])
    _, h, w = stack.shape
    lattices = stack[frame_of].reshape(2, 2, h, w)
    return lattices.transpose(2, 0, 3, 1).reshape(2 * h, 2 * w)
