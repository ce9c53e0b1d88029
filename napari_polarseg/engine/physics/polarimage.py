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

The least-squares fit (plain or weighted) runs chunk by chunk over the pixels, on the
cores, each chunk writing its slice of preallocated maps (:class:`~.fit_maps.FitMaps`):
its memory is the maps (33 bytes a pixel, plus the final weights when kept) and a few
chunks whatever the image's size, and the maps are those of one whole-image pass to the
bit. The robust fit (its IRLS iterations stop together) runs on the whole image.

Angles are radians, measured from the image's column axis towards its row axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..chunks import Progress, chunk_bounds, run_chunks
from ..errors import PolarsegError
from .fit_maps import FitMaps
from .sinusoid_fit import (
    ROBUST_LOSSES,
    irls,
    sinusoid_design,
    unweighted_chunk,
    unweighted_solver,
    weighted_fit,
)

#: Two polariser angles closer than this (radians, modulo π) are the same state.
ANGLE_TOLERANCE = 1e-6
#: Largest magnitude of a sample: beyond it squares overflow in float64 downstream.
MAX_ABS_VALUE = 1e100
#: Pixels per chunk of the weighted least-squares fit (:class:`_WeightedFit`). The
#: chunks' small matrix products may take other BLAS kernels at another chunk size,
#: so the sizes stay those the maps were first computed with: the maps do not change
#: to the bit (1 << 16 would be faster and lighter, and change the last bit of some).
FIT_CHUNK_PIXELS = 1 << 18
#: Pixels per chunk of the unweighted least-squares fit (:func:`_plain_fit`).
PLAIN_CHUNK_PIXELS = 1 << 15


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
    groups = angle_groups(angles)
    n_groups = int(groups.max(initial=-1)) + 1
    finite = np.isfinite(data)
    all_finite = bool(finite.all())
    if weights is None:
        w = finite.astype(np.float64)
    else:  # every sample finite (the usual case): no masked copy of the weights
        w = np.asarray(weights, dtype=np.float64) if all_finite else np.where(finite, weights, 0.0)
    if n_groups == angles.size:
        return (data if all_finite else np.where(finite, data, 0.0)), angles, w
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


