"""Polariser angles from text and file names, and the sensors named in raw file names.

Angles are **degrees** here, as in files and on the command line (the engine takes
radians). :func:`parse_angles` is the one parser of typed angle lists (the command line's
``--angles``/``--mosaic`` and the plugin's *angles* boxes); :func:`angle_from_name` reads
a frame's angle from its file name; :func:`sensor_from_name` recognises a Sony
polarisation sensor in a raw frame's name.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..engine.errors import PolarsegError
from ..engine.physics.colour_mosaic import IMX250MYR_BAYER, IMX250MYR_LAYOUT
from ..engine.physics.mosaic import IMX250MZR_LAYOUT
from ..engine.physics.polarimage import distinct_angle_count
from .common import PathLike

#: Default 2 x 2 super-pixel layout (degrees, row-major) of a polarisation camera.
DEFAULT_MOSAIC = IMX250MZR_LAYOUT

#: Sony polarisation sensors named in raw files: mono (``…MZR``) and colour (``…MYR``).
SENSOR_NAMES = re.compile(r"IMX2(?:50|53|64)M[ZY]R", re.IGNORECASE)

#: What separates the angles of a list: a comma or a semicolon (spaces around it
#: allowed), or spaces alone.
ANGLE_SEPARATOR = re.compile(r"\s*[,;]\s*|\s+")

_NUMBER = re.compile(r"\d+(?:\.\d+)?")


def _bad_angle(text: str, part: str, option: str | None) -> PolarsegError:
    """The error for entry ``part`` of an angle list, worded for ``option`` or a form."""
    if option is not None:
        return PolarsegError(
            f"bad {option} value {text!r}: expected comma-separated numbers in degrees, "
            f"e.g. 0,45,90,135 (problem at {part!r})"
        )
    if not text.strip():
        return PolarsegError(
            "give the polariser angles in degrees, one per frame (e.g. 0,45,90,135)"
        )
    return PolarsegError(f"angles must be numbers in degrees, got {part!r}")


def parse_angles(text: str, option: str | None = "--angles") -> np.ndarray:
    """Parse a list of angles in degrees, e.g. ``"0,30,60,90"`` or ``"0 45; 90 135"``.

    Parameters
    ----------
    text : str
        Numbers separated by commas, semicolons or spaces (:data:`ANGLE_SEPARATOR`);
        spaces around a comma or semicolon and at either end are allowed, an empty entry
        (two commas in a row, a comma at either end) is not.
    option : str or None
        The command-line option the text came from, named in the error message
        (``"bad --angles value '0,x': expected comma-separated numbers in degrees, …"``);
        None for text typed into a form, whose messages name no option
        (``"angles must be numbers in degrees, got 'x'"``; for empty text: ``"give the
        polariser angles in degrees, one per frame (e.g. 0,45,90,135)"``).

    Returns
    -------
    ndarray (N,) float64
        The angles in degrees, in the given order.

    Raises
    ------
    PolarsegError
        If the text is empty, or an entry is empty, not a number, or not finite.

    Examples
    --------
    >>> parse_angles("0, 45,90,135").tolist()
    [0.0, 45.0, 90.0, 135.0]
    >>> parse_angles("0 45; 90 135", option=None).tolist()
    [0.0, 45.0, 90.0, 135.0]
    """
    values = []
    for part in ANGLE_SEPARATOR.split(str(text).strip()):
        try:
            value = float(part)
        except ValueError:
            value = math.nan
        if not part or not math.isfinite(value):
            raise _bad_angle(str(text), part, option)
        values.append(value)
    return np.array(values, dtype=np.float64)


def angle_from_name(name: PathLike) -> float | None:
    """Polariser angle in degrees carried by a file name: the last number of its stem.

    Parameters
    ----------
    name : str or path
        File name or path; only the name without its extension is looked at.

    Returns
    -------
    float or None
        The last run of digits (with an optional decimal part) in the stem, or None if
        the stem has no digits.

    Examples
    --------
    >>> angle_from_name("leaf_030.png"), angle_from_name("nir_45_aligned.tif")
    (30.0, 45.0)
    >>> angle_from_name("scene-b_22.5deg.png"), angle_from_name("dark.png")
    (22.5, None)
    """
    numbers = _NUMBER.findall(Path(name).stem)
    return float(numbers[-1]) if numbers else None


@dataclass(frozen=True)
class SensorDefaults:
    """Decoding of a raw frame named after a polarisation sensor.

    Attributes
    ----------
    sensor : str
        The sensor's name as found in the file name, upper case (e.g. ``"IMX250MYR"``).
    layout_deg : tuple of 4 floats
        Its 2 × 2 polariser layout, degrees, row-major.
    bayer : str or None
        Its Bayer order (colour sensors), None for a mono sensor.
    """

    sensor: str
    layout_deg: tuple[float, ...]
    bayer: str | None


def sensor_from_name(name: PathLike) -> SensorDefaults | None:
    """The sensor defaults of a raw frame whose file name names a Sony polarisation sensor.

    ``…IMX250MZR…``, ``…IMX253MZR…``, ``…IMX264MZR…`` (mono: layout 90, 45, 135, 0) and
    ``…IMX250MYR…``, ``…IMX253MYR…`` (colour: the same layout under an RGGB Bayer filter);
    case does not matter. None for any other name.

    Examples
    --------
    >>> sensor_from_name("fruits_IMX250MYR.png").bayer
    'RGGB'
    >>> sensor_from_name("fruits_IMX250MZR.png").bayer is None
    True
    """
    match = SENSOR_NAMES.search(Path(os.fspath(name)).name)
    if match is None:
        return None
    sensor = match.group(0).upper()
    if sensor.endswith("MYR"):
        return SensorDefaults(sensor, tuple(IMX250MYR_LAYOUT), IMX250MYR_BAYER)
    return SensorDefaults(sensor, tuple(IMX250MZR_LAYOUT), None)


def enough_angles(angles: Any) -> bool:
    """Whether ``angles`` (degrees) are finite numbers with at least 3 distinct modulo
    180 degrees (never raises)."""
    try:
        values = np.asarray(angles, dtype=float).ravel()
    except (TypeError, ValueError):
        return False
    return bool(np.all(np.isfinite(values))) and distinct_angle_count(np.deg2rad(values)) >= 3
