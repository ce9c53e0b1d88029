"""The AoLP/DoLP HSV composite: the standard colour view of a polarisation image.

Each pixel's colour is (hue, saturation, value) with

- hue = φ / π: the angle of linear polarisation (AoLP) φ in [0, π) runs once round the
  hue circle (0° red, 30° yellow, 60° green, 90° cyan, 120° blue, 150° magenta);
- saturation = clip(ρ / ρ_max, 0, 1): the degree of linear polarisation (DoLP) ρ, full
  colour at ``dolp_max`` and above, grey where unpolarised;
- value = clip(Î / Î_p, 0, 1), Î_p the ``intensity_percentile`` (default 99th) of the
  finite, positive Î: dark where the scene is dark.

``mode`` picks the variants polanalyser's ``applyColorToAoLP`` offers: ``"intensity"``
(the above), ``"light"`` (value 1 everywhere: saturation from ρ on a white ground, colour
only where polarised) and ``"dark"`` (saturation 1, value from ρ: colour only where
polarised, on black). Non-finite inputs are black. The HSV → RGB conversion is
:func:`hsv_to_rgb` (the closed form; matplotlib's and scikit-image's agree with it to 1e-6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PolarsegError

#: Variants of :func:`aolp_dolp_composite` (``CompositeParams.mode``).
COMPOSITE_MODES = ("intensity", "light", "dark")


@dataclass(frozen=True)
class CompositeParams:
    """Settings of the HSV composite.

    Attributes
    ----------
    dolp_max : float
        DoLP ρ drawn at full saturation (or full value in the ``"dark"`` mode); in (0, 1].
    mode : str
        One of :data:`COMPOSITE_MODES`.
    intensity_percentile : float
        Percentile of the finite, positive Î mapped to value 1 (``"intensity"`` mode).
    """

    dolp_max: float = 1.0
    mode: str = "intensity"
    intensity_percentile: float = 99.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dolp_max) and 0.0 < self.dolp_max <= 1.0):
            raise PolarsegError(f"dolp_max must be in (0, 1], got {self.dolp_max!r}")
        if self.mode not in COMPOSITE_MODES:
            raise PolarsegError(
                f"mode must be one of {', '.join(COMPOSITE_MODES)}, got {self.mode!r}"
            )
        if not 0.0 < self.intensity_percentile <= 100.0:
            raise PolarsegError(
                f"intensity_percentile must be in (0, 100], got {self.intensity_percentile!r}"
            )


def auto_dolp_max(dop: np.ndarray, percentile: float = 99.0, step: float = 0.05) -> float:
    """A ρ_max that shows a scene's polarisation: its ``percentile`` of ρ, rounded up.

    The ``percentile`` of the finite ρ, rounded up to a multiple of ``step`` and kept in
    [``step``, 1]: a diffuse scene (ρ below 0.1) gets full colour at its strongest
    pixels instead of a grey picture.

    Examples
    --------
    >>> auto_dolp_max(np.linspace(0.0, 0.08, 101))
    0.1
    """
    rho = np.asarray(dop, dtype=np.float64)
    rho = rho[np.isfinite(rho)]
    if rho.size == 0:
        return 1.0
    top = float(np.percentile(rho, percentile))
    return float(np.clip(np.ceil(round(top / step, 9)) * step, step, 1.0).round(6))


def intensity_value(intensity: np.ndarray, percentile: float = 99.0) -> np.ndarray:
    """Î / Î_p clipped to [0, 1], Î_p the ``percentile`` of the finite, positive Î.

    Returns zeros where Î is not finite, and all zeros if no Î is positive.
    """
    i = np.asarray(intensity, dtype=np.float64)
    good = np.isfinite(i) & (i > 0)
    if not good.any():
        return np.zeros(i.shape)
    top = float(np.percentile(i[good], percentile))
    return np.where(good, np.clip(i / top, 0.0, 1.0), 0.0)


def hsv_planes(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    params: CompositeParams | None = None,
) -> np.ndarray:
    """The composite's hue, saturation and value in [0, 1] (H, W, 3), before RGB.

    Hue = (φ mod π) / π, saturation and value as the module docstring says.
    """
    params = CompositeParams() if params is None else params
    rho = np.asarray(dop, dtype=np.float64)
    phi = np.asarray(phase, dtype=np.float64)
    if rho.shape != phi.shape or np.shape(intensity) != rho.shape:
        raise PolarsegError(
            f"Î {np.shape(intensity)}, ρ {rho.shape} and φ {phi.shape} must have one shape"
        )
    finite = np.isfinite(rho) & np.isfinite(phi) & np.isfinite(intensity)
    hue = np.where(finite, np.mod(phi, np.pi) / np.pi, 0.0)
    hue = np.where(hue >= 1.0, 0.0, hue)  # mod can round up to π itself
    dolp = np.where(finite, np.clip(rho / params.dolp_max, 0.0, 1.0), 0.0)
    if params.mode == "intensity":
        saturation, value = dolp, intensity_value(intensity, params.intensity_percentile)
    elif params.mode == "light":
        saturation, value = dolp, np.ones_like(dolp)
    else:  # dark
        saturation, value = np.ones_like(dolp), dolp
    value = np.where(finite, value, 0.0)
    return np.stack([hue, saturation, value], axis=-1)


def hsv_to_rgb(hsv: np.ndarray) -> np.ndarray:
    """RGB (..., 3) of HSV (..., 3), every channel in [0, 1], in the dtype of ``hsv``.

    The closed form: channel n ∈ (5, 3, 1) for (R, G, B) is V − V·S·clip(min(k, 4 − k),
    0, 1) with k = (n + 6H) mod 6. Written here because matplotlib's ``hsv_to_rgb`` and
    scikit-image's ``hsv2rgb`` take several times as long on a camera frame (boolean masks,
    six stacked candidates) and the composite is drawn on every run.
    """
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    out = np.empty(hsv.shape, dtype=hsv.dtype)
    six = h * hsv.dtype.type(6)
    for channel, n in enumerate((5, 3, 1)):
        k = np.mod(n + six, 6)
        np.minimum(k, 4 - k, out=k)
        np.clip(k, 0, 1, out=k)
        out[..., channel] = v - v * s * k
    return out


def aolp_dolp_composite(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    params: CompositeParams | None = None,
) -> np.ndarray:
    """The HSV composite of a polarisation image as an RGB image.

    Parameters
    ----------
    intensity : array (H, W)
        Mean intensity Î (input units).
    dop : array (H, W)
        Degree of linear polarisation ρ in [0, 1].
    phase : array (H, W)
        Angle of linear polarisation φ, radians (taken modulo π).
    params : CompositeParams, optional
        ρ at full saturation, the variant, the Î normalisation.

    Returns
    -------
    ndarray (H, W, 3) uint8
        RGB, 0..255 (rounded).

    Examples
    --------
    >>> rgb = aolp_dolp_composite(np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)))
    >>> rgb[0, 0].tolist()  # φ = 0, fully polarised, bright: pure red
    [255, 0, 0]
    """
    # float32: faster than float64, and an 8-bit picture needs no more
    rgb = hsv_to_rgb(hsv_planes(intensity, dop, phase, params).astype(np.float32))
    return np.round(np.clip(rgb, 0.0, 1.0) * np.float32(255.0)).astype(np.uint8)
