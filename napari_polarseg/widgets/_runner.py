"""Running engine work off the GUI thread: one worker at a time, newest request wins.

A widget hands :class:`WorkerSlot` a *job*: a generator function that calls the engine
and yields ``(stage, index, total)`` between stages (and, optionally,
:class:`~napari_polarseg.widgets.session.Partial` results to show before the end). The
jobs, the values they yield and everything else that needs no Qt are the session layer,
:mod:`napari_polarseg.widgets.session`. The slot runs a job in a napari generator worker
(``napari.qt.threading.create_worker``), reports each stage to the widget (status line,
its own progress bar) and, for runs longer than :data:`ACTIVITY_DELAY`, in napari's
activity dock, and guarantees:

- at most one worker per slot; a request while one is running asks it to stop at its
  next stage boundary (``worker.quit()``) and runs the newest request when it has ended
  (older queued requests are dropped);
- every run gets a number; results of a run that is no longer the newest are dropped;
- a job submitted ``cancellable`` gets a ``cancel`` keyword argument, a callable that
  turns True once the run is asked to stop, to stop inside a long stage (the engine
  raises :class:`~napari_polarseg.engine.errors.Cancelled`, reported as a cancelled run);
- errors raised in the worker arrive in the GUI thread as a napari error notification
  carrying the engine's one-line message (never as an exception in the event loop).

Each run is a :class:`Run`: its worker and the handlers of the worker's signals.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from napari.qt.threading import GeneratorWorker, create_worker
from napari.utils.notifications import show_error
from qtpy.QtCore import QCoreApplication, QTimer

from ..engine.errors import Cancelled
from .session import Job, Partial, Result, error_message, guarded, stage_text

#: Seconds a run must last before it appears in napari's activity dock (a progress bar
#: there and an animated "in progress" spinner in the status bar). The widget's own
#: progress bar and status line show every run; the spinner repaints the window ~33
#: times a second, 16-30 ms each on a software-rendered canvas (Mesa llvmpipe under
#: Xvfb): two thirds of a core taken from the engine's stages. A first *Run* on a camera
#: frame (2-3 s) stays out of it; long runs (large images, batches) appear there. Live
#: reruns (a changed value, a painted stroke) never appear there, however long they
#: last: the spinner slowed a retraining of the pixel classifier after a stroke as much
#: (docs/performance.md, "Measurements behind the code").
ACTIVITY_DELAY = 5.0

#: Least seconds between two reports (status line, progress bars) of a running job; a
#: live rerun's first report comes one interval after its start, so a rerun that ends
#: sooner changes nothing in the window until its result is shown. Every report repaints
#: the window, which on a software-rendered canvas composes all of it again, with CPU
#: taken from the worker (docs/performance.md, "Measurements behind the code").
REPORT_INTERVAL = 0.25

#: Ticks per stage of the progress bars (the widget's and the activity dock's, which take
#: integers): the engine reports shares of its long stages.
PROGRESS_STEPS = 100


@dataclass(frozen=True)
class Request:
    """What :meth:`WorkerSlot.submit` was asked to run (see there)."""

    job: Job
    args: tuple[Any, ...]
    total: int
    on_result: Callable[[int, Any], None]
    on_partial: Callable[[int, Any], None] | None
    live: bool
    cancellable: bool = False
    reports: bool = False


class Run:
    """One run of a :class:`WorkerSlot`: its worker and the handlers of its signals.

    Handlers may be re-entered: updating napari's progress bar can process pending
    events, so a later stage (or the result) can be handled before an earlier one
    finishes. :attr:`ended` makes stage messages that arrive after the end harmless.
    """

    def __init__(self, slot: WorkerSlot, request: Request, run_id: int) -> None:
        self.slot = slot
        self.request = request
        self.run_id = run_id
        self.total = request.total
        self.worker: GeneratorWorker | None = None
        self.ended = False
        self.delivered = False  # the job yielded its Result: what follows is quiet
        self.partial = False  # a Partial was shown: its status line stays until the result
        self.silenced = False  # dropped without a word (WorkerSlot.drop)
        self.index: float = 0  # stages finished (a float within a stage)
        self.stage = ""  # name of the last stage reported by the job
        self.last_report = time.monotonic()  # time of the last report
        self.report_pending = False  # a report is scheduled

    # -- the worker -------------------------------------------------------------------
    def start(self) -> GeneratorWorker:
        """Make the worker, connect its signals, schedule the reports and start it."""
        request = self.request
        kwargs: dict[str, Any] = {"cancel": self.stop} if request.cancellable else {}
        if request.reports:
            kwargs["report"] = self.report_within
            if request.on_partial is not None:
                kwargs["partial"] = self.partial_within
        worker = create_worker(
            guarded, request.job, *request.args, _start_thread=False, _ignore_errors=True, **kwargs
        )
        self.worker = worker
        worker.yielded.connect(self.yielded)
        worker.returned.connect(self.returned)
        worker.errored.connect(self.errored)
        worker.aborted.connect(self.aborted)
        worker.finished.connect(self.finished)
        return worker

    def schedule_reports(self) -> None:
        """The first report (at once, or one interval later for a live rerun) and the
        entry in napari's activity dock (after ``activity_delay``; never when live)."""
        slot, live = self.slot, self.request.live
        if not live or slot.report_interval <= 0:
            self.report()
        else:
            self.report_pending = True  # the first report: one interval after the start
            QTimer.singleShot(round(slot.report_interval * 1000), self.report)
        if live:
            pass  # the widget's own progress bar and status line only
        elif slot.activity_delay <= 0:
            self.show_activity()
        else:
            QTimer.singleShot(round(slot.activity_delay * 1000), self.show_activity)

    def stop(self) -> bool:
        """True once the run is asked to stop (the ``cancel`` callable of the job): from
        then on nothing it reports reaches the status line, so Cancel's "cancelling…"
        and "cancelled" are never overwritten by a late stage report."""
        return self.worker is not None and bool(self.worker.abort_requested)

    def report_within(self, stage: str, index: float, total: int) -> None:
        """Progress within a stage (the ``report`` callable of the job)."""
        # the worker's thread: its yielded signal is queued to the GUI thread
        if self.worker is not None:
            self.worker.yielded.emit((stage, index, total))

    def partial_within(self, value: Any) -> None:
        """A result to show before the end, handed over from inside an engine call (the
        ``partial`` callable of the job): handled as a yielded :class:`Partial`."""
        if self.worker is not None:
            self.worker.yielded.emit(Partial(value))

    @property
    def current(self) -> bool:
        """True while this run is the slot's newest."""
        return self.run_id == self.slot.run_id

    @property
    def quiet(self) -> bool:
        """True once nothing more is to be reported (ended, idle work, or superseded)."""
        return self.ended or self.delivered or self.silenced or not self.current

    # -- reports ----------------------------------------------------------------------
    def report(self) -> None:
        """Show the last stage: status line, progress bars."""
        self.last_report, self.report_pending = time.monotonic(), False
        if self.quiet:
            return
        slot, index, stage = self.slot, self.index, self.stage
        if self.stop():
            return  # Cancel (or a newer request) said so in the status line
        if not self.partial:
            slot.on_status(stage_text(stage, index, self.total))
        slot.on_progress(index, self.total)
        pbar = slot.activity
        if pbar is not None and slot.worker is self.worker:
            pbar.set_description(f"{slot.desc}: {stage}")
            pbar.total = self.total * PROGRESS_STEPS
            pbar.update(round(index * PROGRESS_STEPS) - pbar.n)

    def show_activity(self) -> None:
        """Add the run to napari's activity dock (if it still runs)."""
        slot = self.slot
        if self.ended or self.delivered or slot.worker is not self.worker:
            return
        if slot.activity is not None:
            return
        from napari.utils import progress

        desc = f"{slot.desc}: {self.stage or 'starting'}"
        slot.activity = progress(total=self.total * PROGRESS_STEPS, desc=desc)
        slot.activity.update(round(self.index * PROGRESS_STEPS))

    def staged(self, stage: str, index: float, total: int | None = None) -> None:
        """A stage started (or a share of one is done): report it now or once the
        interval is up. ``total``: the job's count of its stages (it knows what runs),
        which replaces the one it was submitted with."""
        self.index, self.stage = index, stage
        if total:
            self.total = total
        wait = self.last_report + self.slot.report_interval - time.monotonic()
        if wait <= 0:
            self.report()
        elif not self.report_pending:
            self.report_pending = True
            QTimer.singleShot(round(wait * 1000), self.report)

    # -- the worker's signals ---------------------------------------------------------
    def deliver(self, value: Any) -> None:
        """Hand the result to the widget unless a newer request came."""
        if self.current and self.slot.pending is None and not self.silenced:
            if self.stop():  # Cancel came after the last stage: the run stays cancelled
                self.slot.on_status("cancelled")
                return
            self.slot.on_progress(self.total, self.total)
            self.request.on_result(self.run_id, value)

    def yielded(self, value: Any) -> None:
        """A stage, a :class:`Partial` or a :class:`Result` from the job."""
        if self.quiet:
            return
        slot = self.slot
        if isinstance(value, Result):
            self.delivered = True
            slot.quiet = True
            slot.close_activity()
            self.deliver(value.value)
        elif isinstance(value, Partial):
            on_partial = self.request.on_partial
            if on_partial is not None and slot.pending is None and not self.stop():
                self.partial = True
                on_partial(self.run_id, value.value)
        else:
            stage, index, total = value
            self.staged(stage, index, total)

    def returned(self, value: Any) -> None:
        self.ended = True
        if not self.delivered:
            self.deliver(value)

    def errored(self, exc: BaseException) -> None:
        if isinstance(exc, Cancelled):  # stopped inside a stage: as between stages
            self.aborted()
            return
        self.ended = True
        slot = self.slot
        if not self.current or slot.pending is not None or self.delivered or self.silenced:
            return  # a newer run is queued (it reports its own problems), or idle work
        message = error_message(exc)
        slot.last_error = message
        slot.on_status(f"error: {message}")
        show_error(message)

    def aborted(self) -> None:
        self.ended = True
        if self.current and self.slot.pending is None and not (self.delivered or self.silenced):
            self.slot.on_status("cancelled")

    def finished(self) -> None:
        if not self.ended and self.stop():
            # the job returned after a stop request: superqt then emits neither
            # ``returned`` nor ``aborted``; the run was cancelled all the same
            self.aborted()
        # close a generator stopped between stages now (not at garbage collection), so
        # its ``finally`` clauses (the BLAS limit) run at once
        with contextlib.suppress(Exception):
            gen = getattr(self.worker, "_gen", None)
            if gen is not None:
                gen.close()
        self.slot.ended(self)


