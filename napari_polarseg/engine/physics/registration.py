"""Registration of the frames of an angle stack (outdoor scenes and hand-held cameras move).

Each frame is aligned to a reference frame by a translation found with the upsampled
sub-pixel cross-correlation of :func:`skimage.registration.phase_cross_correlation`
(Guizar-Sicairos et al. 2008) and resampled with :func:`scipy.ndimage.shift`.

Two choices make the estimate accurate on real scenes, whose frames are neither periodic
nor rich in fine texture:

- frames are mean-subtracted and multiplied by a Hann window, so the image borders do not
  dominate the correlation, and the correlation is *not* phase-normalised
  (``normalization=None``): whitening the spectrum of a smooth image amplifies
  frequencies that hold only noise and round-off and can pull the peak to zero shift;
- the window biases the peak towards zero, so the estimate is refined: the frame is
  resampled by the shift found so far and the residual shift is measured again (a few
  iterations bring a 3-pixel shift to within a few hundredths of a pixel).

Mean subtraction and the unnormalised correlation are insensitive to the change of
brightness and contrast between polariser angles.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from skimage.filters import window
from skimage.registration import phase_cross_correlation

from ..errors import PolarsegError


def _finite_frame(frame: np.ndarray) -> np.ndarray:
    """Frame as float64 with non-finite pixels set to the frame's finite mean."""
    frame = np.asarray(frame, dtype=np.float64)
    finite = np.isfinite(frame)
    if finite.all():
        return frame
    fill = float(frame[finite].mean()) if finite.any() else 0.0
    return np.where(finite, frame, fill)


def _prepare(frame: np.ndarray, taper: np.ndarray) -> np.ndarray:
    frame = _finite_frame(frame)
    return (frame - frame.mean()) * taper


def estimate_shift(
    reference: np.ndarray, moving: np.ndarray, upsample: int = 20, iterations: int = 3
) -> np.ndarray:
    """Shift (rows, columns) in pixels that aligns ``moving`` with ``reference``.

    Parameters
    ----------
    reference, moving : array (H, W)
        Two frames of the same shape.
    upsample : int
        The shift is resolved to 1/upsample pixel.
    iterations : int
        Refinement passes (see the module docstring); 1 means a single correlation.

    Returns
    -------
    ndarray (2,)
        ``scipy.ndimage.shift(moving, shift)`` lies on ``reference``. A frame without
        contrast gives (0, 0).
    """
    taper = window("hann", reference.shape)
    ref = _prepare(reference, taper)
    moving = _finite_frame(moving)
    if not (np.ptp(ref) > 0 and np.ptp(moving) > 0):
        return np.zeros(2)
    total = np.zeros(2)
    current = moving
    for _ in range(iterations):
        step, _, _ = phase_cross_correlation(
            ref, _prepare(current, taper), upsample_factor=upsample, normalization=None
        )
        if not np.all(np.isfinite(step)):
            break
        total += step
        if np.max(np.abs(step)) < 1.0 / upsample:
            break
        current = ndimage.shift(moving, total, order=3, mode="nearest")
    return total


def register_stack(
    stack: np.ndarray, reference: int = 0, upsample: int = 20, iterations: int = 3
) -> tuple[np.ndarray, np.ndarray]:
    """Align every frame of a stack to one reference frame by sub-pixel translation.

    Parameters
    ----------
    stack : array (N, H, W)
        Angle stack (any real dtype).
    reference : int
        Index of the frame the others are aligned to (negative counts from the end).
    upsample : int
        Upsampling factor of the cross-correlation: shifts are found to 1/upsample pixel.
    iterations : int
        Refinement passes per frame (see the module docstring).

    Returns
    -------
    registered : ndarray (N, H, W) float64
        The aligned stack; the reference frame and frames found not to move are returned
        unchanged, the others are resampled by cubic splines, with edge values repeated
        where a frame moved in.
    shifts : ndarray (N, 2) float64
        Shift (rows, columns) in pixels that was applied to each frame: a frame whose
        content lies ``d`` pixels further along the axes than in the reference gets
        ``shifts = -d``. The reference frame's shift is (0, 0).

    Raises
    ------
    PolarsegError
        If the stack is not 3-D, ``reference`` is out of range, or ``upsample`` or
        ``iterations`` is not a positive integer.

    References
    ----------
    M. Guizar-Sicairos, S. T. Thurman and J. R. Fienup, "Efficient subpixel image
    registration algorithms", Optics Letters 33(2), 156-158 (2008).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy import ndimage
    >>> rng = np.random.default_rng(0)
    >>> ref = ndimage.gaussian_filter(rng.random((64, 64)), 2)
    >>> stack = np.stack([ref, ndimage.shift(ref, (1.5, -2.25), mode="grid-wrap")])
    >>> _, shifts = register_stack(stack)
    >>> np.round(shifts[1], 2).tolist()
    [-1.5, 2.25]
    """
    stack = np.asarray(stack)
    if stack.ndim != 3:
        raise PolarsegError(
            f"registration needs a stack of shape (frames, rows, columns), got {stack.shape}"
        )
    n = stack.shape[0]
    if not isinstance(reference, (int, np.integer)) or not -n <= reference < n:
        raise PolarsegError(f"reference frame {reference!r} is not in a stack of {n} frames")
    for name, value in (("upsample", upsample), ("iterations", iterations)):
        if not isinstance(value, (int, np.integer)) or value < 1:
            raise PolarsegError(f"{name} must be a positive integer, got {value!r}")
    reference = int(reference) % n
    ref = _finite_frame(stack[reference])
    registered = np.empty(stack.shape, dtype=np.float64)
    shifts = np.zeros((n, 2))
    for i in range(n):
        frame = np.asarray(stack[i], dtype=np.float64)
        if i == reference:
            registered[i] = frame
            continue
        shifts[i] = estimate_shift(ref, frame, upsample, iterations)
        if np.any(shifts[i]):
            registered[i] = ndimage.shift(frame, shifts[i], order=3, mode="nearest")
        else:
            registered[i] = frame
    return registered, shifts


def shift_frames(stack: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Apply the per-frame shifts of :func:`register_stack` to another stack of the same
    frames (e.g. each colour of a colour-polarisation stack, whose luminance was
    registered): cubic splines, edge values repeated, as :func:`register_stack` does.

    Parameters
    ----------
    stack : array (..., N, H, W)
    shifts : array (N, 2)
        Shift (rows, columns) in pixels of each frame.

    Returns
    -------
    ndarray, float64, same shape as ``stack``
    """
    stack = np.asarray(stack, dtype=np.float64)
    shifts = np.asarray(shifts, dtype=float)
    if stack.ndim < 3 or shifts.shape != (stack.shape[-3], 2):
        raise PolarsegError(
            f"shifts {shifts.shape} do not match the frames of a stack of shape {stack.shape}"
        )
    out = stack.copy()
    for i, d in enumerate(shifts):
        if np.any(d):
            frames = out[..., i, :, :].reshape(-1, *stack.shape[-2:])
            moved = [ndimage.shift(f, d, order=3, mode="nearest") for f in frames]
            out[..., i, :, :] = np.reshape(moved, out[..., i, :, :].shape)
    return out
