"""What reading an angle stack gives (:class:`StackData`) and what is subtracted from
its samples (:class:`BlackLevel`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..engine.errors import PolarsegError
from ..engine.physics.mosaic import subtract_dark
from .common import input_error


@dataclass
class StackData:
    """An angle stack as read from disk.

    Attributes
    ----------
    stack : ndarray (N, H, W)
        Grey frames, real numbers (the file's dtype where no conversion was needed;
        float64 after dark subtraction, interpolated demosaicing or luma conversion).
    angles_deg : ndarray (N,) float64
        Polariser angle of each frame, degrees.
    source : str
        The file or folder read (the first file, for a list of files).
    metadata : dict
        What else was learned: ``format``, ``saturation_level`` (None: not checked),
        ``bits_per_sample`` (TIFF), and per format ``files`` (folder, list), ``demosaic``,
        ``mosaic_layout_deg`` and ``raw_shape`` (mosaic), ``params`` (npz), ``dark_frame``
        and ``offset`` (when subtracted), ``warnings``.
    ground_truth : ndarray (H, W) or None
        Reference labels shipped with the stack (``labels`` in an ``.npz``), if any.
    saturated : ndarray (N, H, W) of bool or None
        Samples at or above the saturation level in the data as recorded (for a mosaic:
        the demosaiced samples that draw on a saturated raw pixel); None when no level
        applies (float data with ``saturation="auto"``, or ``saturation=None``).
    colour_stack : ndarray (3, N, H, W) float64 or None
        For a colour-polarisation mosaic: the R, G, B stacks (``stack`` is their
        luminance); ``metadata["colours"]`` names them. None otherwise.
    """

    stack: np.ndarray
    angles_deg: np.ndarray
    source: str
    metadata: dict[str, Any] = field(default_factory=dict)
    ground_truth: np.ndarray | None = None
    saturated: np.ndarray | None = None
    colour_stack: np.ndarray | None = None

    @property
    def angles_rad(self) -> np.ndarray:
        """Polariser angles in radians, for the engine."""
        return np.deg2rad(self.angles_deg)


@dataclass(frozen=True)
class BlackLevel:
    """What is subtracted from every sample once saturation was found (resolved from
    :class:`~napari_polarseg.io.read_options.ReadOptions`: the dark frame read).

    Attributes
    ----------
    dark : ndarray (H, W) or None
        Dark frame.
    dark_name : str or None
        The file the dark frame was read from, for messages.
    offset : float or None
        Constant black level.
    """

    dark: np.ndarray | None = None
    dark_name: str | None = None
    offset: float | None = None

    @property
    def subtracts(self) -> bool:
        """Whether a dark frame or an offset is subtracted."""
        return self.dark is not None or self.offset is not None

    def subtract(self, path: Path, data: np.ndarray) -> np.ndarray:
        """``data`` less the dark frame and the offset, negative results set to 0.

        Raises
        ------
        PolarsegError
            Naming the dark frame's file (else ``path``) if its size does not fit.
        """
        if not self.subtracts:
            return data
        try:
            return subtract_dark(data, self.dark, self.offset)
        except PolarsegError as exc:
            raise input_error(self.dark_name or path, str(exc)) from None
