"""Masks, saturated/black samples and the robust fit in "Segment by material"."""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import error_messages, run_and_wait, wait_idle
from napari.layers import Image, Labels

from napari_polarseg.engine import Pipeline, SegmentParams, validity_mask
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.widgets._layers import TAG

pytestmark = pytest.mark.gui

#: Fast parameters (the synthetic samples are 120 x 130 pixels).
FAST = {"window": 10, "degree": 4, "n_segments": 3}


def reference(layer, params, mask=None):
    """The engine's result for the layer's stack, run without the plugin."""
    angles = np.deg2rad(layer.metadata["angles_deg"])
    return Pipeline(np.asarray(layer.data), angles, params, mask=mask).run()


def top_half(shape):
    region = np.zeros(shape, dtype=np.int32)
    region[: shape[0] // 2] = 1
    return region


def test_labels_region_restricts_the_segmentation(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    h, w = stack.data.shape[1:]
    region = top_half((h, w))
    user_mask = viewer.add_labels(region.copy(), name="my region")
    viewer.add_labels(np.ones((h + 1, w), dtype=np.int32), name="other size")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)

    # the chooser offers "none" and the user's Labels layers of the stack's size only
    assert widget.mask_layer.value is None
    assert widget.mask_layer.current_choice == "none"
    offered = [c for c in widget.mask_layer.choices if c is not None]
    assert user_mask in offered and viewer.layers["other size"] not in offered
    assert all(TAG not in layer.metadata for layer in offered)

    widget.mask_layer.value = user_mask
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    ref = reference(stack, SegmentParams(**FAST), mask=validity_mask(stack.data, region=region))
    segments = widget.output("segments")
    np.testing.assert_array_equal(segments.data, ref.labels + 1)
    assert viewer.layers[-1] is segments  # still on top

    masked = widget.output("masked")
    assert isinstance(masked, Labels) and masked.name == f"masked pixels ({stack.name})"
    assert not masked.visible
    np.testing.assert_array_equal(masked.data, (region == 0).astype(np.uint8))
    residual = widget.output("residual")
    assert isinstance(residual, Image) and residual.name == f"fit residual ({stack.name})"
    assert not residual.visible
    np.testing.assert_allclose(residual.data, ref.residual, rtol=1e-9, atol=1e-9)
    assert f"masked: {h * w - np.count_nonzero(region)} outside the mask" in widget.status.value
    counts = segments.metadata["polarseg_summary"]["mask"]
    assert counts["outside_region_pixels"] == h * w // 2
    # the user's layer is only read
    np.testing.assert_array_equal(user_mask.data, region)
    assert TAG not in user_mask.metadata

    # the plugin's own Labels layers never become mask choices
    widget.mask_layer.reset_choices()
    assert segments not in widget.mask_layer.choices
    assert masked not in widget.mask_layer.choices


def test_saturated_and_black_samples_are_counted_and_shown(viewer, add_widget, qtbot):
    scene = make_scene("camouflage")
    data = scene.stack.copy()
    top = np.iinfo(data.dtype).max
    saturated = [(10, 12), (60, 70), (100, 3)]
    data[2, 10, 12] = top
    data[0, 60, 70] = top
    data[5, 60, 70] = top  # two frames of the same pixel: one saturated pixel
    data[6, 100, 3] = top
    data[1, 33, 44] = 0  # black
    stack = viewer.add_image(data, name="clipped", metadata={"angles_deg": list(scene.angles_deg)})
    widget = add_widget("Segment by material")
    assert widget.stack_layer.value is stack
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    assert error_messages() == []

    assert "masked: 3 saturated, 1 black" in widget.status.value
    expected = np.zeros(data.shape[1:], dtype=np.uint8)
    for y, x in [*saturated, (33, 44)]:
        expected[y, x] = 1
    masked = widget.output("masked")
    assert not masked.visible
    np.testing.assert_array_equal(masked.data, expected)
    ref = reference(stack, SegmentParams(**FAST))  # the engine's default flags
    assert ref.mask_counts["saturated_pixels"] == 3 and ref.mask_counts["dark_pixels"] == 1
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)
    np.testing.assert_allclose(widget.output("residual").data, ref.residual, atol=1e-9)
    summary = widget.output("segments").metadata["polarseg_summary"]
    assert summary["mask"]["saturated_pixels"] == 3 and summary["mask"]["dark_pixels"] == 1


