"""How runs show up while they compute: segments before the error map, quiet live reruns,
napari's activity dock only for long runs, and the idle-time prefetch of the next cut."""

from __future__ import annotations

import time

import numpy as np
import pytest
from _gui_helpers import click, engine_result, error_messages, run_and_wait, wait_idle

from napari_polarseg.engine.methods import MethodOutput, register_method, unregister_method
from napari_polarseg.widgets import _runner
from napari_polarseg.widgets._layers import source_key
from napari_polarseg.widgets._runner import REPORT_INTERVAL, Result, WorkerSlot

pytestmark = pytest.mark.gui

FAST = {"window": 10, "degree": 5, "n_segments": 3}


def test_segments_are_shown_before_the_error_map(viewer, open_sample, add_widget, qtbot, gate):
    gate = gate("reconstruct_intensity")
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    gate.arm()
    click(qtbot, widget.run_button)
    qtbot.waitUntil(gate.entered.is_set, timeout=60_000)
    # the reconstruction has not run yet, but the segments are on screen
    qtbot.waitUntil(lambda: widget.output("segments") is not None, timeout=10_000)
    assert widget.output("error") is None
    assert widget.busy and widget.status.value.endswith("computing the error map…")
    shown = widget.output("segments")
    early = shown.data.copy()
    gate.release.set()
    wait_idle(qtbot, widget)
    assert error_messages() == []
    want = engine_result(stack, widget.params())
    np.testing.assert_array_equal(early, want.labels + 1)
    error = widget.output("error")
    np.testing.assert_allclose(error.data, want.reconstruction_error)
    assert widget.output("segments") is shown and viewer.layers[-1] is shown  # on top
    layers = list(viewer.layers)
    assert layers.index(error) < layers.index(shown)
    assert "mean reconstruction error" in widget.status.value
    summary = shown.metadata["polarseg_summary"]
    assert summary["mean_reconstruction_error"] == pytest.approx(want.mean_reconstruction_error)


def test_live_rerun_reports_only_when_it_lasts(viewer, open_sample, add_widget, qtbot, gate):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    done = widget.status.value
    assert not widget.cancel_button.enabled and widget.progress.value == widget.progress.max
    gate = gate("block_coefficients")
    gate.arm()
    widget.live.value = True
    widget.set_params(window=8)
    qtbot.waitUntil(gate.entered.is_set, timeout=10_000)
    started = time.monotonic()
    # a live rerun changes nothing in the dock at first (every repaint costs CPU) ...
    assert not widget.cancel_button.enabled and widget.status.value == done
    # ... and reports, with Cancel, once it has lasted REPORT_INTERVAL
    qtbot.waitUntil(lambda: widget.cancel_button.enabled, timeout=10_000)
    assert time.monotonic() - started >= REPORT_INTERVAL * 0.5
    assert widget.status.value.startswith("running")
    assert 0 < widget.progress.value < widget.progress.max
    gate.release.set()
    wait_idle(qtbot, widget)
    assert widget.params().window == 8 and "segments" in widget.status.value
    assert not widget.cancel_button.enabled


def test_activity_dock_only_for_runs_longer_than_the_delay(qtbot, monkeypatch):
    import napari.utils

    created = []

    class Counting(napari.utils.progress):
        def __init__(self, *args, **kwargs):
            created.append(self)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(napari.utils, "progress", Counting)
    results = []
    slot = WorkerSlot("test", activity_delay=0.3, report_interval=0.05)

    def quick():
        yield "one", 1, 1
        return "quick"

    slot.submit(quick, (), 1, lambda run_id, value: results.append(value))
    slot.wait(30)
    qtbot.wait(400)  # past the delay: nothing may appear for a run that has ended
    assert results == ["quick"] and created == []

    def slow():
        yield "one", 1, 2
        time.sleep(1.0)
        yield "two", 2, 2
        return "slow"

    slot.submit(slow, (), 2, lambda run_id, value: results.append(value))
    qtbot.waitUntil(lambda: slot.activity is not None, timeout=5_000)
    assert len(created) == 1 and slot.activity is created[0]
    slot.wait(30)
    assert results == ["quick", "slow"] and slot.activity is None

    # a live rerun (a changed value, a painted stroke) never appears there
    slot.submit(slow, (), 2, lambda run_id, value: results.append(value), live=True)
    slot.wait(30)
    assert results == ["quick", "slow", "slow"] and len(created) == 1


