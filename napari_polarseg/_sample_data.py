"""npe2 sample data: the bundled synthetic scenes and one real polarisation-camera frame.

Each sample returns the angle stack as an image layer whose ``metadata["angles_deg"]``
holds the polariser angles in degrees; the synthetic scenes add their ground-truth
material labels as a hidden labels layer (material k is label k + 1, because napari
draws label 0 as transparent background). This module imports neither napari nor Qt.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._reader import LayerData, stack_layer_data
from .io import DEFAULT_MOSAIC, read_stack

#: Folder of the bundled files.
SAMPLE_DIR = Path(__file__).resolve().parent / "sample_data"

#: Synthetic scenes bundled as ``<name>.npz``.
SYNTHETIC_SCENES = ("leaves", "camouflage", "fruit")

#: Raw 512 x 512 crop of a Sony IMX250MZR frame (see LICENSE-polanalyser.md).
REAL_FRAME = "fruits_IMX250MZR_crop.png"


def synthetic_scene(name: str) -> list[LayerData]:
    """Angle stack and hidden ground truth of the bundled synthetic scene ``name``."""
    if name not in SYNTHETIC_SCENES:
        raise ValueError(f"unknown sample {name!r}; choose one of {', '.join(SYNTHETIC_SCENES)}")
    data = read_stack(SAMPLE_DIR / f"{name}.npz")
    layers = [stack_layer_data(data, name=name)]
    if data.ground_truth is not None:
        truth = np.asarray(data.ground_truth).astype(np.int32) + 1
        meta: dict[str, Any] = {"source": data.source, "label_offset": 1}
        layers.append(
            (truth, {"name": f"{name} ground truth", "visible": False, "metadata": meta}, "labels")
        )
    return layers


def leaves() -> list[LayerData]:
    """Natural and plastic leaves on a matte board (synthetic, 7 angles, 120 x 130)."""
    return synthetic_scene("leaves")


def camouflage() -> list[LayerData]:
    """Camouflage net over foliage (synthetic, 7 angles, 120 x 130)."""
    return synthetic_scene("camouflage")


def fruit() -> list[LayerData]:
    """Fruit with a bruise that does not show in intensity (synthetic, 7 angles)."""
    return synthetic_scene("fruit")


def fruits_camera() -> list[LayerData]:
    """Apple, background and orange from a real polarisation camera (4 angles, 256 x 256).

    A 512 x 512 crop of a raw Sony IMX250MZR frame (elerac/polanalyser, MIT licence),
    demosaiced by super-pixel into the four angles 0, 45, 90 and 135 degrees.
    """
    data = read_stack(SAMPLE_DIR / REAL_FRAME, mosaic=DEFAULT_MOSAIC)
    return [stack_layer_data(data, name="fruits (polarisation camera)")]
