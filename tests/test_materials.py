"""Named materials (issue 23, item 4): one numbering and one palette in every output.

A scribble classifier's classes keep the values they were painted with (2, 5, 7 here,
not 0, 1, 2) and their names, through the classifier file, ``labels.tif``,
``segments.csv``, ``probabilities.tif``, the plots and ``overview.png``.
"""

from __future__ import annotations

import csv
import dataclasses
import warnings

import numpy as np
import pytest
import tifffile
from test_pixel_classifier import ANGLES, NO_SMOOTHING, PIXEL_ONLY, planted_scene

from napari_polarseg.classifier_file import load_pixel_classifier, save_pixel_classifier
from napari_polarseg.engine import Pipeline, PolarsegError, SegmentParams
from napari_polarseg.engine.analysis import plots
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.materials import Materials, display_values, file_values
from napari_polarseg.outputs import overview_figure, write_result_folder
from napari_polarseg.outputs.figures import scatter_figure
from napari_polarseg.palette import label_rgba, segment_rgba

#: Scribble values the strokes are painted with (not 1, 2, 3).
VALUES = (2, 5, 7)


@pytest.fixture(scope="module")
def named():
    """A classifier result of the planted scene, painted with :data:`VALUES` and named."""
    stack, truth, strokes = planted_scene()
    painted = np.zeros_like(strokes)
    for i, v in enumerate(VALUES):
        painted[strokes == i + 1] = v
    seg = PixelSegmenter(Pipeline(stack, ANGLES, SegmentParams(window=10)))
    out = seg.segment(painted, feature_params=PIXEL_ONLY, params=NO_SMOOTHING)
    return stack, truth, out


def test_materials_values_names_and_defaults():
    m = Materials.of([1, 3], {3: " glass,  bottle "})
    assert m.names == ("material 1", "glass bottle")  # one line, no comma (CSV)
    assert m.renamed({1: "cloth"}).names == ("cloth", "glass bottle")
    np.testing.assert_array_equal(m.label_values(np.array([[0, 1]])), [[1, 3]])
    assert m.to_dict() == {"1": "material 1", "3": "glass bottle"}
    np.testing.assert_array_equal(display_values(3, None), [1, 2, 3])
    np.testing.assert_array_equal(file_values(3, None), [0, 1, 2])
    np.testing.assert_array_equal(display_values(2, m), [1, 3])
    with pytest.raises(PolarsegError):
        Materials((2, 1), ("a", "b"))  # not ascending
    with pytest.raises(PolarsegError):
        Materials((0, 1), ("a", "b"))  # 0 is no material


def test_the_classifier_keeps_the_painted_values_and_names_through_its_file(named, tmp_path):
    _, _, out = named
    assert out.result.materials == Materials.of(VALUES)
    clf = out.classifier.named({2: "cloth", 7: "apple"})
    assert clf.materials().names == ("cloth", "material 5", "apple")
    path = tmp_path / "named.polarseg-clf"
    save_pixel_classifier(path, clf)
    back = load_pixel_classifier(path)
    assert back.class_names == ("cloth", "material 5", "apple")
    # applied elsewhere, its names come with it
    stack2, _, _ = planted_scene(seed=3)
    applied = PixelSegmenter(Pipeline(stack2, ANGLES, SegmentParams(window=10))).segment(
        classifier=back
    )
    assert applied.result.materials.names == ("cloth", "material 5", "apple")


def test_labels_tif_segments_csv_and_probabilities_use_the_painted_values(named, tmp_path):
    stack, truth, out = named
    result = dataclasses.replace(
        out.result, materials=out.result.materials.renamed({5: "banana", 7: "apple"})
    )
    folder = tmp_path / "out"
    write_result_folder(
        folder,
        stack=stack,
        angles_deg=np.rad2deg(ANGLES),
        result=result,
        probabilities=out.prediction.probabilities,
        overview=False,
        views=False,
    )
    labels = tifffile.imread(folder / "labels.tif")
    np.testing.assert_array_equal(labels, np.asarray(VALUES)[truth])  # the painted values
    with tifffile.TiffFile(folder / "labels.tif") as tif:
        assert tif.shaped_metadata[0]["materials"] == {
            "2": "material 2",
            "5": "banana",
            "7": "apple",
        }
    with open(folder / "segments.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["segment"], r["name"]) for r in rows] == [
        ("2", "material 2"),
        ("5", "banana"),
        ("7", "apple"),
    ]
    assert [int(r["pixels"]) for r in rows] == np.bincount(truth.ravel()).tolist()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with tifffile.TiffFile(folder / "probabilities.tif") as tif:
            meta, axes = tif.shaped_metadata[0], tif.series[0].axes
            proba = tif.asarray()
    assert axes == "CYX" and list(meta["materials"]) == ["2", "5", "7"]
    assert proba.shape == (3, *truth.shape)


