"""Polarisation image (Î, ρ, φ) from an angle stack, and the mask of usable pixels.

Implements the transmitted-radiance sinusoid, thesis eq. 3.14,

    I(α) = Î (1 + ρ cos(2α − 2φ)) = c0 + c1 cos 2α + c2 sin 2α,

by exact linear least squares for any set of N >= 3 distinct polariser angles (modulo π):
one 3 × N pseudo-inverse applied to the whole stack. Then Î = c0, ρ = √(c1² + c2²)/c0 and
φ = ½ atan2(c2, c1) mod π. This replaces the thesis moment estimators (eqs. 4.8–4.12),
which mix up a mean with an integral (ρ off by √π, a spurious 2π in eq. 4.11) and whose
arccos folds φ into [0, π/2]. For Gaussian noise the least-squares fit *is* the
Levenberg–Marquardt optimum the thesis refines towards.

Three refinements for real captures:

- **Repeated angles**: frames at the same polariser state (the same angle modulo π, e.g.
  0° and 180°, or two shots at 90°) are *averaged* before the fit, and the average
  weighs as many samples as it holds (:func:`angle_groups`,
  :func:`average_duplicate_angles`): for the linear model this gives exactly the
  least-squares fit of all frames, the minimum-variance estimate under Gaussian noise.
- **Missing samples**: a sample that is not finite, or whose weight is 0 (saturated or
  black, see :func:`validity_mask`), is left out of its pixel's fit. The pixel is fitted
  from the remaining samples (weighted least squares, one 3 × 3 solve per pixel) if at
  least 3 distinct angles remain.
- **Robust fit** (``robust=True``): an MM-type estimate, vectorised over pixels. The
  start is a least-trimmed-squares fit: of the fits that leave out one sample, the one
  with the smallest residual sum (so one grossly wrong frame cannot drag the start). The
  normalised median absolute residual of that start fixes each pixel's noise scale
  (never below the median scale over the image). Then a few iteratively reweighted
  least-squares steps with Tukey's biweight (redescending: samples beyond 4.685 scales
  get weight 0) or Huber's weights (bounded influence) settle the fit. A plain
  M-estimate from the least-squares start does not work here: with 6 samples and 3
  parameters an outlier spreads its residual over the other samples and inflates their
  median absolute residual. An outlier can only be
  told apart with at least 5 distinct angles; with fewer (a polarisation camera has 4,
  whose residuals all have the same size) the robust fit equals the least-squares fit.

Angles are radians, measured from the image's column axis towards its row axis.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..chunks import chunk_bounds, run_chunks
from ..errors import PolarsegError

#: Two polariser angles closer than this (radians, modulo π) are the same state.
ANGLE_TOLERANCE = 1e-6
#: Largest magnitude of a sample: beyond it squares overflow in float64 downstream.
MAX_ABS_VALUE = 1e100
#: Robust losses of :func:`polarisation_image` (``loss=``).
ROBUST_LOSSES = ("tukey", "huber")
#: Tuning constants (in units of the residual scale) for 95 % efficiency under Gaussian noise.
HUBER_C = 1.345
TUKEY_C = 4.685
#: Bits of :attr:`PixelMask.flags` (per sample).
SATURATED, DARK, NONFINITE = 1, 2, 4


@dataclass(frozen=True)
class PolarisationImage:
    """The polarisation image of thesis eq. 4.18 plus fit diagnostics.

    Attributes
    ----------
    intensity : ndarray (H, W)
        Mean intensity Î (units of the input).
    dop : ndarray (H, W)
        Degree of polarisation ρ in [0, 1].
    phase : ndarray (H, W)
        Phase φ, radians in [0, π).
    residual : ndarray (H, W)
        Root-mean-square residual of the sinusoid fit over the pixel's usable samples
        (after averaging repeated angles; units of the input). With the robust fit an
        outlying frame shows here, since it is left out of the fit but not of this RMS.
    invalid : ndarray (H, W) of bool
        Pixels the later stages must not use: Î <= 0, a non-finite sample in any frame,
        fewer than 3 distinct angles with usable samples, or (in the pipeline) outside
        the validity mask. ρ and φ are 0 where Î <= 0 or no fit was possible.
    sample_weights : ndarray (G, H, W) float32 or None
        Final weight of every sample (rows follow ``angles``, after averaging repeated
        angles) in the fit: 1 or 0 for the least-squares fit with missing samples, the
        IRLS weights in [0, 1] for the robust fit, None when every sample had weight 1.
    angles : ndarray (G,) or None
        Angles (radians) of the rows of ``sample_weights``: the distinct polariser states.
    """

    intensity: np.ndarray
    dop: np.ndarray
    phase: np.ndarray
    residual: np.ndarray
    invalid: np.ndarray
    sample_weights: np.ndarray | None = None
    angles: np.ndarray | None = None


def distinct_angle_count(angles: np.ndarray) -> int:
    """Number of distinct polariser states among ``angles`` (radians, modulo π)."""
    a = np.mod(np.asarray(angles, dtype=float), np.pi)
    a = np.sort(a)
    if a.size == 0:
        return 0
    gaps = np.diff(np.concatenate([a, [a[0] + np.pi]]))
    # states separated by less than the tolerance (including across the 0/π wrap) merge
    return max(int(np.count_nonzero(gaps > ANGLE_TOLERANCE)), 1)


def angle_groups(angles: np.ndarray) -> np.ndarray:
    """Polariser state of every frame: frames at the same angle modulo π share a group.

    Parameters
    ----------
    angles : array (N,)
        Polariser angles in radians.

    Returns
    -------
    ndarray (N,) of int
        Group index of each frame, numbered in order of first appearance (0, 1, ...).
        Angles closer than :data:`ANGLE_TOLERANCE` modulo π (0 and π included) share one.

    Examples
    --------
    >>> angle_groups(np.deg2rad([0, 45, 90, 180, 45])).tolist()
    [0, 1, 2, 0, 1]
    """
    a = np.mod(np.asarray(angles, dtype=float).ravel(), np.pi)
    n = a.size
    if n == 0:
        return np.zeros(0, dtype=int)
    order = np.argsort(a, kind="stable")
    sorted_a = a[order]
    runs = np.concatenate([[0], np.cumsum(np.diff(sorted_a) > ANGLE_TOLERANCE)])
    if n > 1 and runs[-1] > 0 and sorted_a[0] + np.pi - sorted_a[-1] <= ANGLE_TOLERANCE:
        runs[runs == runs[-1]] = 0  # the last state wraps round to the first (π ≡ 0)
    raw = np.empty(n, dtype=int)
    raw[order] = runs
    # renumber by first appearance in frame order
    _, first = np.unique(raw, return_index=True)
    rank = np.empty(first.size, dtype=int)
    rank[np.argsort(first)] = np.arange(first.size)
    return rank[np.searchsorted(np.unique(raw), raw)]


def duplicate_angle_frames(angles: np.ndarray) -> list[list[int]]:
    """Frame indices of every polariser state that was captured more than once.

    Examples
    --------
    >>> duplicate_angle_frames(np.deg2rad([0, 45, 90, 180, 135]))
    [[0, 3]]
    """
    groups = angle_groups(angles)
    return [
        np.flatnonzero(groups == g).tolist()
        for g in range(int(groups.max(initial=-1)) + 1)
        if np.count_nonzero(groups == g) > 1
    ]


def average_duplicate_angles(
    stack: np.ndarray, angles: np.ndarray, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Average the frames taken at the same polariser state (angle modulo π).

    Parameters
    ----------
    stack : array (N, ...)
        Frames (any trailing shape); non-finite samples are left out of the averages.
    angles : array (N,)
        Polariser angles in radians.
    weights : array (N, ...), optional
        Sample weights >= 0 (0 = leave out); default 1 for every finite sample.

    Returns
    -------
    stack : ndarray (G, ...) float64
        Per state the weighted mean of its usable samples (0 where it has none).
    angles : ndarray (G,)
        The angle of the first frame of each state.
    weights : ndarray (G, ...) float64
        Per state the summed weight of its usable samples (0 where it has none), so
        that a weighted fit of the averages equals the fit of all the frames.
    """
    data = np.asarray(stack, dtype=np.float64)
    angles = np.asarray(angles, dtype=float).ravel()
    finite = np.isfinite(data)
    w = finite.astype(np.float64) if weights is None else np.where(finite, weights, 0.0)
    groups = angle_groups(angles)
    n_groups = int(groups.max(initial=-1)) + 1
    if n_groups == angles.size:
        return np.where(finite, data, 0.0), angles, w
    onehot = (groups[None, :] == np.arange(n_groups)[:, None]).astype(np.float64)  # (G, N)
    flat_w = w.reshape(angles.size, -1)
    flat_y = np.where(finite, data, 0.0).reshape(angles.size, -1)
    wsum = onehot @ flat_w
    used = onehot @ (flat_w > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = np.where(wsum > 0, (onehot @ (flat_w * flat_y)) / wsum, 0.0)
    first = np.array([np.flatnonzero(groups == g)[0] for g in range(n_groups)])
    shape = (n_groups,) + data.shape[1:]
    return mean.reshape(shape), angles[first], np.where(used > 0, wsum, 0.0).reshape(shape)


def sinusoid_design(angles: np.ndarray) -> np.ndarray:
    """Design matrix (N, 3) with columns 1, cos 2α, sin 2α for angles α in radians."""
    a = np.asarray(angles, dtype=float)
    return np.stack([np.ones_like(a), np.cos(2 * a), np.sin(2 * a)], axis=1)


def check_stack(stack: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate an angle stack; return it (N, H, W) and the angles as float64 (N,).

    A float stack comes back as float64; an integer one (camera counts) as it is: its
    values are exact in float64 and the fit converts them chunk by chunk, so no float64
    copy of the whole stack is made (72 MB for 19 frames of 720 × 660, whose fresh pages
    cost 0.1–0.4 s on the reference machine).

    Raises :class:`PolarsegError` for a wrong shape, a count mismatch between frames and
    angles, fewer than 3 distinct angles modulo π, non-finite angles, data that has no
    finite value at all, or values beyond ±:data:`MAX_ABS_VALUE`.
    """
    stack = np.asarray(stack)
    angles = np.asarray(angles, dtype=float).ravel()
    if stack.ndim != 3:
        raise PolarsegError(
            f"angle stack must have 3 dimensions (angles, rows, columns), got shape {stack.shape}"
        )
    if stack.shape[0] != angles.size:
        raise PolarsegError(
            f"the stack has {stack.shape[0]} frames but {angles.size} angles were given"
        )
    if stack.shape[1] < 1 or stack.shape[2] < 1:
        raise PolarsegError(f"angle stack has an empty frame: shape {stack.shape}")
    if not np.all(np.isfinite(angles)):
        raise PolarsegError("polariser angles must be finite numbers")
    n_distinct = distinct_angle_count(angles)
    if n_distinct < 3:
        raise PolarsegError(
            f"need at least 3 distinct polariser angles (modulo 180 degrees), got {n_distinct}"
        )
    if stack.dtype == np.bool_:
        stack = stack.astype(np.uint8)
    if not np.issubdtype(stack.dtype, np.number) or np.issubdtype(stack.dtype, np.complexfloating):
        raise PolarsegError(f"angle stack must hold real numbers, got dtype {stack.dtype}")
    if np.issubdtype(stack.dtype, np.integer):
        data = np.ascontiguousarray(stack)
        lo, hi = (int(data.min()), int(data.max())) if data.size else (0, 0)
        biggest = float(max(-lo, hi))
    else:
        data = stack.astype(np.float64, copy=False)
        if _all_finite(data):
            # the common case: the extremes, without an |data| copy or a finiteness mask
            biggest = float(max(-data.min(), data.max()))
        else:
            finite = np.isfinite(data)
            if not np.any(finite):
                raise PolarsegError("the angle stack has no finite values (all NaN or infinite)")
            biggest = float(np.max(np.abs(data[finite])))
    if biggest > MAX_ABS_VALUE:
        raise PolarsegError(
            f"intensities up to {biggest:.3g} are too large to process (limit {MAX_ABS_VALUE:g}); "
            "rescale the data"
        )
    return data, angles


def _all_finite(data: np.ndarray) -> bool:
    """True if no value is NaN or infinite (min and max are finite exactly then)."""
    if data.size == 0:
        return True
    return bool(np.isfinite(data.min()) and np.isfinite(data.max()))


def _unweighted_fit(
    data: np.ndarray, angles: np.ndarray, groups: np.ndarray, n_groups: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares fit of eq. 3.14 when every sample counts once: (coef, RMS, angles).

    The fit of the per-state means (frames at one angle modulo π averaged, each state
    weighted by its frame count, as :func:`average_duplicate_angles` with unit weights)
    is linear in the frames: coef = M A x and the residual of the states r = (A − D M A) x
    for a pixel's samples x, with A (G, N) the averaging, D (G, 3) the design and M its
    weighted pseudo-inverse. Both small matrices are formed once and applied to chunks of
    pixels on the cores (no (G, P) array of means or residuals: the means alone were
    68 MB of fresh pages on the 720 × 660 × 19 reference stack, 0.2–0.4 s of a first run).
    Returns ``coef`` (3, P), the RMS residual over the states (P,) and the states' angles.
    """
    n = angles.size
    flat = data.reshape(n, -1)
    counts = np.bincount(groups, minlength=n_groups).astype(np.float64)
    first = np.array([np.flatnonzero(groups == g)[0] for g in range(n_groups)])
    average = (groups[None, :] == np.arange(n_groups)[:, None]) / counts[:, None]  # A
    design = sinusoid_design(angles[first])
    sw = np.sqrt(counts)[:, None]
    to_coef = (np.linalg.pinv(design * sw) * sw.T) @ average  # M A (3, N)
    to_residual = average - design @ to_coef  # (G, N)
    p = flat.shape[1]
    coef = np.empty((3, p))
    residual = np.empty(p)

    def work(a: int, b: int) -> None:
        x = flat[:, a:b]
        np.matmul(to_coef, x, out=coef[:, a:b])
        r = to_residual @ x
        residual[a:b] = np.sqrt(np.einsum("ij,ij->j", r, r) / n_groups)

    step = 1 << 15
    run_chunks(chunk_bounds(p, step), work, p)
    return coef, residual, angles[first]


def _weighted_fit(
    design: np.ndarray, y: np.ndarray, w: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel weighted least squares of y ≈ design @ c.

    ``design`` (G, 3), ``y`` and ``w`` (G, Q). Solves every 3 × 3 normal system in closed
    form (adjugate over determinant, vectorised). Returns ``coef`` (3, Q) and ``ok`` (Q,):
    False where the normal matrix is singular (fewer than 3 distinct angles with positive
    weight); ``coef`` is 0 there.
    """
    pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    products = np.stack([design[:, i] * design[:, j] for i, j in pairs], axis=0)  # (6, G)
    m00, m01, m02, m11, m12, m22 = products @ w  # each (Q,)
    b0, b1, b2 = design.T @ (w * y)  # each (Q,)
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    det = m00 * c00 + m01 * c01 + m02 * c02
    trace = m00 + m11 + m22
    ok = (trace > 0) & (det > 1e-9 * (trace / 3.0) ** 3)
    inv_det = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    coef = np.stack(
        [
            (c00 * b0 + c01 * b1 + c02 * b2) * inv_det,
            (c01 * b0 + c11 * b1 + c12 * b2) * inv_det,
            (c02 * b0 + c12 * b1 + c22 * b2) * inv_det,
        ]
    )
    return coef, ok


def _trimmed_start(
    design: np.ndarray, y: np.ndarray, base: np.ndarray, coef: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Least-trimmed-squares start: per pixel the best fit that leaves out one sample.

    Returns the starting coefficients (3, Q) and the normalised median absolute residual
    of that fit over all usable samples (Q,), the pixel's noise scale.
    Pixels with fewer than 5 usable samples keep ``coef`` (no outlier is detectable).
    """
    usable = base > 0
    n_used = usable.sum(axis=0)
    best_rss = np.full(y.shape[1], np.inf)
    best = coef.copy()
    for k in range(y.shape[0]):
        w = base.copy()
        w[k] = 0.0
        trial, ok = _weighted_fit(design, y, w)
        rss = np.sum(w * (y - design @ trial) ** 2, axis=0)
        better = ok & (rss < best_rss) & (n_used >= 5)
        best = np.where(better, trial, best)
        best_rss = np.where(better, rss, best_rss)
    residual = np.abs(y - design @ best)
    if usable.all():
        mad = np.median(residual, axis=0)
    else:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # pixels with no usable sample
            mad = np.nan_to_num(np.nanmedian(np.where(usable, residual, np.nan), axis=0))
    return best, 1.4826 * mad * np.sqrt(n_used / np.maximum(n_used - 3, 1))


def _irls(
    design: np.ndarray,
    y: np.ndarray,
    base: np.ndarray,
    coef: np.ndarray,
    ok: np.ndarray,
    loss: str,
    iterations: int,
) -> tuple[np.ndarray, np.ndarray]:
    """M-estimate by IRLS from a trimmed start with a fixed scale (module docstring)."""
    coef, scale = _trimmed_start(design, y, base, coef)
    n_used = (base > 0).sum(axis=0)
    detectable = n_used >= 5
    pooled = float(np.median(scale[detectable])) if detectable.any() else 0.0
    floor = 1e-9 * np.abs(coef[0]) + np.finfo(float).tiny
    scale = np.maximum(np.maximum(scale, pooled), floor)
    weights = base
    for _ in range(iterations):
        residual = y - design @ coef
        if loss == "tukey":
            u = np.abs(residual) / (TUKEY_C * scale)
            rw = np.where(u < 1.0, (1.0 - np.minimum(u, 1.0) ** 2) ** 2, 0.0)
        else:
            u = np.abs(residual) / (HUBER_C * scale)
            rw = 1.0 / np.maximum(u, 1.0)
        weights = base * rw
        new, new_ok = _weighted_fit(design, y, weights)
        new_ok &= ok
        step = np.where(new_ok, np.max(np.abs(new - coef), axis=0), 0.0)
        coef = np.where(new_ok, new, coef)
        if np.all(step <= 1e-9 * scale):
            break
    return coef, weights


def polarisation_image(
    stack: np.ndarray,
    angles: np.ndarray,
    robust: bool = False,
    *,
    weights: np.ndarray | None = None,
    loss: str = "tukey",
    iterations: int = 10,
) -> PolarisationImage:
    """Fit thesis eq. 3.14 at every pixel by (optionally robust) least squares.

    Parameters
    ----------
    stack : array (N, H, W)
        Grey images through a linear polariser at the N ``angles``.
    angles : array (N,)
        Polariser angles in radians (any N >= 3 distinct angles modulo π). Frames at the
        same angle modulo π are averaged before the fit (module docstring).
    robust : bool
        Iteratively reweighted least squares that resists outlying frames (module
        docstring) instead of the plain least-squares fit.
    weights : array (N, H, W), optional
        Weight >= 0 of every sample; 0 leaves a sample out (e.g. a saturated or black
        pixel in one frame, :attr:`PixelMask.sample_weights`). Default: 1 for every
        finite sample. Non-finite samples always get weight 0.
    loss : {"tukey", "huber"}
        Robust weights: Tukey's biweight (rejects a grossly wrong sample outright) or
        Huber's (bounded influence, never rejects a sample).
    iterations : int
        Most IRLS iterations (stops earlier once the coefficients settle).

    Returns
    -------
    PolarisationImage
        Î, ρ ∈ [0, 1], φ ∈ [0, π) radians, the RMS fit residual, the invalid mask and the
        final sample weights. A pixel with a non-finite sample in any frame is marked
        invalid (its values come from its finite samples when 3 distinct angles remain).

    Raises
    ------
    PolarsegError
        For a malformed stack or angles (:func:`check_stack`), bad ``weights``, an
        unknown ``loss`` or a non-positive ``iterations``.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.deg2rad([0, 45, 90, 135])
    >>> stack = (2.0 * (1 + 0.3 * np.cos(2 * a - 2 * 0.5)))[:, None, None]
    >>> p = polarisation_image(stack, a)
    >>> round(float(p.intensity[0, 0]), 6), round(float(p.dop[0, 0]), 6)
    (2.0, 0.3)

    A grossly wrong frame among seven is rejected by the robust fit:

    >>> a = np.deg2rad([0, 30, 60, 90, 120, 150, 170])
    >>> stack = (2.0 * (1 + 0.3 * np.cos(2 * a - 2 * 0.5)))[:, None, None]
    >>> stack[3] += 5.0
    >>> lsq, rob = polarisation_image(stack, a), polarisation_image(stack, a, robust=True)
    >>> round(float(lsq.dop[0, 0]), 3), round(float(rob.dop[0, 0]), 6)
    (0.436, 0.3)
    """
    data, angles = check_stack(stack, angles)
    if loss not in ROBUST_LOSSES:
        raise PolarsegError(f"loss must be one of {', '.join(ROBUST_LOSSES)}; got {loss!r}")
    if not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise PolarsegError(f"iterations must be a positive integer, got {iterations!r}")
    n, h, w = data.shape
    groups = angle_groups(angles)
    g = int(groups.max()) + 1
    if weights is None and not (robust and g > 4) and _all_finite(data):
        # every sample usable and weighted once: one pseudo-inverse fits every pixel
        coef, residual, fit_angles = _unweighted_fit(data, angles, groups, g)
        ok = np.ones(coef.shape[1], dtype=bool)
        return _polarisation_result(coef, ok, ok, residual, None, fit_angles, (h, w))
    data = data.astype(np.float64, copy=False)
    finite = np.isfinite(data)
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != data.shape:
            raise PolarsegError(
                f"sample weights have shape {weights.shape} but the stack is {data.shape}"
            )
        if not np.all(np.isfinite(weights)) or np.any(weights < 0):
            raise PolarsegError("sample weights must be finite numbers >= 0")
    bad_pixel = ~np.all(finite, axis=0).ravel()
    fit_y, fit_angles, fit_w = average_duplicate_angles(data, angles, weights)
    g = fit_angles.size
    y = fit_y.reshape(g, -1)
    base = fit_w.reshape(g, -1)
    design = sinusoid_design(fit_angles)
    # Pixels whose every sample is usable share one weight per state (the number of shots
    # averaged into it): one weighted 3 x G pseudo-inverse solves them all at once.
    ref = base.max(axis=1)
    full = np.all(base == ref[:, None], axis=0) if np.all(ref > 0) else np.zeros(y.shape[1], bool)
    uniform = bool(full.all())
    sw = np.sqrt(np.where(ref > 0, ref, 1.0))[:, None]
    solve = np.linalg.pinv(design * sw) * sw.T  # (3, G): weighted least squares
    if uniform:
        coef = solve @ y  # (3, P): the exact least-squares solve
        ok = np.ones(y.shape[1], dtype=bool)
    else:
        coef = np.zeros((3, y.shape[1]))
        ok = full.copy()
        coef[:, full] = solve @ y[:, full]
        part = ~full
        coef[:, part], ok[part] = _weighted_fit(design, y[:, part], base[:, part])
    final_w = base
    if robust and g > 4:
        coef, final_w = _irls(design, y, base, coef, ok, loss, int(iterations))
    usable = base > 0
    n_used = np.maximum(usable.sum(axis=0), 1)
    residual = np.sqrt(np.sum(np.where(usable, (y - design @ coef) ** 2, 0.0), axis=0) / n_used)
    report_w = None
    if not (uniform and final_w is base):
        report_w = final_w.reshape(g, h, w).astype(np.float32)
    return _polarisation_result(coef, ok, ~bad_pixel, residual, report_w, fit_angles, (h, w))


def _polarisation_result(
    coef: np.ndarray,
    ok: np.ndarray,
    good_pixel: np.ndarray,
    residual: np.ndarray,
    report_w: np.ndarray | None,
    fit_angles: np.ndarray,
    shape: tuple[int, int],
) -> PolarisationImage:
    """Î, ρ, φ from the fitted coefficients c = (Î, Îρ cos 2φ, Îρ sin 2φ) of eq. 3.14."""
    c0, c1, c2 = coef
    amp = np.hypot(c1, c2)
    no_value = (c0 <= 0) | ~ok
    invalid = no_value | ~good_pixel
    with np.errstate(divide="ignore", invalid="ignore"):
        dop = np.where(no_value, 0.0, amp / np.where(no_value, 1.0, c0))
    dop = np.clip(dop, 0.0, 1.0)
    phase = np.mod(0.5 * np.arctan2(c2, c1), np.pi)
    phase = np.where(no_value, 0.0, phase)
    # mod can return π itself for tiny negative inputs in floating point
    phase[phase >= np.pi] = 0.0
    intensity = np.where(ok, c0, 0.0)
    h, w = shape
    return PolarisationImage(
        intensity=intensity.reshape(h, w),
        dop=dop.reshape(h, w),
        phase=phase.reshape(h, w),
        residual=np.where(ok, residual, 0.0).reshape(h, w),
        invalid=invalid.reshape(h, w),
        sample_weights=report_w,
        angles=fit_angles,
    )


# -- validity mask --------------------------------------------------------------------------


@dataclass(frozen=True)
class PixelMask:
    """Which samples and pixels the fit and the block features may use.

    A pixel is used only if every one of its samples is usable (not saturated, not black,
    finite) and it lies inside the user's region. Pixels may be excluded for several
    reasons at once; each count below counts a pixel once per reason.

    Attributes
    ----------
    flags : ndarray (N, H, W) uint8
        Per sample, the OR of :data:`SATURATED` (1), :data:`DARK` (2) and
        :data:`NONFINITE` (4); 0 = usable.
    region : ndarray (H, W) of bool or None
        The user's region (True = segment here), or None for the whole image.
    saturation_level : float or None
        Samples at or above it were flagged saturated (None: not checked).
    dark_level : float or None
        Samples at or below it were flagged dark (None: not checked).
    """

    flags: np.ndarray
    region: np.ndarray | None = None
    saturation_level: float | None = None
    dark_level: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the frames."""
        return tuple(self.flags.shape[1:])  # type: ignore[return-value]

    def _any(self, bit: int) -> np.ndarray:
        return np.any(self.flags & bit, axis=0)

    @property
    def saturated(self) -> np.ndarray:
        """(H, W) pixels saturated in at least one frame."""
        return self._any(SATURATED)

    @property
    def dark(self) -> np.ndarray:
        """(H, W) pixels at or below the dark level in at least one frame."""
        return self._any(DARK)

    @property
    def nonfinite(self) -> np.ndarray:
        """(H, W) pixels with a NaN or infinite sample in at least one frame."""
        return self._any(NONFINITE)

    @property
    def outside(self) -> np.ndarray:
        """(H, W) pixels outside the user's region."""
        if self.region is None:
            return np.zeros(self.shape, dtype=bool)
        return ~self.region

    @property
    def valid(self) -> np.ndarray:
        """(H, W) pixels the fit and the features use."""
        ok = ~np.any(self.flags, axis=0)
        return ok if self.region is None else ok & self.region

    @property
    def sample_weights(self) -> np.ndarray:
        """(N, H, W) float64: 1 for usable samples, 0 for flagged ones."""
        return (self.flags == 0).astype(np.float64)

    def counts(self) -> dict[str, Any]:
        """JSON-ready pixel counts per reason and the levels used."""
        valid = self.valid
        return {
            "valid_pixels": int(np.count_nonzero(valid)),
            "masked_pixels": int(valid.size - np.count_nonzero(valid)),
            "saturated_pixels": int(np.count_nonzero(self.saturated)),
            "dark_pixels": int(np.count_nonzero(self.dark)),
            "nonfinite_pixels": int(np.count_nonzero(self.nonfinite)),
            "outside_region_pixels": int(np.count_nonzero(self.outside)),
            "saturation_level": self.saturation_level,
            "dark_level": self.dark_level,
        }

    def shifted(self, shifts: np.ndarray) -> PixelMask:
        """The mask of a registered stack: each frame's flags moved by its shift.

        A flag spreads to every pixel the resampled frame takes a share of the flagged
        sample from (bilinear support), so nothing flagged is lost.
        """
        from scipy import ndimage

        shifts = np.asarray(shifts, dtype=float).reshape(-1, 2)
        out = self.flags.copy()
        for k, d in enumerate(shifts):
            if not np.any(d):
                continue
            frame = np.zeros(self.shape, dtype=np.uint8)
            for bit in (SATURATED, DARK, NONFINITE):
                plane = (self.flags[k] & bit).astype(np.float64)
                if plane.any():
                    moved = ndimage.shift(plane, d, order=1, mode="nearest")
                    frame |= np.where(moved > 1e-6, bit, 0).astype(np.uint8)
            out[k] = frame
        return replace(self, flags=out)


def _level(value: Any, name: str) -> float | None:
    if value is None:
        return None
    try:
        level = float(value)
    except (TypeError, ValueError):
        raise PolarsegError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(level):
        raise PolarsegError(f"{name} must be a finite number, got {value!r}")
    return level


def auto_saturation_level(dtype: np.dtype, bits: int | None = None) -> float | None:
    """Saturation level of integer data: 2**bits − 1, or the dtype's maximum.

    Float data has no natural saturation level (returns None). ``bits`` is the number of
    significant bits (e.g. 12 for a 12-bit camera stored in uint16).
    """
    dtype = np.dtype(dtype)
    if dtype == np.bool_ or not np.issubdtype(dtype, np.integer):
        return None
    top = float(np.iinfo(dtype).max)
    if bits is not None and 0 < bits < np.iinfo(dtype).bits:
        return min(top, float(2**bits - 1))
    return top


def validity_mask(
    stack: np.ndarray,
    saturation: float | str | None = "auto",
    dark_level: float | None = 0.0,
    region: np.ndarray | None = None,
    saturated: np.ndarray | None = None,
) -> PixelMask:
    """Flag saturated, black and non-finite samples and combine them with a user region.

    Parameters
    ----------
    stack : array (N, H, W)
        The angle stack **in the units it was recorded in** (before any conversion that
        loses the saturation level, e.g. dark subtraction or interpolation).
    saturation : float, "auto" or None
        Samples at or above this level are saturated. ``"auto"``: the maximum of an
        integer dtype (255 for uint8, 65535 for uint16), nothing for float data. None:
        no saturation check.
    dark_level : float or None
        Samples at or below this level are black (default 0: exactly black or negative).
        None: no darkness check.
    region : array (H, W), optional
        The user's region: non-zero (True) = segment here, 0 = leave out.
    saturated : array (N, H, W) of bool, optional
        Saturated samples already found (e.g. by the reader on the raw data before dark
        subtraction or demosaicing); used instead of the ``saturation`` level check, and
        ``saturation`` (if a number) is only recorded as the level they were found at.

    Returns
    -------
    PixelMask

    Raises
    ------
    PolarsegError
        If the shapes do not match or a level is not a finite number.

    Examples
    --------
    >>> stack = np.array([[[10, 255]], [[0, 40]], [[30, 50]]], dtype=np.uint8)
    >>> m = validity_mask(stack)
    >>> m.valid.tolist(), m.counts()["saturated_pixels"], m.counts()["dark_pixels"]
    ([[False, False]], 1, 1)
    """
    stack = np.asarray(stack)
    if stack.ndim != 3:
        raise PolarsegError(f"a validity mask needs a stack (N, H, W), got shape {stack.shape}")
    if stack.dtype == np.bool_:
        stack = stack.astype(np.uint8)
    if isinstance(saturation, str):
        if saturation != "auto":
            raise PolarsegError(f"saturation must be a number, 'auto' or None, got {saturation!r}")
        level = auto_saturation_level(stack.dtype)
    else:
        level = _level(saturation, "saturation level")
    dark = _level(dark_level, "dark level")
    # uint8 flags set in place (no int64 temporaries of the stack's size); an integer
    # stack is finite everywhere
    flags = np.zeros(stack.shape, dtype=np.uint8)
    finite = np.isfinite(stack) if stack.dtype.kind == "f" else None

    def flag(bit: int, where: np.ndarray) -> None:
        if finite is not None:
            where &= finite
        np.bitwise_or(flags, np.uint8(bit), out=flags, where=where)

    if finite is not None:
        np.bitwise_or(flags, np.uint8(NONFINITE), out=flags, where=~finite)
    with np.errstate(invalid="ignore"):
        if saturated is not None:
            saturated = np.asarray(saturated, dtype=bool)
            if saturated.shape != stack.shape:
                raise PolarsegError(
                    f"saturated samples have shape {saturated.shape} but the stack is {stack.shape}"
                )
            flag(SATURATED, saturated.copy())
        elif level is not None:
            flag(SATURATED, stack >= level)
        if dark is not None:
            flag(DARK, stack <= dark)
    keep = None
    if region is not None:
        region = np.asarray(region)
        if region.shape != stack.shape[1:]:
            raise PolarsegError(
                f"the mask is {region.shape[0]} x {region.shape[1]} pixels but the frames are "
                f"{stack.shape[1]} x {stack.shape[2]}"
                if region.ndim == 2
                else f"the mask must be a 2-D image, got shape {region.shape}"
            )
        keep = region.astype(bool) if region.dtype.kind != "f" else np.nan_to_num(region) != 0
    return PixelMask(flags, keep, level, dark)


def check_usable(stack: np.ndarray, mask: PixelMask) -> None:
    """Refuse a stack with nothing to segment: no usable pixel, or all samples equal.

    Parameters
    ----------
    stack : array (N, H, W)
        The angle stack (float64 as :func:`check_stack` returns it).
    mask : PixelMask
        Its validity mask.

    Raises
    ------
    PolarsegError
        Naming how many pixels were excluded for which reason, or the constant value.
    """
    valid = mask.valid
    if not valid.any():
        c = mask.counts()
        reasons = [
            f"{c[key]} {label}"
            for key, label in (
                ("saturated_pixels", "saturated"),
                ("dark_pixels", "black (at or below the dark level)"),
                ("nonfinite_pixels", "not finite"),
                ("outside_region_pixels", "outside the mask"),
            )
            if c[key]
        ]
        raise PolarsegError(
            f"no usable pixel: all {valid.size} pixels are excluded ({', '.join(reasons)})"
        )
    if valid.size > 1:
        stack = np.asarray(stack)
        used = stack if valid.all() else stack[:, valid]
        lo, hi = float(np.min(used)), float(np.max(used))
        if lo == hi:
            raise PolarsegError(
                f"the angle stack is constant (every usable sample is {lo:g}): "
                "there is nothing to segment"
            )
