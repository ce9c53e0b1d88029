"""napari widgets of napari-polarseg (need napari and a Qt binding).

- :class:`PolarisationWidget` ("Polarisation image"): Î, ρ, φ and zenith θ layers.
- :class:`SegmentWidget` ("Segment by material"): the segmentation pipeline with live
  parameters, ``segments`` and ``reconstruction error`` layers.
- :class:`SweepWidget` ("Parameter sweep"): scores a grid of w, L and n, heatmaps, the
  best cell one click away.

Both are thin: they read the chosen angle-stack layer, call the engine in a napari worker
thread and show the results. ``import napari_polarseg`` does not import this package.
What they run without Qt (pipelines, jobs, results, texts) is
:mod:`napari_polarseg.widgets.session`; importing it (or this package) imports neither
napari nor Qt: the widget classes are imported when first named.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .polarisation import PolarisationWidget
    from .segment import SegmentWidget
    from .sweep import SweepWidget

__all__ = ["PolarisationWidget", "SegmentWidget", "SweepWidget"]

#: Widget class -> the module that defines it (imported at first use: it needs napari).
_MODULES = {
    "PolarisationWidget": ".polarisation",
    "SegmentWidget": ".segment",
    "SweepWidget": ".sweep",
}


def __getattr__(name: str) -> Any:
    """The widget classes, imported when first named (PEP 562)."""
    module = _MODULES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(module, __name__), name)
