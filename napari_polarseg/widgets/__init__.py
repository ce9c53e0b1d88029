"""napari widgets of napari-polarseg (need napari and a Qt binding).

- :class:`PolarisationWidget` ("Polarisation image"): Î, ρ, φ and zenith θ layers.
- :class:`SegmentWidget` ("Segment by material"): the segmentation pipeline with live
  parameters, ``segments`` and ``reconstruction error`` layers.
- :class:`SweepWidget` ("Parameter sweep"): scores a grid of w, L and n, heatmaps, the
  best cell one click away.

Both are thin: they read the chosen angle-stack layer, call the engine in a napari worker
thread and show the results. ``import napari_polarseg`` does not import this package.
"""

from .polarisation import PolarisationWidget
from .segment import SegmentWidget
from .sweep import SweepWidget

__all__ = ["PolarisationWidget", "SegmentWidget", "SweepWidget"]
