"""A guard for napari's canvas when the viewer loses a dimension.

With napari 0.9.2 (vispy 0.15–0.17, Mesa llvmpipe or softpipe 22.3, PyQt6 6.11) the
process dies (SIGSEGV in ``glDrawArrays``) on the first draw after the last 3-D layer is
removed while 2-D layers stay: the remaining layers' visuals keep the buffers they had
in the 3-D viewer. The plugin's angle stack is such a layer, and its segments, maps and
scribbles are 2-D, so deleting the stack after a Run killed the user's session. It
reproduces without the plugin::

    v = napari.Viewer(); img = v.add_image(np.zeros((4, 64, 64)))
    v.add_labels(np.ones((64, 64), int)); v.layers.remove(img)  # then draw

Giving each remaining layer its data again, in the ``removed`` event (before the next
draw), makes napari rebuild its visual, and the draw goes through. :func:`guard_viewer`
connects that once per viewer; it acts only when a removal lowers the viewer's number
of dimensions. This is written by hand because no napari release we can pin avoids it
(tried: napari 0.9.2 with vispy 0.15.2, 0.16.1 and 0.17.0).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import napari

#: Attribute set on a guarded viewer's layer list (the viewer itself is a model that
#: takes no new attribute), so that every dock connects the guard once.
GUARDED = "polarseg_dims_guard"


def guard_viewer(viewer: napari.viewer.Viewer) -> None:
    """Re-set the data of every remaining layer when a removal lowers the viewer's number
    of dimensions (module docstring); once per viewer, for its life."""
    layers = viewer.layers
    if getattr(layers, GUARDED, False):
        return
    before = {"ndim": 0}

    def removing(event: Any) -> None:
        before["ndim"] = max((layer.ndim for layer in layers), default=0)

    def removed(event: Any) -> None:
        now = max((layer.ndim for layer in layers), default=0)
        if now < before["ndim"]:
            for layer in list(layers):
                layer.data = layer.data  # napari rebuilds the layer's visual

    layers.events.removing.connect(removing)
    layers.events.removed.connect(removed)
    setattr(layers, GUARDED, True)
