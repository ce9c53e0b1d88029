"""Checks that a frame given as a raw polarisation-camera mosaic looks like one.

A raw mosaic is one grey sample per pixel; its 2 x 2 super-pixels put four polarisers
side by side, so the four sub-lattices differ systematically (the scene's polarisation,
the pixels' unequal polariser gains): the image has a component that alternates from
pixel to pixel, energy at the Nyquist frequencies (1/2 cycle per pixel) along rows,
columns and diagonals. An ordinary photograph (or a demosaiced, resized or colour image)
has almost none there.

:func:`nyquist_share` measures that component: the largest of the three 2 x 2 patterns'
image-wide means, relative to the image's mean. On the raw Sony IMX250MZR frames of
``../shared/data/polanalyser`` and the bundled crop it is 0.006-0.34; on ordinary
photographs (scikit-image's sample images) at most 0.001, on those raw frames demosaiced
and resized back to full size 0.0001. Below
:data:`MIN_NYQUIST_SHARE` the reader warns; it does not refuse (a mosaic of a uniform,
unpolarised scene on a perfectly even sensor would look the same).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import input_error

#: Below this :func:`nyquist_share` a frame shows no 2 x 2 periodicity.
MIN_NYQUIST_SHARE = 0.003


def check_mosaic_channels(path: Path, data: np.ndarray, colour: bool) -> np.ndarray:
    """The raw frame of ``data``; refuse an RGB/RGBA image whose colours differ.

    A raw polarisation-camera frame (also a colour-polarisation camera's, whose colours
    are decoded with ``bayer``) has one sample per pixel. A grey image saved as RGB(A)
    with three equal colour channels is taken as its first channel.

    Raises
    ------
    PolarsegError
        If ``data`` has 3 or 4 colour channels that are not all equal.
    """
    if not colour or data.ndim != 3 or data.shape[-1] not in (3, 4):
        return data
    rgb = data[..., :3]
    if np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2]):
        return np.ascontiguousarray(rgb[..., 0])
    raise input_error(
        path,
        f"a colour image ({data.shape[-1]} channels) is not a raw polarisation-camera "
        "frame: a mosaic layout needs the camera's raw single-channel frame (a "
        "colour-polarisation camera's raw frame is single-channel too, decoded with --bayer)",
    )


def nyquist_share(raw: np.ndarray) -> float:
    """The 2 x 2 alternating component of ``raw`` relative to its mean.

    The frame is cut into 2 x 2 super-pixels (a, b / c, d); the three patterns
    (a - b + c - d) / 4 (columns), (a + b - c - d) / 4 (rows) and (a - b - c + d) / 4
    (diagonals) are averaged over the image: the Fourier coefficients at the three
    Nyquist frequencies divided by the one at zero frequency. On a smooth image the
    column and row patterns are minus half the local slope, so the slope measured
    between the neighbouring super-pixels' means (an eighth of their difference) is
    added back first. Returns the largest of the three; ``inf`` for a frame smaller than
    6 x 6 pixels or with no positive mean (nothing to tell).

    Examples
    --------
    >>> nyquist_share(np.tile([[2.0, 1.0], [1.0, 2.0]], (4, 4)))
    0.3333333333333333
    >>> ramp = np.add.outer(np.arange(8.0), np.arange(8.0)) + 10  # a smooth slope
    >>> nyquist_share(ramp)
    0.0
    """
    x = np.asarray(raw, dtype=np.float64)
    x = x[: x.shape[0] // 2 * 2, : x.shape[1] // 2 * 2]
    mean = float(np.nanmean(x)) if x.size else 0.0
    if min(x.shape) < 6 or not np.isfinite(mean) or mean <= 0:
        return float("inf")
    a, b, c, d = (x[i::2, j::2] for i in (0, 1) for j in (0, 1))
    means = (a + b + c + d) / 4
    columns = (a - b + c - d)[:, 1:-1] / 4 + (means[:, 2:] - means[:, :-2]) / 8
    rows = (a + b - c - d)[1:-1] / 4 + (means[2:] - means[:-2]) / 8
    diagonals = (a - b - c + d) / 4
    return float(max(abs(np.nanmean(p)) for p in (columns, rows, diagonals)) / mean)


def periodicity_warning(path: Path, raw: np.ndarray) -> str | None:
    """A one-line warning if ``raw`` shows no 2 x 2 periodicity, else None."""
    share = nyquist_share(raw)
    if share >= MIN_NYQUIST_SHARE:  # inf: too small to tell
        return None
    return (
        f"{path.name} shows no 2 x 2 pixel pattern (alternating component {share:.2%} of "
        f"the mean, a raw polarisation-camera frame has more than "
        f"{MIN_NYQUIST_SHARE:.1%}): is it really a raw mosaic frame, not a demosaiced, "
        "resized or ordinary image?"
    )
