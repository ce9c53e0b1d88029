"""The mask of usable samples and pixels: saturated, black, non-finite, outside a region.

:class:`PixelMask` holds one flag byte per sample (:data:`SATURATED`, :data:`DARK`,
:data:`NONFINITE`) and the user's region; :func:`~.polarimage.validity_mask` builds it
from a stack and the levels (:func:`auto_saturation_level` for integer data).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import PolarsegError

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
