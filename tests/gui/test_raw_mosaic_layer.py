"""A raw polarisation-camera frame opened by napari's own reader (issue 40, point 9).

File ▸ Open preselects *napari builtins*, which opens ``…_IMX250MZR.png`` as one 2-D grey
image. The Segment dock offers it as a raw mosaic with a layout menu; Run decodes it into
the angle-stack layer the plugin's reader would have made, and segments that.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _gui_helpers import error_messages, run_and_wait
from napari.layers import Image

import napari_polarseg
from napari_polarseg.engine import Scene
from napari_polarseg.engine.params import AUTO
from napari_polarseg.io import read_stack
from napari_polarseg.widgets.raw_mosaic import DECODED_KEY, MOSAIC_LAYOUTS, RAW_MOSAIC_SUFFIX

FRAME = Path(napari_polarseg.__file__).parent / "sample_data" / "fruits_IMX250MZR_crop.png"


def _names(box) -> list[str]:
    """The entries a chooser shows (without its empty entry)."""
    texts = [box.native.itemText(i) for i in range(box.native.count())]
    return [t for t in texts if t != box.null_string]


def _open_with_builtins(viewer) -> Image:
    layers = viewer.open(str(FRAME), plugin="napari")  # what OK on the preselected entry does
    assert len(layers) == 1
    raw = layers[0]
    assert isinstance(raw, Image) and raw.ndim == 2 and raw.data.shape == (512, 512)
    return raw


def test_segment_dock_decodes_a_raw_frame_opened_as_a_plain_image(viewer, add_widget, qtbot):
    raw = _open_with_builtins(viewer)
    widget = add_widget("Segment by material", preset=None)  # the default a user gets
    assert _names(widget.stack_layer) == [raw.name + RAW_MOSAIC_SUFFIX]
    assert widget.stack_layer.value is raw
    assert not widget.mosaic.layout.native.isHidden()
    assert widget.mosaic.layout.value == MOSAIC_LAYOUTS[0].label  # mono: …MZR in the name
    assert "raw 512 x 512 camera frame" in widget.status.value
    assert widget.mask_layer.choices == (None,)  # no Labels layer fits a raw frame

    run_and_wait(qtbot, widget)
    assert error_messages() == []
    decoded = widget.stack_layer.value
    assert decoded is not raw and decoded in viewer.layers
    assert decoded.name == f"{raw.name} stack"
    assert decoded.metadata[DECODED_KEY]["layer"] == str(raw.unique_id)
    assert widget.mosaic.layout.native.isHidden()
    # the stack the plugin's reader makes of the file, placed on the raw frame
    expected = read_stack(FRAME)
    np.testing.assert_array_equal(decoded.data, expected.stack)
    assert decoded.metadata["angles_deg"] == [0.0, 45.0, 90.0, 135.0]
    assert widget.angles.value == "0, 45, 90, 135"
    np.testing.assert_allclose(decoded.scale, (1, 2, 2))
    np.testing.assert_allclose(decoded.translate, (0, 0.5, 0.5))
    segments = widget.output("segments")
    assert segments is not None and segments.data.shape == (256, 256)
    ref = Scene(np.asarray(expected.stack), np.deg2rad(expected.angles_deg)).segment(AUTO)
    np.testing.assert_array_equal(segments.data, ref.labels + 1)
    np.testing.assert_allclose(segments.scale, (2, 2))

    # Run again on the raw frame: its decoded layer is chosen again, not decoded anew
    count = len(viewer.layers)
    widget.stack_layer.value = raw
    assert not widget.mosaic.layout.native.isHidden()
    run_and_wait(qtbot, widget)
    assert widget.stack_layer.value is decoded
    assert len(viewer.layers) == count
    assert error_messages() == []


def test_raw_frame_refuses_new_scribbles_until_decoded(viewer, add_widget, qtbot):
    raw = _open_with_builtins(viewer)
    widget = add_widget("Segment by material", preset=None)
    assert widget.stack_layer.value is raw
    assert widget.new_scribbles_layer() is None
    assert "press Run first" in widget.status.value
    assert len(viewer.layers) == 1
    error_messages()  # the refusal is an error notification too


def test_odd_sized_or_colour_images_are_not_raw_frames(viewer, add_widget):
    viewer.add_image(np.ones((33, 64), np.uint16), name="odd")
    viewer.add_image(np.ones((32, 64, 3), np.uint8), name="photo", rgb=True)
    even = viewer.add_image(np.ones((32, 64), np.uint16), name="even")
    widget = add_widget("Segment by material", preset=None)
    assert _names(widget.stack_layer) == ["even" + RAW_MOSAIC_SUFFIX]
    assert widget.stack_layer.value is even
    # the other docks list angle stacks only
    plots = add_widget("Polarisation image")
    assert [c for c in plots.stack_layer.choices if c is not None] == []


def test_dock_chooses_an_angle_stack_before_a_raw_frame(viewer, open_sample, add_widget):
    stack = open_sample("leaves")
    viewer.add_image(np.ones((120, 130), np.uint16), name="a 2-D picture")  # added last
    widget = add_widget("Segment by material", preset=None)
    assert widget.stack_layer.value is stack
    assert _names(widget.stack_layer) == ["leaves", "a 2-D picture" + RAW_MOSAIC_SUFFIX]
    assert widget.mosaic.layout.native.isHidden()
