"""The "Polarisation plots" widget: plots of the last segmentation, component layers."""

from __future__ import annotations

import numpy as np
from _gui_helpers import click, engine_result, error_messages, run_and_wait, wait_idle
from napari.layers import Image

from napari_polarseg.engine import Pipeline, SegmentParams, validity_mask
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.widgets._layers import TAG
from napari_polarseg.widgets.plots import N_COMPONENTS, PlotsWidget

FAST = {"window": 10, "degree": 5, "n_segments": 3}


def _points(widget):
    (ax,) = widget.figure.axes
    return len(ax.collections[0].get_offsets())


def test_plots_widget_draws_the_segmentation_and_adds_component_maps(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("leaves")
    seg = add_widget("Segment by material")
    seg.set_params(**FAST)
    run_and_wait(qtbot, seg)
    widget = add_widget("Polarisation plots")
    assert isinstance(widget, PlotsWidget)
    assert widget.stack_layer.value is stack
    assert widget.result is None

    click(qtbot, widget.run_button)
    assert not widget.busy  # the Segment widget's cached result: no worker, no recomputation
    assert error_messages() == []
    ref = engine_result(stack, SegmentParams(**FAST))
    assert widget.result is not None
    np.testing.assert_array_equal(widget.result.labels, ref.labels)
    h, w = stack.data.shape[1:]
    assert h * w <= 20000  # every pixel is drawn

    widget.plot.value = "scatter_dop"
    assert _points(widget) == h * w
    widget.plot.value = "scatter_phase"
    assert _points(widget) == h * w
    assert "φ" in widget.figure.axes[0].get_xlabel()
    widget.plot.value = "variance"
    (ax,) = widget.figure.axes
    assert len(ax.patches) == ref.explained_variance_ratio.size
    heights = [p.get_height() for p in ax.patches]
    np.testing.assert_allclose(heights, ref.explained_variance_ratio)
    widget.plot.value = "histograms"
    wait_idle(qtbot, widget)
    assert widget.histograms is not None
    axes = widget.figure.axes
    assert len(axes) == 3 and all(len(ax.patches) == 2 for ax in axes)  # Î + L = 4, 12, 20
    hist = widget.histograms
    assert hist.n_pixels == h * w and hist.original.sum() + hist.outside_original == h * w

    # recomputed in a worker from the segments layer's parameters when nothing is cached
    seg._forget(set())
    widget.result = None
    click(qtbot, widget.run_button)
    assert widget.busy
    wait_idle(qtbot, widget)
    assert error_messages() == []
    np.testing.assert_array_equal(widget.result.labels, ref.labels)

    n_before = len(viewer.layers)
    click(qtbot, widget.components_button)
    comps = [layer for layer in viewer.layers if layer.name.startswith("principal component")]
    assert len(comps) == N_COMPONENTS == len(viewer.layers) - n_before
    for i, layer in enumerate(comps):
        assert isinstance(layer, Image)
        assert layer.data.shape == (h, w)
        assert layer.metadata[TAG]["role"] == f"component_{i + 1}"
        block = ref.features[:, i].reshape(ref.block_labels.shape)
        assert layer.data[0, 0] == block[0, 0]
    first = comps[0]
    click(qtbot, widget.components_button)  # replaced in place
    assert len(viewer.layers) == n_before + N_COMPONENTS
    assert viewer.layers[first.name] is first


def _reference(stack, params, region=None, scribbles=None):
    angles = np.deg2rad(stack.metadata["angles_deg"])
    mask = None if region is None else validity_mask(np.asarray(stack.data), region=region)
    pipe = Pipeline(np.asarray(stack.data), angles, params, mask=mask)
    if scribbles is not None:  # the pixel classifier trained on them
        return PixelSegmenter(pipe).segment(scribbles).result.labels
    return pipe.run().labels


def _recompute(qtbot, seg, widget):
    """Load the segmentation in a worker (nothing cached in the Segment widget)."""
    seg._forget(set())
    widget.result = None
    click(qtbot, widget.run_button)
    assert widget.busy
    wait_idle(qtbot, widget)


def test_plots_recompute_with_the_mask_and_scribbles_of_the_segmentation(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("leaves")
    h, w = stack.data.shape[1:]
    region = np.zeros((h, w), dtype=np.int32)
    region[:, : w // 2] = 1
    mask = viewer.add_labels(region.copy(), name="left half")
    seg = add_widget("Segment by material")
    seg.set_params(**FAST)
    seg.mask_layer.value = mask
    run_and_wait(qtbot, seg)
    widget = add_widget("Polarisation plots")
    params = SegmentParams(**FAST)
    masked_ref = _reference(stack, params, region=region != 0)
    assert not np.array_equal(masked_ref, _reference(stack, params))  # the mask matters

    click(qtbot, widget.run_button)  # the Segment widget's result
    np.testing.assert_array_equal(widget.result.labels, masked_ref)
    _recompute(qtbot, seg, widget)  # the mask layer the segments record, read again
    assert error_messages() == []
    np.testing.assert_array_equal(widget.result.labels, masked_ref)
    assert "edited" not in widget.status.value

    # an edited mask is used as it is now, and the status line says so
    mask.data[: h // 2] = 0
    mask.refresh()
    _recompute(qtbot, seg, widget)
    edited_ref = _reference(stack, params, region=np.asarray(mask.data) != 0)
    np.testing.assert_array_equal(widget.result.labels, edited_ref)
    assert "mask 'left half' edited since the segmentation" in widget.status.value

    # scribbles: the classifier's labels, cached or recomputed
    seg.mask_layer.value = None
    scribbles = seg.new_scribbles_layer()
    strokes = np.zeros((h, w), dtype=np.int32)
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    for value in (1, 2, 3):
        rows, cols = np.nonzero(truth == value)
        strokes[rows[::40], cols[::40]] = value
    scribbles.data = strokes
    run_and_wait(qtbot, seg)
    scribble_ref = _reference(stack, params, scribbles=strokes)
    click(qtbot, widget.run_button)
    np.testing.assert_array_equal(widget.result.labels, scribble_ref)
    np.testing.assert_array_equal(seg.output("segments").data, scribble_ref + 1)
    _recompute(qtbot, seg, widget)
    np.testing.assert_array_equal(widget.result.labels, scribble_ref)
    assert error_messages() == []

    # a removed scribbles layer cannot be read again: an error, not a wrong plot
    seg._forget(set())
    viewer.layers.remove(scribbles)
    widget.result = None
    click(qtbot, widget.run_button)
    assert widget.result is None
    assert "scribbles layer 'leaves scribbles'" in widget.status.value
    assert "no longer in the viewer" in error_messages()[-1]
