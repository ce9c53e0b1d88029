"""The two widgets driven in a real napari viewer, compared with the engine run directly."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from _gui_helpers import (
    SAMPLES,
    click,
    engine_result,
    error_messages,
    run_and_wait,
    wait_idle,
)
from napari.layers import Image, Labels
from qtpy.QtCore import QTimer

from napari_polarseg.engine import SegmentParams, polarisation_image, zenith_from_dop
from napari_polarseg.widgets import PolarisationWidget, SegmentWidget
from napari_polarseg.widgets._layers import TAG, own_layers

pytestmark = pytest.mark.gui

POLARISATION_LAYERS = {
    "intensity": "Î intensity",
    "dop": "ρ degree of polarisation",
    "phase": "φ phase",
    "zenith": "θ zenith",
}
#: Fast parameters for most tests (the synthetic samples are 120 x 130 pixels).
FAST = {"window": 10, "degree": 5, "n_segments": 3}


@pytest.mark.parametrize("key", list(SAMPLES))
def test_samples_open_as_one_stack_with_angles(viewer, open_sample, key):
    stack = open_sample(key)
    assert isinstance(stack, Image)
    assert stack.data.shape == SAMPLES[key]
    angles = stack.metadata["angles_deg"]
    assert len(angles) == SAMPLES[key][0]
    if key == "fruits_camera":
        assert angles == [0.0, 45.0, 90.0, 135.0]
    else:
        assert angles == [0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0]
        truth = viewer.layers[f"{key} ground truth"]
        assert isinstance(truth, Labels) and not truth.visible
        assert truth.data.shape == SAMPLES[key][1:] and truth.data.min() == 1


@pytest.mark.parametrize("key", list(SAMPLES))
def test_both_widgets_match_the_engine(viewer, open_sample, add_widget, qtbot, key):
    stack = open_sample(key)
    pol_widget = add_widget("Polarisation image")
    seg_widget = add_widget("Segment by material")
    assert isinstance(pol_widget, PolarisationWidget)
    assert isinstance(seg_widget, SegmentWidget)
    assert pol_widget.stack_layer.value is stack
    assert seg_widget.angles.value == ", ".join(f"{a:g}" for a in stack.metadata["angles_deg"])

    # -- Polarisation image ----------------------------------------------------------------
    pol_widget.refractive_index.value = 1.5
    run_and_wait(qtbot, pol_widget)
    assert error_messages() == []
    angles = np.deg2rad(stack.metadata["angles_deg"])
    pol = polarisation_image(np.asarray(stack.data), angles)
    expected = {
        "intensity": pol.intensity,
        "dop": pol.dop,
        "phase": pol.phase,
        "zenith": zenith_from_dop(pol.dop, 1.5, "diffuse").zenith,
    }
    h, w = SAMPLES[key][1:]
    for role, name in POLARISATION_LAYERS.items():
        layer = viewer.layers[f"{name} ({stack.name})"]
        assert isinstance(layer, Image)
        assert layer.metadata[TAG]["role"] == role
        assert layer.data.shape == (h, w)
        np.testing.assert_allclose(layer.data, expected[role], rtol=1e-12, atol=1e-12)
    dop = viewer.layers[f"ρ degree of polarisation ({stack.name})"]
    assert 0.0 <= dop.data.min() and dop.data.max() <= 1.0
    lo, hi = np.percentile(pol.dop, [1, 99])
    assert dop.contrast_limits == pytest.approx([lo, hi])
    assert dop.colormap.name == "viridis"
    phase = viewer.layers[f"φ phase ({stack.name})"]
    assert phase.colormap.name == "twilight"
    assert tuple(phase.contrast_limits) == (0.0, math.pi)
    assert 0.0 <= phase.data.min() and phase.data.max() < math.pi
    assert viewer.layers[f"Î intensity ({stack.name})"].colormap.name == "gray"
    zenith = viewer.layers[f"θ zenith ({stack.name})"].data
    assert 0.0 <= zenith.min() and zenith.max() <= math.pi / 2

    # -- Segment by material ------------------------------------------------------------------
    seg_widget.set_params(**FAST)
    run_and_wait(qtbot, seg_widget)
    assert error_messages() == []
    ref = engine_result(stack, SegmentParams(**FAST))
    segments = viewer.layers[f"segments ({stack.name})"]
    assert isinstance(segments, Labels)
    assert segments.data.shape == (h, w)  # pixel resolution over the whole image
    np.testing.assert_array_equal(segments.data, ref.labels + 1)
    assert set(np.unique(segments.data)) == set(range(1, ref.n_segments + 1))
    error = viewer.layers[f"reconstruction error ({stack.name})"]
    assert isinstance(error, Image) and error.data.shape == (h, w)
    np.testing.assert_allclose(error.data, ref.reconstruction_error, rtol=1e-9, atol=1e-9)
    assert error.data.min() >= 0
    assert segments.metadata["polarseg_summary"]["n_segments"] == ref.n_segments
    thesis = segments.metadata["polarseg_params"]["method_params"]["thesis"]
    assert thesis["degree"] == FAST["degree"]
    assert "segments" in seg_widget.status.value


def test_thesis_defaults_run_off_the_gui_thread(
    viewer, open_sample, add_widget, qtbot, monkeypatch
):
    """Thesis defaults (w = 10, L = 12): Run returns at once; the event loop keeps turning."""
    from threadpoolctl import threadpool_info

    from napari_polarseg.engine.synthetic.scenes import make_scene

    blas_threads = {pool["filepath"]: pool["num_threads"] for pool in threadpool_info()}
    # large enough that the computation takes a while even with the fast engine, so that
    # one short stall of a busy machine is a small part of it
    # (four copies of a rendered scene: rendering one at this size takes a minute)
    scene = make_scene("leaves", shape=(480, 520))
    stack = viewer.add_image(
        np.tile(scene.stack, (1, 2, 2)),
        name="big leaves",
        metadata={"angles_deg": list(scene.angles_deg)},
    )
    widget = add_widget("Segment by material")
    # the widget starts at the thesis defaults (add_widget chooses the preset)
    assert widget.params() == SegmentParams(method="thesis")
    delivered: list[float] = []
    show = SegmentWidget._show

    def timed_show(self, *args):
        delivered.append(time.perf_counter())
        show(self, *args)
        delivered.append(time.perf_counter())

    monkeypatch.setattr(SegmentWidget, "_show", timed_show)
    ticks: list[float] = []
    timer = QTimer()
    timer.setInterval(10)
    timer.timeout.connect(lambda: ticks.append(time.perf_counter()))
    timer.start()
    t0 = time.perf_counter()
    click(qtbot, widget.run_button)
    returned_after = time.perf_counter() - t0
    assert widget.busy  # the computation goes on in the worker...
    assert returned_after < 0.25, f"Run blocked the GUI thread for {returned_after:.3f} s"
    wait_idle(qtbot, widget)
    timer.stop()
    # until the segments are shown (the error map follows; drawing the new layer then
    # is GUI-thread work)
    computing = delivered[0] - t0
    gaps = np.diff(np.concatenate([[t0], [t for t in ticks if t < delivered[0]]]))
    # ...while the GUI thread keeps processing events: the 10 ms timer keeps ticking.
    # (Computing in the GUI thread would show as one gap as long as the computation.
    # Short gaps remain: the worker's Python code and some C code hold the GIL, and
    # this machine may be busy; hence the generous bounds.)
    # (about 2 s to the segments here; computing in the GUI thread would be one gap)
    assert computing > 0.5, "the run was too short to show anything"
    stalled = gaps[gaps > 0.1].sum()
    assert stalled < 0.5 * computing, f"event loop stalled {stalled:.2f} of {computing:.2f} s"
    assert gaps.max() < max(1.0, 0.5 * computing), f"event loop stalled {gaps.max():.2f} s"
    # showing the results (napari creating the layers) is the only GUI-thread work
    assert len(delivered) == 4  # the segments, then everything
    assert max(np.diff(delivered)[::2]) < 1.5
    ref = engine_result(stack, SegmentParams(method="thesis"))
    np.testing.assert_array_equal(viewer.layers[f"segments ({stack.name})"].data, ref.labels + 1)
    np.testing.assert_allclose(
        viewer.layers[f"reconstruction error ({stack.name})"].data,
        ref.reconstruction_error,
        atol=1e-9,
    )
    # the BLAS thread limit held during the run is lifted again
    after = {pool["filepath"]: pool["num_threads"] for pool in threadpool_info()}
    assert {path: after[path] for path in blas_threads} == blas_threads


def test_rerun_replaces_in_place_and_never_touches_user_layers(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("camouflage")
    # the user's own layers, with the names the plugin uses
    user_segments = viewer.add_labels(np.ones((120, 130), dtype=np.int32), name="segments")
    user_phase = viewer.add_image(np.zeros((120, 130)), name="φ phase")
    pol_widget = add_widget("Polarisation image")
    seg_widget = add_widget("Segment by material")
    pol_widget.stack_layer.value = stack
    seg_widget.stack_layer.value = stack
    seg_widget.set_params(**FAST)
    run_and_wait(qtbot, pol_widget)
    run_and_wait(qtbot, seg_widget)
    first = {layer.metadata[TAG]["role"]: layer for layer in own_layers(viewer, stack)}
    views = {"hsv", "s0", "s1", "s2"}  # the polarisation views (issue 14)
    assert set(first) == {"intensity", "dop", "phase", "zenith", "segments", "error"} | views
    n_layers = len(viewer.layers)
    before = first["segments"].data.copy()

    pol_widget.refractive_index.value = 1.6
    seg_widget.n_segments.value = 2
    run_and_wait(qtbot, pol_widget)
    run_and_wait(qtbot, seg_widget)
    assert len(viewer.layers) == n_layers  # no duplicates piled up
    second = {layer.metadata[TAG]["role"]: layer for layer in own_layers(viewer, stack)}
    for role, layer in first.items():
        assert second[role] is layer  # the same layer object, data replaced in place
    assert not np.array_equal(second["segments"].data, before)
    assert set(np.unique(second["segments"].data)) == {1, 2}
    # the user's layers are untouched
    np.testing.assert_array_equal(user_segments.data, 1)
    np.testing.assert_array_equal(user_phase.data, 0)
    assert TAG not in user_segments.metadata and TAG not in user_phase.metadata
    assert user_segments.name == "segments" and first["segments"].name != "segments"

    # renaming the plugin's layer does not make the next run add another one
    second["segments"].name = "my segmentation"
    run_and_wait(qtbot, seg_widget)
    assert len(viewer.layers) == n_layers
    assert viewer.layers["my segmentation"] is first["segments"]


def test_changing_only_segments_reuses_cached_harmonics(
    viewer, open_sample, add_widget, qtbot, monkeypatch
):
    import threading

    import napari_polarseg.engine.pipeline as pipeline_module

    calls = []
    original = pipeline_module.harmonics.block_coefficients

    def counting(*args, **kwargs):
        if threading.current_thread() is not threading.main_thread():  # the widget's worker
            calls.append(kwargs.get("method"))
        return original(*args, **kwargs)

    monkeypatch.setattr(pipeline_module.harmonics, "block_coefficients", counting)
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    pipe = widget.pipeline
    assert pipe is not None and pipe.calls["harmonics"] == 1
    assert calls.count("thesis") == 1

    widget.live.value = True
    for k in (2, 4, 5):
        widget.n_segments.value = k
        wait_idle(qtbot, widget)
        ref = engine_result(stack, SegmentParams(**{**FAST, "n_segments": k}))
        np.testing.assert_array_equal(
            viewer.layers[f"segments ({stack.name})"].data, ref.labels + 1
        )
    assert widget.pipeline is pipe  # one pipeline kept per stack layer
    assert pipe.calls["harmonics"] == 1  # harmonics were not computed again
    assert calls.count("thesis") == 1
    assert pipe.calls["labels"] == 4
    for stage in ("polarisation", "normals", "pca", "affinity", "cut", "reconstruction"):
        assert pipe.calls[stage] == 1, stage

    # a change upstream of the harmonics recomputes them (and only once)
    widget.window.value = 12
    wait_idle(qtbot, widget)
    assert pipe.calls["harmonics"] == 2
    assert pipe.calls["polarisation"] == 1


@pytest.fixture
def blocked_harmonics(gate):
    """Make the harmonics stage wait for ``release`` (deterministic mid-run actions)."""
    return gate("block_coefficients")


def test_cancel_leaves_no_half_written_layer(
    viewer, open_sample, add_widget, qtbot, blocked_harmonics
):
    gate = blocked_harmonics
    stack = open_sample("fruit")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)

    # 1. first run, cancelled after the harmonics stage: no output layer at all
    gate.arm()
    click(qtbot, widget.run_button)
    assert widget.cancel_button.enabled
    qtbot.waitUntil(gate.entered.is_set, timeout=10_000)
    click(qtbot, widget.cancel_button)
    gate.release.set()
    wait_idle(qtbot, widget)
    assert widget.status.value == "cancelled"
    assert widget.output("segments") is None and widget.output("error") is None
    assert "segments" not in viewer.layers
    pipe = widget.pipeline
    # stopped inside the harmonics (Cancel is checked after every chunk of a stage)
    assert pipe.calls["harmonics"] == 0 and pipe.calls["pca"] == 0
    assert not widget.cancel_button.enabled

    # 2. a full run reuses the harmonics cached before the cancel
    run_and_wait(qtbot, widget)
    assert pipe.calls["harmonics"] == 1
    segments = widget.output("segments")
    before = segments.data.copy()
    error_before = widget.output("error").data.copy()
    np.testing.assert_array_equal(before, engine_result(stack, widget.params()).labels + 1)

    # 3. a new window size, cancelled mid-run: the previous layers stay as they were
    widget.window.value = 8
    gate.arm()
    click(qtbot, widget.run_button)
    qtbot.waitUntil(gate.entered.is_set, timeout=10_000)
    click(qtbot, widget.cancel_button)
    gate.release.set()
    wait_idle(qtbot, widget)
    assert widget.output("segments") is segments
    np.testing.assert_array_equal(segments.data, before)
    np.testing.assert_array_equal(widget.output("error").data, error_before)
    assert len([layer for layer in viewer.layers if layer.name.startswith("segments")]) == 1
    assert error_messages() == []


def test_one_worker_at_a_time_and_stale_results_are_dropped(
    viewer, open_sample, add_widget, qtbot, blocked_harmonics
):
    gate = blocked_harmonics
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)

    # live off: a value changed while the worker computes makes its result stale
    gate.arm()
    click(qtbot, widget.run_button)
    qtbot.waitUntil(gate.entered.is_set, timeout=10_000)
    widget.n_segments.value = 4
    gate.release.set()
    wait_idle(qtbot, widget)
    assert widget.output("segments") is None
    assert "dropped" in widget.status.value

    # live on: changes during a run stop it at the next stage and queue the newest values
    gate.arm()
    widget.degree.value = 4
    widget.live.value = True
    qtbot.waitUntil(gate.entered.is_set, timeout=10_000)  # the live run reached harmonics
    first_worker = widget.worker
    widget.n_segments.value = 2
    widget.n_segments.value = 3
    qtbot.wait(300)  # longer than the live delay: the request is queued behind the worker
    assert widget.worker is first_worker and widget.busy
    gate.release.set()
    wait_idle(qtbot, widget)
    assert gate.state["max_active"] == 1  # never two workers at once
    pipe = widget.pipeline
    assert pipe.calls["harmonics"] == 2  # degree 5 (first run) and degree 4, each once
    ref = engine_result(stack, SegmentParams(**{**FAST, "degree": 4, "n_segments": 3}))
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)
    assert widget.output("segments").metadata["polarseg_params"]["n_segments"] == 3


def test_engine_errors_become_notifications(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)

    widget.window.value = 200  # larger than the 120 x 130 image
    run_and_wait(qtbot, widget)
    expected = "window size 200 is larger than the image (120 x 130 pixels)"
    assert error_messages() == [expected]
    assert widget.last_error == expected and widget.status.value == f"error: {expected}"
    assert widget.output("segments") is None

    widget.window.value = 10
    widget.angles.value = "0, 45"
    run_and_wait(qtbot, widget)
    assert error_messages()[-1] == "the stack has 7 frames but 2 angles were given"

    widget.angles.value = "0, 0, 0, 90, 90, 90, 180"
    run_and_wait(qtbot, widget)
    assert error_messages()[-1] == (
        "need at least 3 distinct polariser angles (modulo 180 degrees), got 2"
    )

    widget.angles.value = "0, 30, sixty"
    run_and_wait(qtbot, widget)
    assert error_messages()[-1] == "angles must be numbers in degrees, got 'sixty'"

    # the viewer stays usable: a good run afterwards works
    widget.angles.value = "0, 30, 60, 90, 120, 150, 180"
    run_and_wait(qtbot, widget)
    assert widget.output("segments") is not None
    assert len(error_messages()) == 4
    assert stack in viewer.layers


def test_polarisation_widget_reports_missing_angles(viewer, add_widget, qtbot):
    data = np.random.default_rng(0).uniform(1, 2, size=(4, 32, 40))
    stack = viewer.add_image(data, name="no angles")
    widget = add_widget("Polarisation image")
    assert widget.stack_layer.value is stack
    assert widget.angles.value == ""
    click(qtbot, widget.run_button)
    assert error_messages() == [
        "give the polariser angles in degrees, one per frame (e.g. 0,45,90,135)"
    ]
    widget.angles.value = "0,45,90,135"
    run_and_wait(qtbot, widget)
    assert viewer.layers[f"Î intensity ({stack.name})"].data.shape == (32, 40)


def test_segments_visible_in_a_canvas_screenshot(make_napari_viewer, qtbot):
    viewer = make_napari_viewer(show=True)  # rendering needs a shown (Xvfb) window
    stack = viewer.open_sample("napari-polarseg", "leaves")[0]
    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    segments = widget.output("segments")
    assert viewer.layers[-1] is segments  # on top, over the grey stack
    assert widget.output("error") is None  # the default method computes no error map
    viewer.reset_view()
    shot = viewer.screenshot(canvas_only=True, flash=False)
    assert shot.ndim == 3 and shot.shape[2] == 4
    rgb = shot[..., :3].astype(int)
    # the stack is grey (r = g = b); the labels tint it with their colours
    coloured = (rgb.max(axis=-1) - rgb.min(axis=-1)) > 25
    assert coloured.mean() > 0.2, "the segments layer is not visible in the screenshot"
    colours = {tuple(c) for c in (rgb[coloured] // 32)}
    assert len(colours) >= 3, f"expected several label colours, got {colours}"

    segments.visible = False
    hidden = viewer.screenshot(canvas_only=True, flash=False)[..., :3].astype(int)
    assert ((hidden.max(axis=-1) - hidden.min(axis=-1)) > 25).mean() < 0.01
    assert stack.visible


def test_presets_and_controls_describe_the_engine_parameters(viewer, add_widget):
    from napari_polarseg.engine.params import RECOMMENDED

    widget = add_widget("Segment by material")
    assert widget.params() == SegmentParams(method="thesis")
    widget.preset.value = "recommended"
    assert widget.params() == RECOMMENDED
    widget.n_segments.value = 5
    widget.model.value = "specular"
    assert not widget.specular_branch.native.isHidden()  # (the viewer itself is hidden)
    widget.specular_branch.value = "above-brewster"
    assert widget.params() == RECOMMENDED.replace(
        n_segments=5, model="specular", specular_branch="above-brewster"
    )
    widget.preset.value = "thesis"
    assert widget.params() == SegmentParams(method="thesis")
    assert widget.specular_branch.native.isHidden()
