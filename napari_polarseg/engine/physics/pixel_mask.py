"""The mask of usable samples and pixels: saturated, black, non-finite, outside a region.

:class:`PixelMask` holds one flag byte per sample (:data:`SATURATED`, :data:`DARK`,
:data:`NONFINITE`) and the user's region; :func:`validity_mask` builds it
from a stack and the levels (:func:`auto_saturation_level` for integer data).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .. import disk_arrays
from ..errors import PolarsegError
from ..tiles import row_bands

#: The word for each excluded-pixel count of :meth:`PixelMask.counts` (and of a result's
#: ``mask_counts``), in the order messages list them.
MASK_REASONS: tuple[tuple[str, str], ...] = (
    ("saturated_pixels", "saturated"),
    ("dark_pixels", "black"),
    ("nonfinite_pixels", "not finite"),
    ("outside_region_pixels", "outside the mask"),
)


def mask_reasons(counts: dict[str, Any], dark: str = "black") -> list[str]:
    """``["12 saturated", "3 black", ...]``: the non-zero counts of ``counts`` with their
    words (:data:`MASK_REASONS`); ``dark`` is the word for the dark pixels."""
    words = {**dict(MASK_REASONS), "dark_pixels": dark}
    return [f"{int(counts[key])} {words[key]}" for key, _ in MASK_REASONS if counts.get(key)]


#: Bits of :attr:`PixelMask.flags` (per sample).
SATURATED, DARK, NONFINITE = 1, 2, 4
#: Pixels of a band :meth:`PixelMask.counts` counts at once.
COUNT_ROWS_PIXELS = 1 << 20


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

    def _any(self, bit: int, rows: slice = slice(None)) -> np.ndarray:
        """(h, W) pixels of ``rows`` with ``bit`` set in any frame, frame by frame (no
        (N, h, W) temporary)."""
        out = np.zeros(self.flags[0, rows].shape, dtype=bool)
        for frame in self.flags:
            out |= (frame[rows] & bit) != 0
        return out

    def _valid(self, rows: slice = slice(None)) -> np.ndarray:
        """(h, W) pixels of ``rows`` the fit and the features use."""
        ok = np.ones(self.flags[0, rows].shape, dtype=bool)
        for frame in self.flags:
            ok &= frame[rows] == 0
        return ok if self.region is None else ok & self.region[rows]

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
        return self._valid()

    @property
    def sample_weights(self) -> np.ndarray:
        """(N, H, W) float64: 1 for usable samples, 0 for flagged ones."""
        return (self.flags == 0).astype(np.float64)

    def counts(self) -> dict[str, Any]:
        """JSON-ready pixel counts per reason and the levels used, counted a band of
        :data:`COUNT_ROWS_PIXELS` pixels at a time (no full-size mask: a 100 MP frame's
        four masks and their temporaries were 0.5 GB at once), the flags' pages on disk
        given back after each band."""
        h, w = self.shape
        total = {"valid": 0, "saturated": 0, "dark": 0, "nonfinite": 0}
        bits = {"saturated": SATURATED, "dark": DARK, "nonfinite": NONFINITE}
        for band in row_bands(h, max(1, COUNT_ROWS_PIXELS // max(w, 1))):
            total["valid"] += int(np.count_nonzero(self._valid(band)))
            for name, bit in bits.items():
                total[name] += int(np.count_nonzero(self._any(bit, band)))
            disk_arrays.release(self.flags)
        outside = (
            0 if self.region is None else int(self.region.size - np.count_nonzero(self.region))
        )
        return {
            "valid_pixels": total["valid"],
            "masked_pixels": h * w - total["valid"],
            "saturated_pixels": total["saturated"],
            "dark_pixels": total["dark"],
            "nonfinite_pixels": total["nonfinite"],
            "outside_region_pixels": outside,
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


def finite_level(value: Any, name: str) -> float | None:
    """``value`` as a finite float (None stays None); PolarsegError naming ``name`` else."""
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


def fill_from_nearest(valid: np.ndarray, *maps: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every map with each pixel outside ``valid`` replaced by the nearest valid pixel's
    value (Euclidean distance, :func:`scipy.ndimage.distance_transform_edt`).

    What a method that filters or groups pixels (superpixels, Gaussian features) reads
    instead of the raw maps when the user restricts it to a region: the filled maps are
    a function of the valid pixels alone, so nothing outside the region can move a
    label inside it. Maps are returned unchanged (not copied) when every pixel is valid.

    Raises
    ------
    PolarsegError
        No valid pixel at all.
    """
    valid = np.asarray(valid, dtype=bool)
    if valid.all():
        return maps
    ri, ci = nearest_valid(valid)
    return tuple(np.asarray(m)[ri, ci] for m in maps)


