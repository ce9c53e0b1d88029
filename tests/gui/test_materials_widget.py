"""Named materials in "Segment by material" (issue 23, item 4): the material list picks
the brush's class, shows its colour and renames it; one colour per class in the viewer,
the plots and the overview; the names reach the export and the saved classifier."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import tifffile
from _gui_helpers import click, error_messages, run_and_wait, wait_idle

from napari_polarseg.classifier_file import load_pixel_classifier
from napari_polarseg.engine.synthetic.scenes import scribble_strokes
from napari_polarseg.outputs import overview_figure
from napari_polarseg.palette import label_rgba

pytestmark = pytest.mark.gui

FAST = {"window": 10, "degree": 4, "n_segments": 3}
#: The scribble values the three materials are painted with (not 1, 2, 3).
VALUES = (2, 5, 7)


def _rename(widget, value, name):
    """Choose the material ``value`` in the list and type its name (Enter)."""
    widget.materials.material.value = value
    widget.materials.name_edit.value = name
    widget.materials.name_edit.native.editingFinished.emit()


def test_material_list_colours_and_names_everywhere(
    viewer, open_sample, add_widget, qtbot, tmp_path
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    scribbles = widget.new_scribbles_layer()
    strokes = scribble_strokes(truth - 1, seed=0)
    painted = np.zeros(strokes.shape, np.int32)
    for i, v in enumerate(VALUES):
        painted[strokes == i + 1] = v
    scribbles.data = painted
    materials = widget.materials
    materials.refresh()
    assert materials.values() == [1, *VALUES]  # the brush's label 1 and the painted ones
    # the painted values are counted once per edit: a brush stroke shows in the list
    scribbles.paint((0, 0), 9, refresh=True)
    assert materials.values() == [1, *VALUES, 9]
    scribbles.paint((0, 0), 0, refresh=True)
    assert materials.values() == [1, *VALUES]
    # choosing a material sets the brush; its swatch is its viewer colour
    materials.material.value = 5
    assert scribbles.selected_label == 5
    r, g, b = (label_rgba([5])[0][:3] * 255).round().astype(int)
    assert f"rgb({r}, {g}, {b})" in materials.swatch.native.styleSheet()
    scribbles.selected_label = 7  # napari's own label control: the list follows
    assert materials.material.value == 7
    click(qtbot, materials.add_button)
    assert scribbles.selected_label == 8 and materials.material.value == 8
    _rename(widget, 5, "banana")
    assert widget.material_names() == {5: "banana"}
    assert scribbles.metadata["polarseg_materials"] == {"5": "banana"}  # kept with the strokes

    run_and_wait(qtbot, widget)
    assert error_messages() == []
    assert "5 banana" in widget.status.value
    segments = widget.output("segments")
    assert set(np.unique(segments.data)) == set(VALUES)  # the painted values, as painted
    result = widget.shown_result(stack)
    assert result.materials.values == VALUES
    assert result.materials.names == ("material 2", "banana", "material 7")

    # one colour per class: the viewer's segments and strokes, the plots, the overview
    viewer_rgba = np.array([segments.get_color(v) for v in VALUES])
    np.testing.assert_allclose(viewer_rgba, label_rgba(VALUES))
    np.testing.assert_allclose([scribbles.get_color(v) for v in VALUES], viewer_rgba)
    plots = add_widget("Polarisation plots")
    click(qtbot, plots.run_button)
    wait_idle(qtbot, plots)
    plots.plot.value = "scatter_dop"
    ax = plots.figure.axes[0]
    points = ax.collections[0].get_facecolors()
    data_labels = plots.result.labels.ravel()  # every pixel is drawn (a small sample)
    assert len(points) == data_labels.size
    for k in range(len(VALUES)):
        np.testing.assert_allclose(points[data_labels == k][:1], viewer_rgba[k : k + 1])
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["2 material 2", "5 banana", "7 material 7"]
    fig = overview_figure(np.asarray(stack.data)[0], result)
    (seg_ax,) = [a for a in fig.axes if a.get_title().startswith("segments")]
    image = seg_ax.images[0]
    for k in range(len(VALUES)):
        np.testing.assert_allclose(image.cmap(image.norm(k)), viewer_rgba[k])

    # renamed after the run: the export and the saved classifier carry the new name
    _rename(widget, 7, "stem")
    out = tmp_path / "out"
    assert widget.export_results(out)
    wait_idle(qtbot, widget)
    with open(out / "segments.csv", newline="") as f:
        rows = [(r["segment"], r["name"]) for r in csv.DictReader(f)]
    assert rows == [("2", "material 2"), ("5", "banana"), ("7", "stem")]
    labels = tifffile.imread(out / "labels.tif")
    np.testing.assert_array_equal(labels, segments.data)  # one numbering: as the viewer
    clf = tmp_path / "named.polarseg-clf"
    assert widget.save_classifier(clf)
    wait_idle(qtbot, widget)
    assert load_pixel_classifier(clf).class_names == ("material 2", "banana", "stem")
