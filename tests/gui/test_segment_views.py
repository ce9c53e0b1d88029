"""*Segment by material* adds the AoLP/DoLP HSV and Stokes layers too, and both widgets
offer the light and dark variants of the HSV view (issue 14, item 6)."""

from __future__ import annotations

import numpy as np
from _gui_helpers import error_messages, run_and_wait, wait_idle

from napari_polarseg.engine import polarisation_image
from napari_polarseg.engine.analysis.views import (
    CompositeParams,
    aolp_dolp_composite,
    auto_dolp_max,
)
from napari_polarseg.engine.physics.stokes import stokes_components
from napari_polarseg.widgets._layers import TAG

FAST = {"window": 10, "degree": 5, "n_segments": 3}


def _composite(result, mode: str) -> np.ndarray:
    params = CompositeParams(dolp_max=auto_dolp_max(result.dop), mode=mode)
    return aolp_dolp_composite(result.intensity, result.dop, result.phase, params)


def test_segment_widget_adds_views_in_the_chosen_hsv_variant(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    assert widget.output("hsv") is None  # off by default: the layer list stays short
    widget.views.value = True  # draws the shown result's views at once, no rerun
    widget.view_mode.value = "dark"
    wait_idle(qtbot, widget)  # the layers come one per event-loop turn
    result = widget.shown_result(stack)
    hsv = widget.output("hsv")
    assert hsv is not None and hsv.rgb and hsv.metadata[TAG]["role"] == "hsv"
    assert hsv.name == f"AoLP/DoLP HSV ({stack.name})"
    assert hsv.metadata["polarseg_composite"]["mode"] == "dark"
    np.testing.assert_array_equal(hsv.data, _composite(result, "dark"))
    for k, want in enumerate(stokes_components(result.intensity, result.dop, result.phase)):
        layer = widget.output(f"s{k}")
        assert layer is not None and not layer.visible
        np.testing.assert_allclose(layer.data, want)
    layers = list(viewer.layers)
    assert layers[-1] is widget.output("segments")  # the segments stay on top
    # "dark": value from ρ, so the least polarised pixels are the darkest
    rho = np.asarray(result.dop)
    value = hsv.data.max(axis=-1)
    calm, strong = rho < np.percentile(rho, 5), rho > np.percentile(rho, 95)
    assert value[calm].mean() < 0.5 * value[strong].mean()
    # another variant redraws the same layer in place, without a rerun
    calls = dict(widget.pipeline.calls)
    widget.view_mode.value = "light"
    wait_idle(qtbot, widget)
    assert widget.output("hsv") is hsv and dict(widget.pipeline.calls) == calls
    np.testing.assert_array_equal(hsv.data, _composite(result, "light"))
    # a rerun updates the views with the new result
    widget.n_segments.value = 2
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    assert widget.output("hsv") is hsv
    np.testing.assert_array_equal(hsv.data, _composite(widget.shown_result(stack), "light"))


def test_polarisation_widget_offers_the_dark_hsv_view(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Polarisation image")
    run_and_wait(qtbot, widget)
    hsv = widget.output("hsv")
    pol = polarisation_image(np.asarray(stack.data), np.deg2rad(stack.metadata["angles_deg"]))
    np.testing.assert_array_equal(hsv.data, _composite(pol, "intensity"))
    widget.view_mode.value = "dark"
    assert widget.output("hsv") is hsv
    assert hsv.metadata["polarseg_composite"]["mode"] == "dark"
    np.testing.assert_array_equal(hsv.data, _composite(pol, "dark"))