def test_result_then_idle_work_that_the_next_request_stops(qtbot):
    seen, idle_steps = [], []

    def with_idle_work(steps):
        yield "compute", 1, 1
        yield Result("value")
        for i in range(steps):
            time.sleep(0.05)
            idle_steps.append(i)
            yield "idle", 1, 1
        return "ignored"

    statuses = []
    slot = WorkerSlot("test", on_status=statuses.append, report_interval=0)
    slot.submit(with_idle_work, (100,), 1, lambda run_id, value: seen.append(value))
    qtbot.waitUntil(lambda: seen == ["value"], timeout=10_000)
    assert slot.busy  # still doing its idle work, without reports
    qtbot.waitUntil(lambda: len(idle_steps) >= 2, timeout=10_000)
    slot.submit(with_idle_work, (0,), 1, lambda run_id, value: seen.append(value))
    slot.wait(30)
    assert seen == ["value", "value"] and len(idle_steps) < 100  # stopped at a yield
    assert not any("idle" in s for s in statuses)
    assert _runner.ACTIVITY_DELAY > REPORT_INTERVAL


def test_next_cut_is_prefetched_after_a_result(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("camouflage")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)  # waits for the prefetch too: it runs in the same worker
    tree = widget.pipeline.get("cut")
    assert set(tree._candidates) == set(tree._ids)  # every segment's next cut is solved
    widget.set_params(n_segments=4)
    run_and_wait(qtbot, widget)
    want = engine_result(stack, widget.params())
    np.testing.assert_array_equal(widget.output("segments").data, want.labels + 1)
    assert widget.pipeline.calls["cut"] == 1  # the same tree, one split further


def test_progress_moves_within_the_harmonics_stage(
    viewer, open_sample, add_widget, qtbot, monkeypatch
):
    import napari_polarseg.engine.pipeline as pipeline_module
    from napari_polarseg.widgets._base import PROGRESS_STEPS

    original = pipeline_module.harmonics.block_coefficients

    def slow(*args, progress=None, **kwargs):
        # each chunk's report stays the newest for longer than the report interval, so
        # the throttled progress bar shows it
        def slowly(share):
            progress(share)
            time.sleep(2 * REPORT_INTERVAL)

        return original(*args, progress=None if progress is None else slowly, **kwargs)

    monkeypatch.setattr(pipeline_module.harmonics, "block_coefficients", slow)
    open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)  # 156 blocks: two chunks of the harmonic fit
    seen: list[tuple[int, int]] = []
    statuses: list[str] = []  # the status line at each move of the bar (set just before)

    def moved(value: int) -> None:
        seen.append((value, widget.progress.max))
        statuses.append(widget.status.value)

    widget.progress.changed.connect(moved)
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    stages = widget.pipeline.stages()
    i = stages.index("harmonics")
    inside = [v for v, top in seen if i * PROGRESS_STEPS < v < (i + 1) * PROGRESS_STEPS]
    assert inside, seen  # strictly between the stage boundaries
    assert all(top == len(stages) * PROGRESS_STEPS for _, top in seen if top)
    assert any(s.startswith("running: harmonics 50 %") for s in statuses), statuses
    assert widget.progress.value == widget.progress.max