def polarisation_image(
    stack: np.ndarray,
    angles: np.ndarray,
    robust: bool = False,
    *,
    weights: np.ndarray | None = None,
    loss: str = "tukey",
    iterations: int = 10,
    keep_weights: bool = True,
    progress: Progress | None = None,
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
    keep_weights : bool
        Return ``sample_weights`` (4·G bytes a pixel); False: None (the pipeline's).
    progress : callable(share), optional
        Called with the share fitted (0..1]; what it raises stops the fit there.

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
    _check_robust_options(loss, iterations)
    n, h, w = data.shape
    groups = angle_groups(angles)
    g = int(groups.max()) + 1
    robust = robust and g > 4
    if weights is None and not robust and _all_finite(data):
        # every sample usable and weighted once: one pseudo-inverse fits every pixel
        maps, fit_angles = _plain_fit(data.reshape(n, -1), angles, groups, progress)
        return _image(maps, (h, w), None, fit_angles)
    fit = _WeightedFit(loss, int(iterations), keep_weights, progress)
    return fit.run(data, angles, _checked_weights(weights, data.shape), robust)


def _check_robust_options(loss: str, iterations: int) -> None:
    """Raise for an unknown ``loss`` or a non-positive ``iterations``."""
    if loss not in ROBUST_LOSSES:
        raise PolarsegError(f"loss must be one of {', '.join(ROBUST_LOSSES)}; got {loss!r}")
    if not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise PolarsegError(f"iterations must be a positive integer, got {iterations!r}")


def _checked_weights(weights: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
    """``weights`` as an array of the stack's ``shape`` (any real dtype: bool weights
    are 0 or 1, converted chunk by chunk); raises for another shape or a negative or
    non-finite weight."""
    if weights is None:
        return None
    weights = np.asarray(weights)
    if weights.shape != shape:
        raise PolarsegError(f"sample weights have shape {weights.shape} but the stack is {shape}")
    if not (_all_finite(weights) and (weights.size == 0 or weights.min() >= 0)):
        raise PolarsegError("sample weights must be finite numbers >= 0")
    return weights


def _every_percent(progress: Progress | None) -> Progress | None:
    """``progress`` called once a percent of the work more is done (and at the end)."""
    if progress is None:
        return None
    last = [0.0]

    def report(share: float) -> None:
        if share >= 1.0 or share >= last[0] + 0.01:
            last[0] = share
            progress(share)

    return report


def _plain_fit(
    flat: np.ndarray, angles: np.ndarray, groups: np.ndarray, progress: Progress | None
) -> tuple[FitMaps, np.ndarray]:
    """The unweighted least-squares fit of eq. 3.14 of ``flat`` (N, P) in chunks of
    :data:`PLAIN_CHUNK_PIXELS` pixels on the cores
    (:func:`~.sinusoid_fit.unweighted_chunk`), written into the maps; returns them and
    the states' angles (radians)."""
    to_coef, to_residual, fit_angles = unweighted_solver(angles, groups, int(groups.max()) + 1)
    p = flat.shape[1]
    maps = FitMaps.empty(p)

    def work(a: int, b: int) -> None:
        coef, residual = unweighted_chunk(to_coef, to_residual, flat[:, a:b])
        maps.write(a, b, coef, None, None, residual)

    run_chunks(chunk_bounds(p, PLAIN_CHUNK_PIXELS), work, p, _every_percent(progress))
    return maps, fit_angles


@dataclass(frozen=True)
class _WeightedFit:
    """:func:`polarisation_image` with sample weights, missing samples or the robust fit.

    Duplicate angles averaged (:func:`average_duplicate_angles`), then one weighted
    pseudo-inverse for the pixels whose every sample is usable and a 3 × 3 solve per
    pixel for the others (:func:`_fit_pixels`); robust: IRLS with ``loss`` from there
    (eq. 3.14). The least-squares fit runs on chunks of :data:`FIT_CHUNK_PIXELS` pixels
    on the cores (:func:`~..chunks.run_chunks`), each written into the maps: its float64
    temporaries stay small and are reused instead of a dozen whole-image arrays of fresh
    pages (3× faster on a camera frame). The robust fit, whose iterations stop
    together, runs on the whole image.
    """

    loss: str
    iterations: int
    keep_weights: bool
    progress: Progress | None

    def run(
        self, data: np.ndarray, angles: np.ndarray, weights: np.ndarray | None, robust: bool
    ) -> PolarisationImage:
        n, h, w = data.shape
        p = h * w
        flat = data.reshape(n, -1)
        flat_w = None if weights is None else weights.reshape(n, -1)
        maps = FitMaps.empty(p)
        if robust:
            coef, ok, good, residual, final_w, _, fit_angles = _fit_pixels(
                flat, angles, flat_w, True, self.loss, self.iterations
            )
            maps.write(0, p, coef, ok, good, residual)
            report_w = None
            if final_w is not None and self.keep_weights:
                report_w = final_w.reshape(-1, h, w).astype(np.float32)
            return _image(maps, (h, w), report_w, fit_angles)
        g = int(angle_groups(angles).max()) + 1
        # pages touched only where written
        final = np.empty((g, p), dtype=np.float32) if self.keep_weights else None
        uniform: dict[int, np.ndarray] = {}  # chunk start -> its one weight per state
        states: list[np.ndarray] = []

        def work(a: int, b: int) -> None:
            w_ab = None if flat_w is None else flat_w[:, a:b]
            c, o, gd, r, f, ref, fa = _fit_pixels(flat[:, a:b], angles, w_ab, False, self.loss, 1)
            maps.write(a, b, c, o, gd, r)
            if f is None:
                uniform[a] = ref
            elif final is not None:
                final[:, a:b] = f
            states.append(fa)

        bounds = chunk_bounds(p, FIT_CHUNK_PIXELS)
        run_chunks(bounds, work, p, self.progress)
        report_w = None
        if final is not None and len(uniform) < len(bounds):  # a pixel had a missing sample
            for a, ref in uniform.items():
                final[:, a : a + FIT_CHUNK_PIXELS] = ref[:, None]
            report_w = final.reshape(g, h, w)
        return _image(maps, (h, w), report_w, states[0])


def _fit_pixels(
    data: np.ndarray,
    angles: np.ndarray,
    weights: np.ndarray | None,
    robust: bool,
    loss: str,
    iterations: int,
) -> tuple[np.ndarray, ...]:
    """The fit of eq. 3.14 for pixels (columns) of ``data`` (N, Q) with ``weights``
    (N, Q) or None: (coef (3, Q), ok (Q,), good (Q,): every sample finite, RMS residual
    (Q,), final weights (G, Q) or None when every pixel had the weights ``ref`` (G,),
    ``ref``, the states' angles)."""
    data = data.astype(np.float64, copy=False)
    bad_pixel = ~np.all(np.isfinite(data), axis=0)
    fit_y, fit_angles, fit_w = average_duplicate_angles(data, angles, weights)
    y, base = fit_y, fit_w
    design = sinusoid_design(fit_angles)
    # Pixels whose every sample is usable share one weight per state (the number of shots
    # averaged into it): one weighted 3 x G pseudo-inverse solves them all at once.
    ref = base.max(axis=1)
    full = np.all(base == ref[:, None], axis=0) if np.all(ref > 0) else np.zeros(y.shape[1], bool)
    uniform = bool(full.all())
    sw = np.sqrt(np.where(ref > 0, ref, 1.0))[:, None]
    solve = np.linalg.pinv(design * sw) * sw.T  # (3, G): weighted least squares
    coef = solve @ y  # (3, P): the exact least-squares solve of the full pixels
    ok = np.ones(y.shape[1], dtype=bool) if uniform else full.copy()
    if not uniform:  # the others: one weighted solve each (a product of every pixel,
        part = ~full  # then these overwritten, costs less than gathering the full ones)
        coef[:, part], ok[part] = weighted_fit(design, y[:, part], base[:, part])
    final_w = base
    if robust:
        coef, final_w = irls(design, y, base, coef, ok, loss, iterations)
    usable = base > 0
    n_used = np.maximum(usable.sum(axis=0), 1)
    misfit = design @ coef
    misfit -= y
    misfit *= misfit
    misfit[~usable] = 0.0
    residual = np.sqrt(misfit.sum(axis=0) / n_used)
    reported = None if (uniform and final_w is base) else final_w
    return coef, ok, ~bad_pixel, residual, reported, ref, fit_angles


def _image(
    maps: FitMaps,
    shape: tuple[int, int],
    report_w: np.ndarray | None,
    fit_angles: np.ndarray,
) -> PolarisationImage:
    """The :class:`PolarisationImage` of the written maps (views, no copy)."""
    intensity, dop, phase, residual, invalid = maps.shaped(shape)
    return PolarisationImage(intensity, dop, phase, residual, invalid, report_w, fit_angles)
