"""The maps of the polarisation image, written chunk by chunk into preallocated arrays.

The sinusoid of thesis eq. 3.14, I(α) = c0 + c1 cos 2α + c2 sin 2α, is fitted per pixel
(:mod:`.sinusoid_fit`); its coefficients give

    Î = c0,    ρ = √(c1² + c2²) / c0  (clipped to [0, 1]),    φ = ½ atan2(c2, c1) mod π,

Î in the input's units, ρ dimensionless, φ in radians. :class:`FitMaps` holds the four
float64 maps (Î, ρ, φ and the RMS residual of the fit, input units) and the invalid
mask, allocated once for the whole image (in temporary files when they do not fit the
run's memory limit: :mod:`..disk_arrays`); each chunk of pixels writes its own slice
(:meth:`FitMaps.write`), so no whole-image coefficient array or float64 temporary is
ever made: the fit's memory is the maps (33 bytes a pixel) plus one chunk's. Every
pixel goes through the same operations as in one whole-image pass, in the same order,
so the maps are the same to the bit however the image is cut.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import disk_arrays

#: Bytes a pixel of the maps of :class:`FitMaps`: four float64 maps and the invalid mask.
FIT_MAP_BYTES = 4 * 8 + 1


@dataclass(frozen=True)
class FitMaps:
    """Flat (P,) outputs of the fit, P = H·W: Î, ρ, φ, RMS residual (float64) and the
    invalid pixels (bool), each written by the chunks of :meth:`write`."""

    intensity: np.ndarray
    dop: np.ndarray
    phase: np.ndarray
    residual: np.ndarray
    invalid: np.ndarray

    @classmethod
    def empty(cls, pixels: int) -> FitMaps:
        """Uninitialised maps of ``pixels`` pixels (pages are touched as chunks write):
        in memory, or in temporary files when the run's full-size arrays do not fit its
        work limit (:func:`~..disk_arrays.empty`)."""
        maps = [disk_arrays.empty((pixels,)) for _ in range(4)]
        return cls(*maps, invalid=disk_arrays.empty((pixels,), dtype=bool))

    def write(
        self,
        start: int,
        stop: int,
        coef: np.ndarray,
        ok: np.ndarray | None,
        good: np.ndarray | None,
        residual: np.ndarray,
    ) -> None:
        """Write pixels ``start:stop`` from their fit.

        Parameters
        ----------
        coef : ndarray (3, Q)
            c0, c1, c2 of eq. 3.14 for the Q = stop − start pixels.
        ok : ndarray (Q,) of bool or None
            The fit was possible (at least 3 distinct angles with usable samples);
            None: every pixel.
        good : ndarray (Q,) of bool or None
            Every sample of the pixel was finite; None: every pixel.
        residual : ndarray (Q,)
            RMS residual of the fit (input units).

        Where the fit failed or Î = c0 <= 0, ρ and φ are 0 and the pixel is invalid;
        where it failed, Î and the residual are 0 too.
        """
        c0, c1, c2 = coef
        no_value = c0 <= 0
        if ok is not None:
            no_value |= ~ok
        part = slice(start, stop)
        if good is None:
            self.invalid[part] = no_value
        else:
            np.logical_or(no_value, ~good, out=self.invalid[part])
        ratio = np.hypot(c1, c2)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio /= np.where(no_value, 1.0, c0)
        ratio[no_value] = 0.0
        np.clip(ratio, 0.0, 1.0, out=self.dop[part])
        phase = np.arctan2(c2, c1)
        phase *= 0.5
        np.mod(phase, np.pi, out=phase)
        phase[no_value] = 0.0
        # mod can return π itself for tiny negative inputs in floating point
        phase[phase >= np.pi] = 0.0
        self.phase[part] = phase
        if ok is None:
            self.intensity[part] = c0
            self.residual[part] = residual
        else:
            np.copyto(self.intensity[part], np.where(ok, c0, 0.0))
            np.copyto(self.residual[part], np.where(ok, residual, 0.0))

    def shaped(self, shape: tuple[int, int]) -> tuple[np.ndarray, ...]:
        """(Î, ρ, φ, residual, invalid) as (H, W) views."""
        return tuple(
            m.reshape(shape)
            for m in (self.intensity, self.dop, self.phase, self.residual, self.invalid)
        )
