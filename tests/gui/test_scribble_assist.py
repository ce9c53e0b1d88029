"""*Use as scribbles* and *Paint here next* in "Segment by material" (issue 23, item 4)."""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import click, error_messages, run_and_wait
from napari.layers import Labels, Shapes
from napari.utils.notifications import notification_manager
from skimage.draw import polygon2mask

from napari_polarseg.engine.classifier.scribbles_from_labels import (
    DEFAULT_MARGIN,
    scribbles_from_labels,
)
from napari_polarseg.engine.classifier.suggestion import paint_here_next
from napari_polarseg.widgets.segment_assist import view_camera

pytestmark = pytest.mark.gui


def test_use_as_scribbles_then_paint_here_next(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)  # the default method
    click(qtbot, widget.assist.use_button)  # nothing to turn into strokes yet
    assert "run a segmentation" in widget.status.value
    assert error_messages() == ["run a segmentation of this stack first"]
    notification_manager.records.clear()
    run_and_wait(qtbot, widget)  # unsupervised
    segments = np.asarray(widget.output("segments").data)
    result = widget.shown_result(stack)

    # the unsupervised segments as editable strokes: interiors kept, borders left out
    click(qtbot, widget.assist.use_button)
    scribbles = widget.scribbles_layer.value
    assert isinstance(scribbles, Labels) and scribbles.name == f"{stack.name} scribbles"
    strokes = np.asarray(scribbles.data)
    expected = scribbles_from_labels(segments, DEFAULT_MARGIN, valid=result.valid)
    np.testing.assert_array_equal(strokes, expected)
    marked = strokes > 0
    np.testing.assert_array_equal(strokes[marked], segments[marked])  # the shown values
    assert len(np.unique(segments)) == 3 and len(np.unique(strokes[marked])) == 3
    assert 0.2 < marked.mean() < 0.98  # a border band was left out
    edge = np.zeros_like(marked)
    edge[:, 1:] |= segments[:, 1:] != segments[:, :-1]
    assert not marked[edge].any()  # no stroke on a border
    assert "as scribbles" in widget.status.value
    assert widget.materials.values() == sorted(set(np.unique(strokes)) - {0})

    # the classifier trained on them: then the place it is least sure of
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    assert widget.output("uncertainty") is not None, widget.status.value
    uncertainty = np.asarray(widget.output("uncertainty").data)
    click(qtbot, widget.assist.next_button)
    s = widget.assist.suggestion
    expected_s = paint_here_next(uncertainty, painted=strokes, valid=result.valid)
    assert s is not None and s.centre == expected_s.centre
    np.testing.assert_array_equal(s.region, expected_s.region)
    assert not (s.region & marked).any()  # away from the strokes
    shapes = viewer.layers[f"{stack.name} paint here next"]
    assert isinstance(shapes, Shapes) and len(shapes.data) == 1
    outline = polygon2mask(s.region.shape, shapes.data[0])
    assert (outline & s.region).sum() > 0.8 * s.region.sum()  # the outline is the region's
    centre = np.asarray(view_camera(viewer).center)[-2:]
    world = np.asarray(stack.translate[-2:]) + np.asarray(stack.scale[-2:]) * s.centre
    np.testing.assert_allclose(centre, world)  # the view moved there
    assert "paint here next" in widget.status.value
    # again: the same layer is updated, not a second one
    click(qtbot, widget.assist.next_button)
    assert sum(layer.name.endswith("paint here next") for layer in viewer.layers) == 1
