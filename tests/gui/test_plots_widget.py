"""The "Polarisation plots" widget: plots of the last segmentation, component layers."""

from __future__ import annotations

import numpy as np
from _gui_helpers import click, engine_result, error_messages, run_and_wait, wait_idle
from napari.layers import Image

from napari_polarseg.engine import SegmentParams
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
    (ax,) = widget.figure.axes
    assert len(ax.patches) == 4  # original + L = 4, 12, 20
    assert widget.histograms.original.sum() == h * w

    # recomputed in a worker from the segments layer's parameters when nothing is cached
    seg.store.discard(set())
    widget.result = None
    run_and_wait(qtbot, widget)
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