class WorkerSlot:
    """Runs one job at a time in a napari worker; the newest request wins.

    Parameters
    ----------
    desc : str
        Description of the progress bar.
    on_status : callable(str), optional
        Receives short status texts ("running: harmonics", "cancelled", errors).
    on_idle : callable(), optional
        Called when the last worker has ended and nothing waits to run.
    on_progress : callable(index, total), optional
        Called with the stages done so far at each report of a running job (at its start,
        or for a live rerun :data:`REPORT_INTERVAL` later; then at most every interval)
        and with (total, total) when it has returned.
    activity_delay : float
        Seconds before a still-running job is shown in napari's activity dock
        (:data:`ACTIVITY_DELAY`); 0 shows every run there at once. A ``live`` job
        (:meth:`submit`) is never shown there.
    report_interval : float
        Least seconds between two stage reports (:data:`REPORT_INTERVAL`).
    """

    def __init__(
        self,
        desc: str,
        on_status: Callable[[str], None] | None = None,
        on_idle: Callable[[], None] | None = None,
        on_progress: Callable[[int, int], None] | None = None,
        activity_delay: float = ACTIVITY_DELAY,
        report_interval: float = REPORT_INTERVAL,
    ) -> None:
        self.desc = desc
        self.on_status = on_status or (lambda text: None)
        self.on_idle = on_idle or (lambda: None)
        self.on_progress = on_progress or (lambda index, total: None)
        self.activity_delay = activity_delay
        self.report_interval = report_interval
        #: napari progress bar of the running job, once it is shown in the activity dock
        self.activity: Any = None
        self.quiet = False  # the running job has delivered its Result: idle work now
        self.run_id = 0
        self.worker: GeneratorWorker | None = None
        #: the request waiting for the running worker to end (the newest one)
        self.pending: Request | None = None
        self.last_error: str | None = None
        self._runs: set[Run] = set()  # started and not finished: kept alive for Qt
        self._current: Run | None = None  # the newest run

    @property
    def busy(self) -> bool:
        """True while a worker runs or a request waits for it to end."""
        return self.worker is not None or self.pending is not None

    def submit(
        self,
        job: Job,
        args: tuple[Any, ...],
        total: int,
        on_result: Callable[[int, Any], None],
        on_partial: Callable[[int, Any], None] | None = None,
        live: bool = False,
        cancellable: bool = False,
        reports: bool = False,
    ) -> None:
        """Run ``job(*args)`` now, or as soon as the running worker has stopped.

        ``on_result(run_id, value)`` receives the job's result in the GUI thread: its
        return value, or the value of a :class:`Result` it yields (the job then goes on
        quietly: idle-time work that reports nothing and that the next request stops at
        its next yield). ``on_partial(run_id, value)`` receives the value of every
        :class:`Partial` it yields. Compare ``run_id`` with :attr:`run_id` to drop
        results of superseded runs. The run is reported at once ("running…", progress 0)
        unless it is ``live`` (a rerun after a parameter change or a stroke): that one
        reports only when still running :data:`REPORT_INTERVAL` later, and only to the
        widget (never in napari's activity dock, see :data:`ACTIVITY_DELAY`). A
        ``cancellable`` job is called as ``job(*args, cancel=stop)``: ``stop()`` is True
        once a newer request or :meth:`cancel` has asked the run to stop (the job may then
        raise :class:`~napari_polarseg.engine.errors.Cancelled`, which ends the run as if
        it had been stopped between stages). A job that ``reports`` is called with
        ``report=callable(stage, index, total)`` too, for progress *within* a stage
        (``index`` a float between the stage boundaries, e.g. 2.4 of 8 while the third
        stage is 40 % done; the engine's :meth:`Pipeline.run_iter
        <napari_polarseg.engine.Pipeline.run_iter>` ``progress``): called from the
        worker's thread, it is handled like a yielded stage (throttled the same way);
        given ``on_partial`` too, it is called with ``partial=callable(value)`` as well,
        for results the engine hands over while a stage runs (the pixel classifier's
        preview): handled like a yielded :class:`Partial`.
        """

        request = Request(job, args, total, on_result, on_partial, live, cancellable, reports)
        if self.worker is not None:
            self.pending = request  # replaces any older queued request
            self.worker.quit()
            if not self.quiet:
                self.on_status("stopping the previous run…")
        else:
            self._launch(request)

    def cancel(self) -> None:
        """Drop a queued request and ask the running worker to stop after its stage."""
        self.pending = None
        if self.worker is not None:
            self.worker.quit()
            if not self.quiet:
                self.on_status("cancelling…")

    def drop(self) -> None:
        """Stop the running job and drop a queued one without a word (the caller shows
        what is current): no "cancelled", no result."""
        self.pending = None
        run = self._current
        if self.worker is not None and run is not None and run.worker is self.worker:
            run.silenced = True
            self.worker.quit()

    def _launch(self, request: Request) -> None:
        """Start ``request`` in a new worker as the newest run."""
        self.run_id += 1
        run = Run(self, request, self.run_id)
        self._current = run
        worker = run.start()
        self._runs.add(run)
        self.worker = worker
        self.quiet = False
        self.last_error = None
        run.schedule_reports()
        worker.start()

    def ended(self, run: Run) -> None:
        """``run``'s worker has finished: start the queued request, or go idle."""
        self._runs.discard(run)
        if self.worker is run.worker:
            self.worker = None
            self.close_activity()
        if self.pending is not None and self.worker is None:
            pending, self.pending = self.pending, None
            self._launch(pending)
        elif self.worker is None:
            self.on_idle()

    def close_activity(self) -> None:
        """End the running job's entry in napari's activity dock, if it has one."""
        if self.activity is not None:
            with contextlib.suppress(Exception):
                self.activity.close()
            self.activity = None

    def wait(self, timeout: float | None = None, extra: Callable[[], bool] | None = None) -> bool:
        """Process Qt events until idle (and ``extra()`` is False); True if idle in time.

        For scripts and tests that drive the widgets without a user: the results are
        delivered through the Qt event loop, which this keeps turning.
        """
        app = QCoreApplication.instance()
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.busy or (extra is not None and extra()):
            if deadline is not None and time.monotonic() > deadline:
                return False
            if app is not None:
                app.processEvents()
            time.sleep(0.005)
        if app is not None:
            app.processEvents()
        return True
