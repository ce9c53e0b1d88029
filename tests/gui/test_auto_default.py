"""The plugin's default (issue 13 item 4): *Segment by material* starts on preset auto."""

from __future__ import annotations

import numpy as np
from _gui_helpers import engine_result, error_messages, run_and_wait

from napari_polarseg.engine.params import AUTO, DEFAULT_PRESET


def test_segment_widget_defaults_to_auto_and_matches_the_engine(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)
    assert widget.preset.value == "auto" == DEFAULT_PRESET
    assert widget.params() == AUTO
    assert widget.method.value == AUTO.method
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    ref = engine_result(stack, AUTO)
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)
    # a degenerate result would say so in the status line; this one is not
    assert "degenerate" not in widget.status.value
    assert "one smooth surface" not in widget.status.value  # many leaves, not a close-up


def test_status_line_says_when_the_frame_is_a_close_up(viewer, open_sample, add_widget, qtbot):
    """On the fruit close-up the default segments by the departure from the surface's
    trend and the status line says so, as the CLI does."""
    stack = open_sample("fruit")
    widget = add_widget("Segment by material", preset=None)
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    share = engine_result(stack, AUTO).method_record["surface_share"]
    assert 0.8 < share < 1.0  # the close-up test's threshold, and not the whole of it
    assert f"one smooth surface ({share:.0%} of the polarisation)" in widget.status.value
    summary = widget.output("segments").metadata["polarseg_summary"]
    assert summary["superpixels"]["close_up"] is True
    ref = engine_result(stack, AUTO)
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)


def test_segments_box_says_what_0_means_and_0_finds_the_number(
    viewer, open_sample, add_widget, qtbot
):
    """The box cannot show the word "auto", so its label names it, as the CLI takes it
    (``--segments auto`` is 0); 0 runs the method's own choice of k, as the engine does."""
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)
    assert widget.n_segments.label == "segments (0 = auto)"
    assert widget.n_segments.min == 0
    assert widget.window.label == "window size"  # a box with no word keeps its plain label
    widget.n_segments.value = 0
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    ref = engine_result(stack, AUTO.replace(n_segments=0))
    assert ref.method_record["k_found"] is True
    np.testing.assert_array_equal(widget.output("segments").data, ref.labels + 1)
    assert f"{ref.method_record['k']} segments" in widget.status.value


def test_segments_box_says_0_is_auto_only_under_a_method_that_finds_the_number(viewer, add_widget):
    from qtpy.QtWidgets import QLabel

    from napari_polarseg.engine.params import FINDS_K_METHODS

    widget = add_widget("Segment by material", preset=None)

    def on_screen() -> list[str]:  # the labels the dock shows
        return [label.text() for label in widget.native.findChildren(QLabel)]

    assert "thesis" not in FINDS_K_METHODS and AUTO.method in FINDS_K_METHODS
    assert "segments (0 = auto)" in on_screen()
    widget.method.value = "thesis"
    assert widget.n_segments.label == "segments"
    assert "segments" in on_screen() and "segments (0 = auto)" not in on_screen()
    widget.method.value = AUTO.method
    assert widget.n_segments.label == "segments (0 = auto)" and "segments (0 = auto)" in on_screen()
