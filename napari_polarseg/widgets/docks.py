"""Finding the plugin's docked widgets: the one place that scans a viewer's docks.

The docks that work with the *Segment by material* widget (plots, batch, sweep) find it
with :func:`segment_dock`; it is recognised by the :class:`SegmentDock` marker it
inherits, so this module imports no widget (no import cycle).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    import napari

T = TypeVar("T")


class SegmentDock:
    """Marker base of the *Segment by material* widget (what :func:`segment_dock` finds)."""


def docked(viewer: napari.viewer.Viewer, kind: type[T]) -> list[T]:
    """The widgets docked in ``viewer``'s window that are ``kind`` (in dock order; none
    for a viewer without a window, or one closing)."""
    try:
        widgets = list(viewer.window.dock_widgets.values())
    except (AttributeError, RuntimeError):
        return []
    return [w for w in widgets if isinstance(w, kind)]


def segment_dock(viewer: napari.viewer.Viewer) -> Any:
    """The first docked *Segment by material* widget of ``viewer`` (a
    :class:`~napari_polarseg.widgets.segment.SegmentWidget`, which imports this module:
    not named in the annotation, so no import cycle), or None."""
    found: list[Any] = docked(viewer, SegmentDock)
    return found[0] if found else None