class Waiting:
    """A toy method of three stages whose second waits for ``release`` (status and
    progress checked while it runs)."""

    name = "waiting"
    title = "waits in its second stage"
    reads = ("n_segments",)
    inputs: tuple[str, ...] = ()

    def __init__(self) -> None:
        import threading

        self.entered, self.release = threading.Event(), threading.Event()

    def stages(self, params):
        return ("first", "second", "third")

    def segment(self, scene, params, inputs, run):
        run.begin("first")
        run.begin("second")
        self.entered.set()
        while not self.release.wait(0.02):
            # half done, reported again and again; not checking for a stop request, as
            # a report from a stage that has not seen Cancel yet
            run.progress("second", run.index("second") + 0.5, run.total)
        run.begin("third")  # raises Cancelled after a stop request
        h, w = scene.shape
        return MethodOutput(np.zeros((h, w), dtype=np.int32))


@pytest.fixture
def waiting_method():
    method = register_method(Waiting())
    yield method
    method.release.set()
    unregister_method(Waiting.name)


def test_progress_counts_the_running_methods_own_stages(
    viewer, open_sample, add_widget, qtbot, waiting_method
):
    from napari_polarseg.widgets._base import PROGRESS_STEPS

    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)
    widget.method.value = waiting_method.name
    seen: list[tuple[int, int]] = []
    widget.progress.changed.connect(lambda value: seen.append((value, widget.progress.max)))
    widget.run_button.clicked.emit()
    qtbot.waitUntil(waiting_method.entered.is_set, timeout=60_000)
    # polarisation, normals and the method's three stages: the second one runs
    total = len(("polarisation", "normals", "first", "second", "third"))
    qtbot.waitUntil(lambda: "second" in widget.status.value, timeout=10_000)
    assert widget.status.value.startswith(f"running: second 50 % (3/{total})")
    waiting_method.release.set()
    wait_idle(qtbot, widget)
    assert error_messages() == []
    scene = widget.store.scene(source_key(stack))
    assert len(scene.stages(widget.params())) == total
    assert all(top == total * PROGRESS_STEPS for value, top in seen if value), seen
    values = [value for value, _ in seen]
    assert values == sorted(values) and values[-1] == total * PROGRESS_STEPS  # no jump back
    assert "1 segments" in widget.status.value


def test_cancel_feedback_is_not_overwritten_by_a_late_report(
    viewer, open_sample, add_widget, qtbot, waiting_method
):
    open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)
    widget.method.value = waiting_method.name
    statuses: list[str] = []  # every status the run's reports and Cancel set
    on_status = widget._slot.on_status

    def record(text: str) -> None:
        statuses.append(text)
        on_status(text)

    widget._slot.on_status = record
    widget.run_button.clicked.emit()
    qtbot.waitUntil(waiting_method.entered.is_set, timeout=60_000)
    qtbot.waitUntil(lambda: widget.status.value.startswith("running: second"), timeout=10_000)
    widget.cancel_button.clicked.emit()
    assert widget.status.value == "cancelling…"
    qtbot.wait(3 * int(REPORT_INTERVAL * 1000))  # the stage keeps reporting meanwhile
    waiting_method.release.set()
    wait_idle(qtbot, widget)
    assert widget.status.value == "cancelled"
    after = statuses[statuses.index("cancelling…") :]
    assert after == ["cancelling…", "cancelled"], after
    assert widget.output("segments") is None


def test_a_run_that_ends_after_cancel_stays_cancelled(qtbot):
    import threading

    entered, release = threading.Event(), threading.Event()
    results, statuses = [], []

    def late(report=None, cancel=None):
        yield "first", 0, 2
        entered.set()
        release.wait(10)
        report("first", 0.5, 2)  # a report from inside the stage, after Cancel
        return "value"

    slot = WorkerSlot("test", on_status=statuses.append, report_interval=0)
    on_result = lambda run_id, value: results.append(value)  # noqa: E731
    slot.submit(late, (), 2, on_result, cancellable=True, reports=True)
    qtbot.waitUntil(entered.is_set, timeout=5_000)
    qtbot.waitUntil(lambda: statuses[-1].startswith("running: first"), timeout=5_000)
    slot.cancel()
    assert statuses[-1] == "cancelling…"
    release.set()
    slot.wait(30)
    assert results == [] and statuses[-1] == "cancelled"
    assert not any(s.startswith("running") for s in statuses[statuses.index("cancelling…") :])
