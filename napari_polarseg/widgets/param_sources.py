"""Where the batch, time-series and sweep widgets take their parameters from: the docked
*Segment by material* widget, a preset, or a parameters JSON file."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..engine import PolarsegError, SegmentParams
from ..engine.params import PRESETS
from ..io import read_params_file
from .docks import segment_dock

if TYPE_CHECKING:
    import napari

#: Where the batch and time-series widgets' parameters come from (the first is the default).
PARAM_SOURCES = ("Segment by material widget", "auto", "recommended", "thesis", "JSON file")


def params_from(viewer: napari.viewer.Viewer, source: str, path: Any = None) -> SegmentParams:
    """Parameters from one of :data:`PARAM_SOURCES` (raises PolarsegError).

    ``"Segment by material widget"``: the values of the first such widget docked in
    ``viewer``; a preset; or a SegmentParams JSON file at ``path``.
    """
    if source in PRESETS:
        return PRESETS[source]
    if source == "JSON file":
        if path is None:
            raise PolarsegError("None: cannot read the parameters file (no file chosen)")
        # a SegmentParams JSON or a params.json written by polarseg, as `segment --params`
        return read_params_file(path)
    widget = segment_dock(viewer)
    if widget is not None:
        return widget.params()
    raise PolarsegError(
        "no 'Segment by material' widget is open: open it, or choose a preset or a JSON "
        "file as the parameters"
    )