def test_unsupervised_segments_csv_has_an_empty_name_column(named, tmp_path):
    stack, _, out = named
    result = dataclasses.replace(out.result, materials=None)
    write_result_folder(
        tmp_path / "u",
        stack=stack,
        angles_deg=np.rad2deg(ANGLES),
        result=result,
        overview=False,
        views=False,
    )
    with open(tmp_path / "u" / "segments.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["segment"], r["name"]) for r in rows] == [("0", ""), ("1", ""), ("2", "")]
    np.testing.assert_array_equal(
        np.unique(tifffile.imread(tmp_path / "u" / "labels.tif")), [0, 1, 2]
    )


def _panel_rgba(fig, title_start):
    (ax,) = [ax for ax in fig.axes if ax.get_title().startswith(title_start)]
    image = ax.images[0]
    return ax, image


def test_plots_and_overview_draw_each_class_in_its_viewer_colour(named):
    """The viewer draws scribble value v in ``label_rgba(v)``: the scatter plot's points
    of that class and the overview's segments panel use the same RGBA, and the
    overview's legend names the material."""
    stack, truth, out = named
    result = dataclasses.replace(out.result, materials=out.result.materials.renamed({5: "banana"}))
    expected = label_rgba(VALUES)
    np.testing.assert_allclose(expected, segment_rgba()[[1, 4, 6]])
    # overview: the segments panel's colour of label k is the viewer's of VALUES[k]
    fig = overview_figure(stack[0], result, truth=truth)
    ax, image = _panel_rgba(fig, "segments")
    for k in range(3):
        np.testing.assert_allclose(image.cmap(image.norm(k)), expected[k])
    fig.canvas.draw()
    ticks = [t.get_text() for t in image.colorbar.ax.get_yticklabels()]
    assert ticks == ["2 material 2", "5 banana", "7 material 7"]
    # the truth panel: each material in the colour of the segment it matches
    _, true_image = _panel_rgba(fig, "ground truth")
    for k in range(3):
        np.testing.assert_allclose(true_image.cmap(true_image.norm(k)), expected[k])
    # the scatter plot: every point of class k in the same RGBA, the legend named
    data = plots.scatter_data(result, 2000)
    sfig = scatter_figure(data, "dop", first_label=1, materials=result.materials)
    points = sfig.axes[0].collections[0].get_facecolors()
    for k in range(3):
        np.testing.assert_allclose(
            points[data.labels == k], np.tile(expected[k], (np.sum(data.labels == k), 1))
        )
    legend = [t.get_text() for t in sfig.axes[0].get_legend().get_texts()]
    assert legend == ["2 material 2", "5 banana", "7 material 7"]


def test_unsupervised_overview_and_plots_use_the_viewer_numbering_colours(named):
    """Without materials segment k is label k + 1 in the viewer: the same colour in the
    overview and the plots (not matplotlib's tab10)."""
    stack, _, out = named
    result = dataclasses.replace(out.result, materials=None)
    fig = overview_figure(stack[0], result)
    _, image = _panel_rgba(fig, "segments")
    for k in range(3):
        np.testing.assert_allclose(image.cmap(image.norm(k)), segment_rgba()[k])
    data = plots.scatter_data(result, 500)
    sfig = scatter_figure(data, "dop", first_label=1)
    points = sfig.axes[0].collections[0].get_facecolors()
    np.testing.assert_allclose(points, segment_rgba()[data.labels])
