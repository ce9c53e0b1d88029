"""The polariser angle of the frame shown, beside napari's angle slider.

The reader names a stack's first axis "angle" (``_reader.STACK_AXIS_LABELS``), but
napari's slider shows the frame index. A scale in degrees would not do: napari maps an
axis to the world by one affine step, and the angles of a stack need not be equally
spaced (0, 45, 90, 135 and a repeated 180, or any order a folder of files gives).
So each plugin dock keeps an :class:`AngleLabel`: on every slider move (and layer change)
it sets the slider's axis label to the angle of the frame shown, e.g. ``angle 45°``,
read from the stack layer's ``metadata["angles_deg"]``. The label sits where the eye
already is, and napari widens the label column to fit it. napari writes the layers' own
axis labels (``angle``) back to the slider whenever a layer's data, scale or translate
changes (a rerun replacing the segments' data did): the label also follows the slider's
labels, and puts the angle back.
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Any

import numpy as np

from ._layers import ANGLES_KEY, layer_tag

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

#: Name of the angle axis (the reader's label), also the label's start.
ANGLE_AXIS = "angle"


def angles_of(layer: Layer) -> np.ndarray | None:
    """The polariser angles (degrees) of a 3-D stack layer, one per frame, or None."""
    if layer.ndim != 3 or layer_tag(layer) is not None or not isinstance(layer.metadata, dict):
        return None
    angles = layer.metadata.get(ANGLES_KEY)
    if angles is None or np.size(angles) != layer.data.shape[0]:
        return None
    return np.asarray(angles, dtype=float).ravel()


def shown_stack(viewer: napari.viewer.Viewer) -> Layer | None:
    """The angle stack whose frame the slider picks: the selected one, else the top
    visible one, else the top one (None without a stack)."""
    stacks = [layer for layer in viewer.layers if angles_of(layer) is not None]
    if not stacks:
        return None
    active = viewer.layers.selection.active
    if active in stacks:
        return active
    visible = [layer for layer in stacks if layer.visible]
    return (visible or stacks)[-1]


def angle_label(viewer: napari.viewer.Viewer) -> tuple[int, str] | None:
    """(world axis, label) of the shown stack's angle axis, e.g. ``(0, "angle 45°")``:
    the angle of the frame at the slider's position (None without a stack)."""
    layer = shown_stack(viewer)
    if layer is None:
        return None
    angles = angles_of(layer)
    assert angles is not None
    axis = viewer.dims.ndim - layer.ndim
    if axis < 0:
        return None
    position = layer.world_to_data(viewer.dims.point)[0]
    index = int(np.clip(np.round(position), 0, angles.size - 1))
    return axis, f"{ANGLE_AXIS} {angles[index]:g}°"


class AngleLabel:
    """Keeps the angle slider's label at the angle of the frame shown (module docstring).

    Listens to the viewer's slider, layers and selection until :meth:`close`; several
    (one per plugin dock) set the same text.
    """

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        self._viewer = viewer
        self._emitters = (
            viewer.dims.events.current_step,
            viewer.dims.events.axis_labels,  # napari resets them when a layer's data changes
            viewer.layers.events.inserted,
            viewer.layers.events.removed,
            viewer.layers.events.reordered,
            viewer.layers.selection.events.active,
        )
        for emitter in self._emitters:
            emitter.connect(self.update)
        self.update()

    def update(self, *_: Any) -> None:
        """Set the label of the shown stack's angle axis."""
        found = angle_label(self._viewer)
        if found is None:
            return
        axis, text = found
        if self._viewer.dims.axis_labels[axis] != text:
            self._viewer.dims.set_axis_label(axis, text)

    def close(self) -> None:
        """Stop listening (the dock closed)."""
        for emitter in self._emitters:
            with contextlib.suppress(Exception):
                emitter.disconnect(self.update)