def test_robust_fit_reaches_the_engine(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("fruit")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    assert widget.params().fit == "lsq"
    assert widget.fit.current_choice == "least squares"
    run_and_wait(qtbot, widget)
    lsq = reference(stack, SegmentParams(**FAST))
    np.testing.assert_array_equal(widget.output("segments").data, lsq.labels + 1)
    assert widget.output("residual") is None  # nothing masked, least squares: no extras

    widget.fit.value = "robust"
    assert widget.params() == SegmentParams(**FAST, fit="robust")
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    assert widget.pipeline.params.fit == "robust"
    segments = widget.output("segments")
    assert segments.metadata["polarseg_params"]["fit"] == "robust"
    assert segments.metadata["polarseg_summary"]["fit"] == "robust"
    robust = reference(stack, SegmentParams(**FAST, fit="robust"))
    np.testing.assert_array_equal(segments.data, robust.labels + 1)
    residual = widget.output("residual")
    np.testing.assert_allclose(residual.data, robust.residual, rtol=1e-9, atol=1e-9)
    assert not np.allclose(robust.residual, lsq.residual)

    # presets set the fit too
    widget.preset.value = "recommended"
    assert widget.fit.value == RECOMMENDED.fit == "lsq"


def test_switching_the_mask_recomputes(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    h, w = stack.data.shape[1:]
    region = top_half((h, w))
    user_mask = viewer.add_labels(region.copy(), name="my region")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    widget.mask_layer.value = user_mask
    run_and_wait(qtbot, widget)
    masked_pipe = widget.pipeline
    segments, masked = widget.output("segments"), widget.output("masked")
    n_layers = len(viewer.layers)

    # back to "none": a new pipeline over every pixel, layers updated in place
    widget.mask_layer.value = None
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    assert widget.pipeline is not masked_pipe
    full = reference(stack, SegmentParams(**FAST))
    assert widget.output("segments") is segments and widget.output("masked") is masked
    np.testing.assert_array_equal(segments.data, full.labels + 1)
    np.testing.assert_array_equal(masked.data, 0)
    assert "masked:" not in widget.status.value
    assert len(viewer.layers) == n_layers

    # painting the chosen Labels layer is picked up at the next run
    widget.mask_layer.value = user_mask
    run_and_wait(qtbot, widget)
    np.testing.assert_array_equal(masked.data, (region == 0).astype(np.uint8))
    before = widget.pipeline
    user_mask.data[:, : w // 2] = 0  # an in-place edit, as the paint brush does
    user_mask.refresh()
    edited = np.asarray(user_mask.data) != 0
    run_and_wait(qtbot, widget)
    assert widget.pipeline is not before
    ref = reference(stack, SegmentParams(**FAST), mask=validity_mask(stack.data, region=edited))
    np.testing.assert_array_equal(segments.data, ref.labels + 1)
    np.testing.assert_array_equal(masked.data, (~edited).astype(np.uint8))

    # an unchanged mask keeps the cached pipeline (only the last stage reruns)
    pipe = widget.pipeline
    widget.n_segments.value = 2
    run_and_wait(qtbot, widget)
    assert widget.pipeline is pipe and pipe.calls["harmonics"] == 1


def test_removed_mask_layer_falls_back_to_none(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    user_mask = viewer.add_labels(top_half(stack.data.shape[1:]), name="my region")
    widget = add_widget("Segment by material")
    widget.mask_layer.value = user_mask
    viewer.layers.remove(user_mask)
    assert widget.mask_layer.value is None
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    np.testing.assert_array_equal(
        widget.output("segments").data, reference(stack, SegmentParams(**FAST)).labels + 1
    )


def test_painting_the_mask_with_live_update_reruns(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    h, w = stack.data.shape[1:]
    user_mask = viewer.add_labels(top_half((h, w)), name="my region")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    widget.mask_layer.value = user_mask
    run_and_wait(qtbot, widget)  # ticking live update runs nothing before a first Run
    widget.live.value = True
    wait_idle(qtbot, widget)
    masked = widget.output("masked")
    np.testing.assert_array_equal(masked.data, (top_half((h, w)) == 0).astype(np.uint8))
    first = widget._slot.run_id

    # erase a patch with the brush (label 0), as a user would: the widget reruns itself
    user_mask.brush_size = 20
    user_mask.paint((20, 30), 0)
    assert widget._waiting()
    wait_idle(qtbot, widget)
    assert error_messages() == []
    assert widget._slot.run_id == first + 1
    edited = np.asarray(user_mask.data) != 0
    assert edited.sum() < np.count_nonzero(top_half((h, w)))
    np.testing.assert_array_equal(masked.data, (~edited).astype(np.uint8))
    ref = reference(stack, SegmentParams(**FAST), mask=validity_mask(stack.data, region=edited))
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)

    # with live update off, painting waits for Run
    widget.live.value = False
    user_mask.paint((20, 80), 0)
    qtbot.wait(400)
    assert not widget._waiting() and widget._slot.run_id == first + 1
