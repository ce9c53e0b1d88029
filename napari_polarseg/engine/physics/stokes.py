"""Linear Stokes components S0, S1, S2 from the polarisation image (Î, ρ, φ).

A linear polariser at angle α transmits, in Stokes form,

    I(α) = ½ (S0 + S1 cos 2α + S2 sin 2α),

which is the engine's sinusoid (thesis eq. 3.14) I(α) = Î (1 + ρ cos(2α − 2φ)) with

    S0 = 2 Î,    S1 = S0 ρ cos 2φ,    S2 = S0 ρ sin 2φ.

So S0 is the total intensity (I(0°) + I(90°), twice the mean intensity Î, in the input's
units); on a four-angle camera S1 = I(0°) − I(90°) and S2 = I(45°) − I(135°). ρ = √(S1² +
S2²) / S0 and φ = ½ atan2(S2, S1) give the polarisation image back (the AoLP is φ, the
DoLP ρ).

Angle convention (the package's, see :mod:`napari_polarseg.engine.physics.polarimage`): α and φ
are measured from the image's column axis (along a row, towards larger column index: 0°
points right) towards its row axis (towards larger row index: 90° points down). On an
image shown with row 0 at the top that is clockwise. S1 > 0 means polarised along the
rows (horizontal), S1 < 0 along the columns (vertical), S2 > 0 along the diagonal from
the top-left to the bottom-right corner (45°).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Names of the planes of :func:`stokes_components`, in order.
STOKES_COMPONENTS = ("S0", "S1", "S2")

#: What ``stokes.tif`` says of its planes and their convention (its JSON ImageDescription).
STOKES_CONVENTION: dict[str, Any] = {
    "quantity": "linear Stokes components",
    "dimensions": "component, row, column",
    "components": list(STOKES_COMPONENTS),
    "definition": "I(alpha) = (S0 + S1 cos 2alpha + S2 sin 2alpha) / 2 for a linear "
    "polariser at alpha; S0 = 2 I_mean (= I(0) + I(90)), S1 = S0 rho cos 2phi "
    "(= I(0) - I(90)), S2 = S0 rho sin 2phi (= I(45) - I(135))",
    "angle_zero": "along the image rows (towards larger column index)",
    "angle_direction": "from the column axis towards the row axis (towards larger row "
    "index): clockwise on an image shown with row 0 at the top",
    "unit": "input units",
}


def stokes_components(intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """S0, S1, S2 of the polarisation image: S0 = 2Î, S1 = S0 ρ cos 2φ, S2 = S0 ρ sin 2φ.

    Parameters
    ----------
    intensity : array (H, W)
        Mean intensity Î (input units).
    dop : array (H, W)
        Degree of linear polarisation ρ in [0, 1].
    phase : array (H, W)
        Angle of linear polarisation φ, radians (any range; only 2φ enters).

    Returns
    -------
    ndarray (3, H, W) float64
        S0, S1, S2 in the input's units; non-finite inputs give non-finite components.

    Examples
    --------
    >>> s = stokes_components(np.array([[1.0]]), np.array([[0.5]]), np.array([[0.0]]))
    >>> s[:, 0, 0].tolist()
    [2.0, 1.0, 0.0]
    """
    i = np.asarray(intensity, dtype=np.float64)
    rho = np.asarray(dop, dtype=np.float64)
    phi = np.asarray(phase, dtype=np.float64)
    s0 = 2.0 * i
    return np.stack([s0, s0 * rho * np.cos(2.0 * phi), s0 * rho * np.sin(2.0 * phi)])
