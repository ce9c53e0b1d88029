"""Keeping a fitted view fitted when a dock takes room from the canvas.

napari fits the view to the first layer, then never again: a dock opened afterwards
narrows the canvas and hid the image's right edge until the user pressed Home. Each
plugin dock keeps a :class:`FitKeeper` on its viewer: when the canvas changes size and
the layers were wholly in view before but are not now, it fits the view again
(``viewer.reset_view()``). A user who zoomed in (the layers were not wholly in view) keeps
the view as it is.
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import napari


def view_rect(viewer: napari.viewer.Viewer, size: tuple[int, int] | None = None) -> np.ndarray:
    """The world rectangle the 2-D canvas shows, ``[[y0, x0], [y1, x1]]``, for a canvas of
    ``size`` (height, width) pixels (default its size now): the camera centre ± half the
    size over the zoom (canvas pixels per world unit)."""
    camera = viewer.scene.camera
    h, w = viewer.canvas.size if size is None else size
    centre = np.asarray(camera.center, dtype=float)[-2:]
    half = np.array([h, w], dtype=float) / (2.0 * camera.zoom)
    return np.stack([centre - half, centre + half])


def layers_rect(viewer: napari.viewer.Viewer) -> np.ndarray | None:
    """The world rectangle of the displayed layers' data, ``[[y0, x0], [y1, x1]]``, to
    the outer edges of the pixels (None without layers)."""
    if len(viewer.layers) == 0:
        return None
    extent = viewer.layers.extent
    displayed = list(viewer.dims.displayed)
    world = np.asarray(extent.world, dtype=float)[:, displayed]
    half_step = np.asarray(extent.step, dtype=float)[displayed] / 2.0
    return np.stack([world[0] - half_step, world[1] + half_step])


def layers_in_view(viewer: napari.viewer.Viewer, size: tuple[int, int] | None = None) -> bool:
    """True when the layers lie wholly inside the view of a canvas of ``size`` (2-D
    display; within half a canvas pixel). False in 3-D and without layers."""
    data = layers_rect(viewer)
    if data is None or viewer.dims.ndisplay != 2:
        return False
    view = view_rect(viewer, size)
    slack = 0.5 / viewer.scene.camera.zoom
    return bool(np.all(data[0] >= view[0] - slack) and np.all(data[1] <= view[1] + slack))


class FitKeeper:
    """Fits ``viewer``'s view again when the canvas shrinks under a fitted view.

    Listens to ``viewer.canvas.events.size`` until :meth:`close`. Several keepers on one
    viewer (one per plugin dock) agree: the first refits, the others then find the layers
    in view.
    """

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        self._viewer = viewer
        self._size = tuple(viewer.canvas.size)
        viewer.canvas.events.size.connect(self._on_size)

    def _on_size(self, *_: Any) -> None:
        viewer = self._viewer
        old, new = self._size, tuple(viewer.canvas.size)
        self._size = new
        if old != new and layers_in_view(viewer, old) and not layers_in_view(viewer, new):
            viewer.reset_view()

    def close(self) -> None:
        """Stop listening (the dock closed)."""
        with contextlib.suppress(Exception):
            self._viewer.canvas.events.size.disconnect(self._on_size)
