"""The Segment widget says when a result is degenerate, and Cancel stops a running cut
at once (issue 13)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from _gui_helpers import click, engine_result, error_messages, run_and_wait, wait_idle

from napari_polarseg.engine import Cancelled, SegmentParams
from napari_polarseg.engine.graph import ncut
from napari_polarseg.engine.params import RECOMMENDED

pytestmark = pytest.mark.gui

#: Thesis scale at degree 5 on the leaves sample: [15400, 100, 100] pixels.
DEGENERATE = SegmentParams(window=10, degree=5, n_segments=3)
#: 624 blocks (above ncut.DENSE_EIGH_MAX: the iterative eigensolver runs).
ITERATIVE = SegmentParams(window=5, degree=4, n_segments=3)


def test_status_line_says_when_one_segment_holds_nearly_everything(
    viewer, open_sample, add_widget, qtbot
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(DEGENERATE)
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    status = widget.status.value
    assert status.startswith(
        "3 segments · degenerate: one segment holds 98.72 % of the pixels (try the "
        "recommended preset, fewer or more segments, a larger window, or scribbles) · "
    )
    summary = widget.output("segments").metadata["polarseg_summary"]
    assert summary["degenerate"] is True
    assert summary["largest_segment_share"] == pytest.approx(15400 / 15600, abs=1e-6)

    widget.set_params(RECOMMENDED)
    run_and_wait(qtbot, widget)
    assert "degenerate" not in widget.status.value
    assert widget.output("segments").metadata["polarseg_summary"]["degenerate"] is False
    np.testing.assert_array_equal(
        widget.output("segments").data, engine_result(stack, RECOMMENDED).labels + 1
    )


@pytest.fixture
def slow_products(monkeypatch):
    """Every product of the cut's eigensolvers takes until ``release`` (at most 30 s),
    checking the run's cancel request every 5 ms as the solvers do between products."""
    entered, release = threading.Event(), threading.Event()
    original = ncut.Budget.take

    def take(self, columns, stop=None):
        entered.set()
        deadline = time.monotonic() + 30
        while not release.is_set() and time.monotonic() < deadline:
            if self.cancel is not None and self.cancel():
                raise Cancelled("the normalized cut was cancelled")
            time.sleep(0.005)
        return original(self, columns, stop)

    monkeypatch.setattr(ncut.Budget, "take", take)
    yield entered, release
    release.set()


def test_cancel_stops_a_running_cut_within_a_second(
    viewer, open_sample, add_widget, qtbot, slow_products
):
    entered, release = slow_products
    stack = open_sample("camouflage")
    widget = add_widget("Segment by material")
    widget.set_params(ITERATIVE)

    # 1. Cancel while the eigensolver runs: the run ends at once, nothing is shown
    click(qtbot, widget.run_button)
    qtbot.waitUntil(entered.is_set, timeout=60_000)
    t0 = time.perf_counter()
    click(qtbot, widget.cancel_button)
    wait_idle(qtbot, widget, timeout=5_000)
    assert time.perf_counter() - t0 < 1.0
    assert widget.status.value == "cancelled"
    assert widget.output("segments") is None
    pipe = widget.pipeline
    assert pipe.is_fresh("cut") and not pipe.is_fresh("labels")  # stopped inside the cut

    # 2. a newer request while the cut runs: it starts at once (the issue: it sat at
    # "stopping the previous run…" until the stage ended), and its result is right
    entered.clear()
    click(qtbot, widget.run_button)
    qtbot.waitUntil(entered.is_set, timeout=60_000)
    first = widget._slot.worker
    t0 = time.perf_counter()
    widget.set_params(n_segments=2)
    click(qtbot, widget.run_button)
    qtbot.waitUntil(lambda: widget._slot.worker not in (None, first), timeout=5_000)
    assert time.perf_counter() - t0 < 1.0
    assert "stopping" not in widget.status.value
    release.set()
    wait_idle(qtbot, widget)
    assert error_messages() == []
    expected = engine_result(stack, ITERATIVE.replace(n_segments=2)).labels + 1
    np.testing.assert_array_equal(widget.output("segments").data, expected)