def nearest_valid(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) (each H × W) of the nearest ``valid`` pixel of every pixel
    (itself where valid): the indices :func:`fill_from_nearest` reads, to keep when the
    same mask fills many maps."""
    from scipy import ndimage

    valid = np.asarray(valid, dtype=bool)
    if not valid.any():
        raise PolarsegError("the mask leaves no pixel to segment")
    _, (ri, ci) = ndimage.distance_transform_edt(~valid, return_indices=True)
    return ri, ci


# -- the mask of a stack ---------------------------------------------------------------


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
    level = _saturation_level(saturation, stack.dtype)
    dark = finite_level(dark_level, "dark level")
    # uint8 flags set in place (no int64 temporaries of the stack's size); an integer
    # stack is finite everywhere
    # (in a temporary file when the run's full-size arrays do not fit its limit)
    flags = disk_arrays.zeros(stack.shape, dtype=np.uint8)
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
    keep = None if region is None else _region_pixels(region, stack.shape)
    return PixelMask(flags, keep, level, dark)


def _saturation_level(saturation: float | str | None, dtype: np.dtype) -> float | None:
    """The level of :func:`validity_mask`'s ``saturation``: a number, "auto" or None."""
    if isinstance(saturation, str):
        if saturation != "auto":
            raise PolarsegError(f"saturation must be a number, 'auto' or None, got {saturation!r}")
        return auto_saturation_level(dtype)
    return finite_level(saturation, "saturation level")


def _region_pixels(region: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The user's region of a stack of ``shape`` (N, H, W) as (H, W) bool: non-zero = in."""
    region = np.asarray(region)
    if region.shape != shape[1:]:
        raise PolarsegError(
            f"the mask is {region.shape[0]} x {region.shape[1]} pixels but the frames are "
            f"{shape[1]} x {shape[2]}"
            if region.ndim == 2
            else f"the mask must be a 2-D image, got shape {region.shape}"
        )
    return region.astype(bool) if region.dtype.kind != "f" else np.nan_to_num(region) != 0


def usable_extremes(stack: np.ndarray, valid: np.ndarray) -> tuple[float, float]:
    """(lowest, highest) sample of the ``valid`` (H, W) pixels of ``stack`` (N, H, W),
    in the stack's units: reduced where they are valid, without a copy of the samples
    or their indices (a boolean index of a 100 MP frame made two int64 index arrays,
    1.6 GB)."""
    if valid.all():
        return float(np.min(stack)), float(np.max(stack))
    kind = stack.dtype.kind
    if kind not in "iuf":  # pragma: no cover - check_stack gives numbers
        used = stack[:, valid]
        return float(np.min(used)), float(np.max(used))
    info = np.iinfo(stack.dtype) if kind in "iu" else None
    top = info.max if info is not None else np.inf
    bottom = info.min if info is not None else -np.inf
    where = valid[None]
    lo = np.min(stack, where=where, initial=top)
    hi = np.max(stack, where=where, initial=bottom)
    return float(lo), float(hi)


def check_usable(stack: np.ndarray, mask: PixelMask) -> None:
    """Refuse a stack with nothing to segment: no usable pixel, or all samples equal.

    Parameters
    ----------
    stack : array (N, H, W)
        The angle stack (float64 as :func:`~.polarimage.check_stack` returns it).
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
        reasons = mask_reasons(c, dark="black (at or below the dark level)")
        raise PolarsegError(
            f"no usable pixel: all {valid.size} pixels are excluded ({', '.join(reasons)})"
        )
    if valid.size > 1:
        lo, hi = usable_extremes(np.asarray(stack), valid)
        if lo == hi:
            raise PolarsegError(
                f"the angle stack is constant (every usable sample is {lo:g}): "
                "there is nothing to segment"
            )
