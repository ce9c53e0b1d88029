"""Issue 25: showing a result runs no percentile on the GUI thread (the contrast limits
come from the worker) and adds its secondary layers one per event-loop turn."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from _gui_helpers import run_and_wait

import napari_polarseg.widgets._layers as layers_module
from napari_polarseg.widgets._layers import ROLES, contrast_of, find_output


@pytest.fixture
def percentile_threads(monkeypatch):
    """The threads ``fitted_limits`` (the percentile) ran on, as a list of booleans:
    True for the GUI (main) thread."""
    calls: list[bool] = []
    original = layers_module.fitted_limits

    def recorded(*args, **kwargs):
        calls.append(threading.current_thread() is threading.main_thread())
        return original(*args, **kwargs)

    monkeypatch.setattr(layers_module, "fitted_limits", recorded)
    return calls


def _image_roles(viewer, stack):
    out = {}
    for role, style in ROLES.items():
        layer = find_output(viewer, role, stack)
        if layer is not None and style.layer_type == "image":
            out[role] = layer
    return out


def test_polarisation_contrast_comes_from_the_worker(
    viewer, open_sample, add_widget, qtbot, percentile_threads
):
    stack = open_sample("fruits_camera")
    widget = add_widget("Polarisation image")
    run_and_wait(qtbot, widget)
    shown = _image_roles(viewer, stack)
    assert set(shown) == {"intensity", "dop", "phase", "zenith", "s0", "s1", "s2", "hsv"}
    assert percentile_threads and not any(percentile_threads)  # all in the worker
    for role, layer in shown.items():
        expected = contrast_of(role, np.asarray(layer.data))
        np.testing.assert_allclose(layer.contrast_limits, expected.limits, err_msg=role)
    # a rerun updates them in place, with the worker's values again
    percentile_threads.clear()
    widget.refractive_index.value = 1.6
    run_and_wait(qtbot, widget)
    assert percentile_threads and not any(percentile_threads)
    zenith = find_output(viewer, "zenith", stack)
    expected = contrast_of("zenith", np.asarray(zenith.data))
    np.testing.assert_allclose(zenith.contrast_limits, expected.limits)
    np.testing.assert_allclose(zenith.contrast_limits_range, expected.range)


def test_segment_maps_contrast_comes_from_the_worker(
    viewer, open_sample, add_widget, qtbot, percentile_threads
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")  # thesis preset: with the error map
    widget.set_params(window=10, degree=5, fit="robust")  # robust: the fit residual too
    widget.views.value = True
    run_and_wait(qtbot, widget)
    shown = _image_roles(viewer, stack)
    assert {"error", "residual", "s0", "hsv"} <= set(shown)
    on_gui = [c for c in percentile_threads if c]
    # the error map and the residual: from the worker; only the optional HSV and Stokes
    # views (off by default) are still fitted on the GUI thread
    assert len(on_gui) <= 3
    for role in ("error", "residual"):
        layer = shown[role]
        expected = contrast_of(role, np.asarray(layer.data))
        np.testing.assert_allclose(layer.contrast_limits, expected.limits, err_msg=role)
    percentile_threads.clear()
    widget.views.value = False
    widget.n_segments.value = 4  # a rerun: the maps updated in place
    run_and_wait(qtbot, widget)
    assert not any(percentile_threads)


def test_secondary_layers_come_one_per_event_loop_turn(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Polarisation image")
    queue = widget._later
    per_turn: list[int] = []

    def counted() -> None:
        before = len(viewer.layers)
        queue._next()
        per_turn.append(len(viewer.layers) - before)

    queue._timer.timeout.disconnect()
    queue._timer.timeout.connect(counted)
    run_and_wait(qtbot, widget)  # waits for the queued layers too
    assert per_turn == [1] * 8  # Î, ρ, φ, θ, S0, S1, S2, HSV: one per turn
    assert len(_image_roles(viewer, stack)) == 8
