"""The polarisation views in the plugin: the HSV composite and the Stokes layers.

After *Compute* the Polarisation image widget adds an RGB ``AoLP/DoLP HSV`` layer (the
engine's composite of the same Î, ρ, φ) and hidden ``S0/S1/S2 Stokes`` layers; its *DoLP
maximum* spin box redraws only the composite.
"""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import SAMPLES, error_messages, run_and_wait

from napari_polarseg.engine import polarisation_image
from napari_polarseg.engine.analysis.views import (
    CompositeParams,
    aolp_dolp_composite,
    auto_dolp_max,
)
from napari_polarseg.engine.physics.stokes import stokes_components
from napari_polarseg.widgets import polarisation as polarisation_module
from napari_polarseg.widgets._layers import TAG

pytestmark = pytest.mark.gui


def test_hsv_and_stokes_layers_after_compute_and_the_dolp_maximum(
    viewer, open_sample, add_widget, qtbot, monkeypatch
):
    stack = open_sample("leaves")
    widget = add_widget("Polarisation image")
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    pol = polarisation_image(np.asarray(stack.data), np.deg2rad(stack.metadata["angles_deg"]))
    h, w = SAMPLES["leaves"][1:]

    hsv = viewer.layers[f"AoLP/DoLP HSV ({stack.name})"]
    assert hsv.rgb and hsv.visible and hsv.metadata[TAG]["role"] == "hsv"
    assert hsv.data.shape == (h, w, 3) and hsv.data.dtype == np.uint8
    auto = auto_dolp_max(pol.dop)
    assert widget.dolp_max.value == 0.0  # "auto"
    assert hsv.metadata["polarseg_composite"]["dolp_max"] == pytest.approx(auto)
    want = aolp_dolp_composite(pol.intensity, pol.dop, pol.phase, CompositeParams(dolp_max=auto))
    np.testing.assert_array_equal(hsv.data, want)

    stokes = stokes_components(pol.intensity, pol.dop, pol.phase)
    for k in range(3):
        layer = viewer.layers[f"S{k} Stokes ({stack.name})"]
        assert not layer.visible and layer.metadata[TAG]["role"] == f"s{k}"
        np.testing.assert_allclose(layer.data, stokes[k], rtol=1e-12, atol=1e-9)
    # of the four maps only ρ starts visible (stacked, the top one would hide the others)
    shown = {
        n: viewer.layers[f"{n} ({stack.name})"].visible
        for n in ("Î intensity", "φ phase", "θ zenith")
    }
    assert viewer.layers[f"ρ degree of polarisation ({stack.name})"].visible and not any(
        shown.values()
    )

    # the DoLP maximum redraws only the composite, without a new computation
    def no_job(*args, **kwargs):
        raise AssertionError("the DoLP maximum must not recompute the polarisation image")

    monkeypatch.setattr(polarisation_module, "polarisation_job", no_job)
    intensity_data = viewer.layers[f"Î intensity ({stack.name})"].data
    before = hsv.data.copy()
    n_layers = len(viewer.layers)
    widget.dolp_max.value = 0.02
    after = viewer.layers[f"AoLP/DoLP HSV ({stack.name})"].data
    assert not np.array_equal(after, before)
    np.testing.assert_array_equal(
        after,
        aolp_dolp_composite(pol.intensity, pol.dop, pol.phase, CompositeParams(dolp_max=0.02)),
    )
    assert viewer.layers[f"AoLP/DoLP HSV ({stack.name})"] is hsv and len(viewer.layers) == n_layers
    assert viewer.layers[f"Î intensity ({stack.name})"].data is intensity_data
    # a lower maximum saturates more pixels
    sat = lambda rgb: rgb.max(axis=-1).astype(int) - rgb.min(axis=-1)  # noqa: E731
    assert sat(after).mean() > sat(before).mean()
    widget.dolp_max.value = 0.0  # back to auto: the first picture again
    np.testing.assert_array_equal(viewer.layers[f"AoLP/DoLP HSV ({stack.name})"].data, before)


def test_a_run_keeps_the_users_layer_selection(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    mine = viewer.add_labels(np.zeros(stack.data.shape[1:], dtype=np.int32), name="mine")
    viewer.layers.selection.active = mine
    widget = add_widget("Segment by material")
    run_and_wait(qtbot, widget)
    assert widget.output("segments") is not None
    assert viewer.layers.selection.active is mine
    assert set(viewer.layers.selection) == {mine}
