"""One segmentation job of the command line (and of each scene of a batch), computed in
memory: what :mod:`napari_polarseg.jobs` makes and :mod:`napari_polarseg.messages`
reports on (below both, so neither imports the other back)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import io as pio
from .engine import Pipeline, Scene, SegmentationResult
from .engine.params import SegmentParams
from .engine.physics.pixel_mask import PixelMask


@dataclass
class Run:
    """One segmentation job, everything computed in memory."""

    data: pio.StackData
    params: SegmentParams
    stack: np.ndarray
    result: SegmentationResult
    shifts: np.ndarray | None
    seconds: dict[str, float] = field(default_factory=dict)
    mask: PixelMask | None = None
    pipeline: Pipeline | None = None
    colour_stack: np.ndarray | None = None
    scene: Scene | None = None
