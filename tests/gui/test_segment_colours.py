"""Segments are drawn in bright, clearly distinct colours (issue 14, item 6): napari's
default labels colormap drew label 1 in a dark brown that read as "nothing happened"."""

from __future__ import annotations

import itertools

import numpy as np
from _gui_helpers import run_and_wait

#: Labels whose colours must be told apart at a glance.
FIRST_LABELS = range(1, 11)


def _colours(layer, labels) -> np.ndarray:
    return np.array([layer.get_color(k)[:3] for k in labels], dtype=float)


def test_segments_and_scribbles_get_bright_distinct_colours(viewer, add_widget, open_sample, qtbot):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    run_and_wait(qtbot, widget)
    segments = widget.output("segments")
    assert segments is not None and set(np.unique(segments.data)) >= {1, 2}
    rgb = _colours(segments, FIRST_LABELS)
    assert rgb.max(axis=1).min() >= 0.5  # none is dark
    for i, j in itertools.combinations(range(len(rgb)), 2):
        assert np.linalg.norm(rgb[i] - rgb[j]) >= 0.3, (i + 1, j + 1, rgb[i], rgb[j])
    assert segments.get_color(0) is None  # label 0 stays transparent
    # a new scribbles layer paints with the same colours: a stroke and its segment match
    scribbles = widget.new_scribbles_layer()
    np.testing.assert_allclose(_colours(scribbles, FIRST_LABELS), rgb)
    # what the canvas shows of a label is its colour (blended over the stack by opacity)
    shown = segments.colormap.map(np.asarray(segments.data[:2, :2]).ravel())[:, :3]
    np.testing.assert_allclose(shown, _colours(segments, segments.data[:2, :2].ravel()))
