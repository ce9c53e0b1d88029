"""Layers derived from a raw mosaic frame overlay that frame (issue 14, item 6).

A super-pixel decoding has half the raw frame's size (a quarter for a colour mosaic);
without a scale it covered only a quarter of the raw frame in the canvas. The decoded
stack and every output of a run on it sit on the raw frame's cells (napari pixel
centres: stack pixel k covers raw pixels 2k and 2k + 1).
"""

from __future__ import annotations

import numpy as np
from _gui_helpers import run_and_wait
from skimage import io as skio

from napari_polarseg import _reader
from napari_polarseg.engine.physics.mosaic import mosaic_superpixel


def _two_materials(h: int = 24, w: int = 32) -> np.ndarray:
    """A (4, h, w) stack at 0, 45, 90, 135 degrees: unpolarised left, polarised right."""
    theta = np.deg2rad([0.0, 45.0, 90.0, 135.0])[:, None, None]
    rho = np.zeros((h, w))
    rho[:, w // 2 :] = 0.4
    noise = np.random.default_rng(1).normal(0, 2.0, (4, h, w))
    return 1000.0 * (1 + rho * np.cos(2 * theta - 1.0)) + noise


def test_outputs_of_a_mosaic_frame_map_onto_its_cells(tmp_path, viewer, add_widget, qtbot):
    stack = _two_materials()
    raw = np.round(mosaic_superpixel(stack, angles_deg=(0.0, 45.0, 90.0, 135.0)))
    raw = raw.astype(np.uint16)
    path = tmp_path / "scene_IMX250MZR.png"
    skio.imsave(path, raw, check_contrast=False)
    frame = viewer.add_image(raw, name="raw frame")  # as napari's own reader shows it
    (decoded,) = viewer.open(str(path), plugin="napari-polarseg")
    assert tuple(decoded.scale) == (1.0, 2.0, 2.0)
    assert tuple(decoded.translate) == (0.0, 0.5, 0.5)
    widget = add_widget("Segment by material")
    widget.stack_layer.value = decoded
    widget.set_params(window=4, degree=2, n_segments=2)
    run_and_wait(qtbot, widget)
    segments, error = widget.output("segments"), widget.output("error")
    assert segments.data.shape == (raw.shape[0] // 2, raw.shape[1] // 2)
    zero = list(decoded.metadata["angles_deg"]).index(0.0)
    for layer in (segments, error, decoded):
        for r, c in [(0, 0), (5, 9), (23, 31)]:
            pixel = (zero, r, c) if layer is decoded else (r, c)
            lead = pixel[:-2]
            # the output pixel's corners are the corners of raw cell (2r, 2c)..(2r+1, 2c+1)
            for dr, dc in [(-0.5, -0.5), (0.5, 0.5)]:
                corner = (*lead, r + dr, c + dc)
                world = layer.data_to_world(corner)
                got = frame.world_to_data(world[-2:])
                np.testing.assert_allclose(got, (2 * r + 0.5 + 2 * dr, 2 * c + 0.5 + 2 * dc))
            # and its centre is the cell's centre
            centre = frame.world_to_data(layer.data_to_world(pixel)[-2:])
            np.testing.assert_allclose(centre, (2 * r + 0.5, 2 * c + 0.5))
    # the 0-degree frame's pixel is the raw sample at the 0-degree corner of its cell
    # (90/45 over 135/0: bottom right), and the segments follow the materials' border
    np.testing.assert_array_equal(decoded.data[zero], raw[1::2, 1::2])
    left, right = segments.data[:, :14], segments.data[:, 18:]
    assert len(np.unique(left)) == 1 and len(np.unique(right)) == 1
    assert np.unique(left) != np.unique(right)
    # the world position of a raw pixel falls on the segment of its cell
    world = frame.data_to_world((9, 40))
    r, c = np.floor(np.asarray(segments.world_to_data(world)) + 0.5).astype(int)
    assert (r, c) == (4, 20)


def test_a_colour_mosaic_stack_gets_its_period_of_four(tmp_path):
    raw = np.random.default_rng(0).integers(100, 200, (16, 24), dtype=np.uint16)
    path = tmp_path / "bench_IMX250MYR.png"
    skio.imsave(path, raw, check_contrast=False)
    ((data, meta, _),) = _reader.get_reader(str(path))(str(path))
    assert data.shape == (4, 4, 6)
    assert meta["scale"] == (1.0, 4.0, 4.0) and meta["translate"] == (0.0, 1.5, 1.5)
    assert _reader.mosaic_placement({"format": "mosaic", "demosaic": "interpolated"}) == {}
    assert _reader.mosaic_placement({"format": "npz"}) == {}
