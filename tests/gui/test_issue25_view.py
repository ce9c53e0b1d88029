"""Issue 25, the viewer around the docks: a dock that narrows the canvas refits a fitted
view (the image's right edge was hidden until Home), and the angle slider reads the
polariser angle of the frame shown (it read the frame index under the label "-3")."""

from __future__ import annotations

import numpy as np
import pytest
from qtpy.QtWidgets import QApplication

from napari_polarseg._reader import STACK_AXIS_LABELS


def _whole_image_in_view(viewer, layer) -> bool:
    """The layer's pixels, corner to corner, lie inside the canvas's view of the world."""
    camera = viewer.scene.camera
    h, w = viewer.canvas.size
    centre = np.asarray(camera.center)[-2:]
    half = np.array([h, w]) / (2 * camera.zoom)
    shape = np.array(layer.data.shape[-2:])
    lo, hi = np.array([-0.5, -0.5]), shape - 0.5  # pixel edges (scale 1)
    return bool(np.all(lo >= centre - half - 1e-6) and np.all(hi <= centre + half + 1e-6))


@pytest.fixture
def shown(viewer, qtbot):
    """The viewer's window shown at 1600 x 1000, with a wide 768 x 1024 stack fitted."""
    window = viewer.window._qt_window
    window.resize(1600, 1000)
    window.show()
    qtbot.wait(50)
    stack = np.random.default_rng(0).random((4, 768, 1024)).astype(np.float32)
    layer = viewer.add_image(stack, name="wide", metadata={"angles_deg": [0.0, 45.0, 90.0, 135.0]})
    qtbot.wait(50)
    assert _whole_image_in_view(viewer, layer)  # napari fits the first layer
    return layer


def test_a_dock_that_narrows_the_canvas_refits_the_view(viewer, shown, add_widget, qtbot):
    before = viewer.canvas.size
    add_widget("Segment by material")
    qtbot.waitUntil(lambda: viewer.canvas.size[1] < before[1], timeout=5000)
    qtbot.wait(50)
    assert _whole_image_in_view(viewer, shown)
    add_widget("Polarisation plots")  # a tab of the Segment dock
    qtbot.wait(100)
    assert _whole_image_in_view(viewer, shown)


def test_a_zoomed_in_view_stays_as_the_user_left_it(viewer, shown, add_widget, qtbot):
    camera = viewer.scene.camera
    camera.zoom *= 4
    camera.center = (0.0, 200.0, 300.0)
    before, zoom = viewer.canvas.size, camera.zoom
    add_widget("Segment by material")
    qtbot.waitUntil(lambda: viewer.canvas.size[1] < before[1], timeout=5000)
    qtbot.wait(50)
    assert camera.zoom == zoom and tuple(camera.center)[-2:] == (200.0, 300.0)


def test_the_angle_slider_reads_the_angle_of_the_frame(viewer, open_sample, add_widget):
    stack = open_sample("leaves")
    assert stack.axis_labels == STACK_AXIS_LABELS
    assert viewer.dims.axis_labels[0] == "angle"  # named by the reader, no dock needed
    add_widget("Segment by material")
    angles = stack.metadata["angles_deg"]
    for step in (0, 2, len(angles) - 1):
        viewer.dims.set_current_step(0, step)
        assert viewer.dims.axis_labels[0] == f"angle {angles[step]:g}°"
    slider = viewer.window._qt_viewer.dims.slider_widgets[0]
    QApplication.processEvents()
    assert slider.axis_label.text() == f"angle {angles[-1]:g}°"
    viewer.add_image(np.zeros(stack.data.shape[1:]), name="a 2-D layer")
    assert viewer.dims.axis_labels[0] == f"angle {angles[-1]:g}°"  # kept on a layer change


def test_unequal_angles_read_as_given(viewer, add_widget):
    # a scale in degrees would put these frames at wrong slider positions
    angles = [0.0, 10.0, 45.0, 135.0, 170.0]
    data = np.zeros((len(angles), 16, 16), dtype=np.float32)
    viewer.add_image(data, name="uneven", metadata={"angles_deg": angles})
    add_widget("Polarisation image")
    for step, angle in enumerate(angles):
        viewer.dims.set_current_step(0, step)
        assert viewer.dims.axis_labels[0] == f"angle {angle:g}°"
