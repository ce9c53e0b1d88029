"""Every widget's Run / Compute / Cancel button says what it does (issue 14, item 6)."""

from __future__ import annotations

import pytest

WIDGETS = (
    "Polarisation image",
    "Segment by material",
    "Batch over a folder",
    "Time series change map",
    "Polarisation plots",
    "Parameter sweep",
)


@pytest.mark.parametrize("name", WIDGETS)
def test_run_and_cancel_buttons_have_tooltips(viewer, add_widget, name):
    widget = add_widget(name)
    buttons = [widget.run_button] + (
        [widget.cancel_button] if hasattr(widget, "cancel_button") else []
    )
    for button in buttons:
        tip = button.native.toolTip()
        assert len(tip.split()) >= 4, f"{name}: {button.text!r} has the tooltip {tip!r}"


def test_time_series_offers_no_superpixel_preset(viewer, add_widget):
    # the time series cuts one block graph of all days (engine.analysis.timeseries refuses
    # clustering="superpixels"), so its parameter menu has no preset auto
    widget = add_widget("Time series change map")
    assert "auto" not in widget.source.choices
    assert "recommended" in widget.source.choices


def _controls(container):
    """Every magicgui control inside ``container`` (nested containers, the footer)."""
    from magicgui.widgets import Container, Label, ProgressBar, Table

    # the footer (Run, Cancel, status) and the sweep's row of buttons below its heatmaps
    parts = list(container) + [getattr(container, k, None) for k in ("footer", "_buttons")]
    for widget in parts:
        if widget is None or isinstance(widget, (Label, ProgressBar, Table)):
            continue
        if isinstance(widget, Container):
            yield from _controls(widget)
        else:
            yield widget


@pytest.mark.parametrize("name", WIDGETS)
def test_every_control_has_a_tooltip(viewer, add_widget, name):
    # issue 25: a user hovering any control of any dock learns what it does
    widget = add_widget(name)
    controls = list(_controls(widget))
    assert len(controls) >= 3
    missing = [
        getattr(c, "label", "") or getattr(c, "text", "") or c.name
        for c in controls
        if not c.native.toolTip().strip()
    ]
    assert missing == [], f"{name}: no tooltip on {missing}"


#: Words of the thesis that a control's first line (what it does to the result) avoids.
JARGON = (
    "eq.",
    "thesis section",
    "Gram",
    "Mahalanobis",
    "IRLS",
    "Ncut",
    "normalized cut",
    "eigen",
    "harmonic",
    "PCA",
    "spherical",
    "Fresnel",
    "Tukey",
    "(L+1)",
)


def test_segment_tooltips_lead_with_what_a_control_does(viewer, add_widget):
    # issue 25: the Segment widget's tooltips were long and full of thesis words; what a
    # control does is its spec's effect (the shared table's, or its method's own)
    widget = add_widget("Segment by material")
    for name in widget.controlled:
        effect = widget.param_specs[name].effect
        tip = getattr(widget, name).native.toolTip()
        assert effect and tip.startswith(effect), name
        assert "Details:" in tip  # the technical help follows
    for control in _controls(widget):
        lead = control.native.toolTip().split("\n\n")[0]
        label = getattr(control, "label", "") or getattr(control, "text", "") or control.name
        assert len(lead.split()) <= 45, f"{label}: {lead!r}"
        found = [word for word in JARGON if word.lower() in lead.lower()]
        assert found == [], f"{label}: {found} in {lead!r}"
