"""Issue 25: a map the method did not compute is a note in overview.png, not a flat
image with a meaningless colour bar."""

from __future__ import annotations

import numpy as np
import pytest

from napari_polarseg.engine import Scene
from napari_polarseg.engine.params import AUTO, PRESETS
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.outputs.overview import overview_figure

SHAPE = (48, 56)


@pytest.fixture(scope="module")
def scene():
    return make_scene("leaves", shape=SHAPE, angles_deg=(0.0, 45.0, 90.0, 135.0), noise_sigma=0)


def _error_panel(fig):
    """The reconstruction-error panel and the colour bars of the figure."""
    panel = next(ax for ax in fig.axes if ax.get_title() == "reconstruction error")
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    return panel, bars


def test_the_error_map_of_a_method_without_it_is_a_note_without_colour_bar(scene):
    result = Scene(scene.stack, np.deg2rad(scene.angles_deg)).segment(AUTO.replace(n_segments=3))
    assert result.reconstruction_error is None
    fig = overview_figure(scene.stack[0], result)
    panel, bars = _error_panel(fig)
    assert len(panel.images) == 0  # no flat image
    text = " ".join(" ".join(t.get_text().split()) for t in panel.texts)
    assert f"not computed by the {result.method} method" in text
    # one colour bar per image panel (input, Î, ρ, φ, HSV, segments): none for the note
    assert len(bars) == sum(1 for ax in fig.axes if ax.images)
    fig.canvas.draw()  # lays out and draws without error


def test_a_computed_error_map_keeps_its_image_and_colour_bar(scene):
    params = PRESETS["thesis"].replace(window=8, n_segments=3)
    result = Scene(scene.stack, np.deg2rad(scene.angles_deg)).segment(params)
    assert result.reconstruction_error is not None
    fig = overview_figure(scene.stack[0], result)
    panel, bars = _error_panel(fig)
    assert len(panel.images) == 1 and len(panel.texts) == 0
    assert len(bars) == sum(1 for ax in fig.axes if ax.images)


def test_the_aolp_bar_names_its_unit_above_itself_not_beside(scene):
    """The AoLP colour bar's label sat in the gap before the next panel (issue 25): it is
    the bar's title, and the bar's right edge stays left of the next panel."""
    result = Scene(scene.stack, np.deg2rad(scene.angles_deg)).segment(AUTO.replace(n_segments=3))
    fig = overview_figure(scene.stack[0], result)
    fig.canvas.draw()
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    aolp = next(ax for ax in bars if ax.get_title() == "AoLP °")
    assert aolp.get_ylabel() == ""
    renderer = fig.canvas.get_renderer()
    right = aolp.get_tightbbox(renderer).x1
    later = [
        ax.get_window_extent().x0
        for ax in fig.axes
        if ax.images
        and ax.get_window_extent().x0 > aolp.get_window_extent().x0
        and abs(ax.get_window_extent().y0 - aolp.get_window_extent().y0) < 50
    ]
    assert later and right < min(later)
