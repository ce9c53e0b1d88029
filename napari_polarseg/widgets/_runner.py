"""Running engine work off the GUI thread: one worker at a time, newest request wins.

A widget hands :class:`WorkerSlot` a *job*: a generator function that calls the engine
and yields ``(stage, index, total)`` between stages (and, optionally, :class:`Partial`
results to show before the end). The slot runs it in a napari generator worker
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

:class:`PipelineStore` keeps one :class:`~napari_polarseg.engine.Pipeline` per
angle-stack layer so that a rerun only recomputes the stages a parameter change made
stale; a different mask (another region, an edited one, or none) builds a new one.

:func:`classifier_stages` is the scribble mode's job body: the pipeline's stages up to the
block features, the pixel feature stack (kept by a
:class:`~napari_polarseg.engine.analysis.pixel_segmentation.PixelSegmenter` per pipeline), then the
pixel classifier trained on the user's strokes (or a loaded one) instead of affinity and
cut, assembled into a :class:`~napari_polarseg.engine.SegmentationResult` like the cut's.
A job that accepts it gets a ``cancel`` callable (``WorkerSlot.submit(...,
cancellable=True)``) that turns True when a newer request or Cancel stops the run, so
the prediction stops between chunks instead of at the next stage boundary.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import threading
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from napari.qt.threading import GeneratorWorker, create_worker
from napari.utils.notifications import show_error
from qtpy.QtCore import QCoreApplication, QTimer

from ..engine import Pipeline, PolarsegError, SegmentationResult, SegmentParams, validity_mask
from ..engine.analysis.pixel_segmentation import PixelSegmenter
from ..engine.errors import Cancelled

if TYPE_CHECKING:
    from ..engine.analysis.pixel_classifier import PixelClassifier, PixelPrediction
    from ..engine.analysis.pixel_segmentation import PixelSegmentation

Stage = tuple[str, int, int]
Job = Callable[..., Generator[Any, None, Any]]

#: Seconds a run must last before it appears in napari's activity dock (a progress bar
#: there and an animated "in progress" spinner in the status bar). Interactive reruns end
#: sooner and show their stages only in the widget: the spinner repaints the window ~25
#: times a second, which on a software-rendered canvas (Mesa llvmpipe under Xvfb) takes
#: CPU from the engine's stages. Live reruns (a changed value, a painted stroke) never
#: appear there, however long they last: the spinner slowed a retraining of the pixel
#: classifier after a stroke as much (docs/performance.md, "Measurements behind the code").
ACTIVITY_DELAY = 1.0

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
class Result:
    """The result of a job that goes on with idle-time work (e.g. precomputing).

    :class:`WorkerSlot` hands ``value`` to ``on_result`` at once, as if the job had
    returned it; the rest of the job reports nothing and the next request stops it at its
    next yield.
    """

    value: Any


@dataclass(frozen=True)
class Partial:
    """A result a job yields before it ends (e.g. the segments before the error map).

    :class:`WorkerSlot` hands ``value`` to the ``on_partial`` callback of the run in the
    GUI thread, unless a newer run has been requested since.
    """

    value: Any


class StageFailed(Exception):
    """An unexpected error inside a worker (re-raised so the worker reports it).

    superqt's generator worker swallows ``RuntimeError`` raised by the generator (it
    takes it for a deleted Qt object); wrapping keeps such errors visible.
    """


#: Fewest cores on which workers leave one to the GUI thread (:class:`_BlasShare`).
MIN_CORES_TO_SHARE = 3


class _BlasShare:
    """Leave a core to the GUI thread while workers compute, on machines with 3+ cores.

    OpenBLAS threads spin while they wait for work; with as many of them as cores they
    compete with the GUI thread (and with Xvfb/Mesa) and froze the event loop while a
    progress spinner was animating. While at least one
    worker runs, BLAS pools are limited to ``cpu_count - 1`` threads; the original
    limits come back when the last worker ends. With 2 cores (or 1) nothing is limited:
    since runs no longer repaint the window while they compute (``REPORT_INTERVAL``,
    ``ACTIVITY_DELAY``), one BLAS thread only made the eigensolver's products slower and
    left the event loop's longest stall where it was (docs/performance.md, "Measurements
    behind the code"). Needs
    ``threadpoolctl`` (a scikit-learn dependency); without it nothing is changed.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._users = 0
        self._saved: Any = None

    @contextlib.contextmanager
    def __call__(self) -> Iterator[None]:
        with self._lock:
            self._users += 1
            if self._users == 1:
                self._saved = self._limit()
        try:
            yield
        finally:
            with self._lock:
                self._users -= 1
                if self._users == 0 and self._saved is not None:
                    with contextlib.suppress(Exception):
                        self._saved.restore_original_limits()
                    self._saved = None

    @staticmethod
    def _limit() -> Any:
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:  # pragma: no cover - scikit-learn brings it
            return None
        cores = os.cpu_count() or 2
        if cores < MIN_CORES_TO_SHARE:
            return None
        return threadpool_limits(limits=cores - 1, user_api="blas")


blas_share = _BlasShare()


def guarded(job: Job, *args: Any, **kwargs: Any) -> Generator[Stage, None, Any]:
    """Run ``job(*args, **kwargs)`` as a generator with BLAS threads limited
    (:class:`_BlasShare`), turning a ``RuntimeError`` into :class:`StageFailed`."""
    with blas_share():
        try:
            result = yield from job(*args, **kwargs)
        except RuntimeError as exc:
            raise StageFailed(f"{type(exc).__name__}: {exc}") from exc
    return result


def stage_text(stage: str, index: float, total: int) -> str:
    """The status line of a running job: ``"running: pca (4/8)"`` after a stage,
    ``"running: harmonics 40 % (2/8)"`` within one (a fractional ``index``)."""
    if not stage:
        return "running…"
    done = int(index)
    share = index - done
    within = f" {share:.0%}".replace("%", " %") if share > 0 else ""
    return f"running: {stage}{within} ({done}/{total})"


def error_message(exc: BaseException) -> str:
    """The one line shown to the user: the engine's message, or type and message."""
    if isinstance(exc, (PolarsegError, StageFailed)):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


def parse_angles(text: str) -> np.ndarray:
    """Polariser angles in degrees from ``"0, 45, 90, 135"`` (commas, semicolons or spaces).

    Raises :class:`PolarsegError` naming the bad entry.
    """
    parts = [p for p in re.split(r"[,;\s]+", text.strip()) if p]
    if not parts:
        raise PolarsegError(
            "give the polariser angles in degrees, one per frame (e.g. 0,45,90,135)"
        )
    out = []
    for p in parts:
        try:
            out.append(float(p))
        except ValueError:
            raise PolarsegError(f"angles must be numbers in degrees, got {p!r}") from None
    return np.asarray(out, dtype=float)


def format_angles(angles_deg: Any) -> str:
    """``[0.0, 45.0]`` -> ``"0, 45"``."""
    return ", ".join(f"{float(a):g}" for a in np.asarray(angles_deg, dtype=float).ravel())


def content_digest(array: Any) -> str | None:
    """A short fingerprint of an array's shape, dtype and values (None for None).

    Used to tell whether a mask or scribbles layer was edited since a run.
    """
    if array is None:
        return None
    a = np.ascontiguousarray(array)
    if a.dtype == bool:
        a = np.packbits(a)
    digest = hashlib.blake2b(a.tobytes(), digest_size=16).hexdigest()
    return f"{np.shape(array)}:{np.asarray(array).dtype}:{digest}"


# -- scribble mode ----------------------------------------------------------------------

#: Stages of the scribble mode: the pipeline's maps and block features (for the result's
#: plots and error map), the pixel features, the classifier (training and prediction, or
#: prediction only for a loaded classifier) and the reconstruction. The cut's own stages
#: (affinity, cut, labels) are neither computed nor invalidated.
PIPELINE_STAGES = ("polarisation", "normals", "harmonics", "pca")
CLASSIFIER_STAGES = (*PIPELINE_STAGES, "pixel features", "pixel classifier", "reconstruction")


def scribble_problem(scribbles: np.ndarray) -> str | None:
    """Why ``scribbles`` cannot train the classifier yet (None when they can).

    Checked in the GUI thread before a run: at least two distinct non-zero labels.
    """
    values = np.unique(np.asarray(scribbles))
    if values.size and values[0] < 0:
        return "scribble labels must be >= 0 (0 = unlabelled)"
    marked = values[values > 0]
    if marked.size >= 2:
        return None
    found = "none yet" if marked.size == 0 else f"only label {int(marked[0])}"
    return f"paint at least 2 materials (label 1 on one material, 2 on another, …); found {found}"


@dataclass
class ClassifierOutput:
    """What a scribble-mode job returns (or yields as a :class:`Partial`).

    ``segmentation`` is the engine's
    :class:`~napari_polarseg.engine.analysis.pixel_segmentation.PixelSegmentation`: its
    ``result.labels`` hold the class index 0..K-1, ``prediction.classes[k]`` is the
    scribble value (label) of class k, ``prediction.probabilities`` is (K, H, W) and
    sums to 1 over K, ``prediction.uncertainty`` is (H, W) in [0, 1]. ``trained`` is
    False when a loaded classifier was applied. When the strokes cannot train the
    classifier (e.g. every pixel of a material is masked) or the classifier does not
    fit the stack, ``problem`` says why and ``segmentation`` is None.
    """

    segmentation: PixelSegmentation | None
    trained: bool = True
    problem: str | None = None

    @property
    def result(self) -> SegmentationResult:
        assert self.segmentation is not None
        return self.segmentation.result

    @property
    def prediction(self) -> PixelPrediction:
        assert self.segmentation is not None
        return self.segmentation.prediction

    @property
    def classifier(self) -> PixelClassifier:
        assert self.segmentation is not None
        return self.segmentation.classifier


def classifier_stages(
    pipe: Pipeline,
    segmenter: PixelSegmenter,
    params: SegmentParams,
    scribbles: np.ndarray | None = None,
    classifier: PixelClassifier | None = None,
    reconstruction: bool = True,
    cancel: Callable[[], bool] | None = None,
) -> Generator[Any, None, ClassifierOutput]:
    """Run the stages the scribble mode needs (yielding after each), then classify.

    Trains the pixel classifier on ``scribbles``, or applies ``classifier`` (exactly one
    of them). ``len(CLASSIFIER_STAGES)`` stage yields (one fewer without the
    reconstruction). The pipeline's cached stages and ``segmenter``'s feature stack are
    reused: once they are computed, a new stroke reruns only training and prediction.
    When the reconstruction still has to be computed, the output without it is yielded
    as a :class:`Partial` first (the segments are shown while the error map is
    computed). ``cancel`` is handed to the prediction, which raises
    :class:`~napari_polarseg.engine.errors.Cancelled` between chunks when it returns
    True.
    """
    names = CLASSIFIER_STAGES if reconstruction else CLASSIFIER_STAGES[:-1]
    total = len(names)
    timings: dict[str, float] = {}
    recomputed: list[str] = []
    partial = reconstruction and not pipe.is_fresh("reconstruction", params)

    def run_stage(i: int, name: str) -> Stage:
        before = pipe.calls[name]
        t0 = time.perf_counter()
        pipe.get(name, params)
        if pipe.calls[name] != before:
            timings[name] = time.perf_counter() - t0
            recomputed.append(name)
        return name, i + 1, total

    for i, name in enumerate(PIPELINE_STAGES):
        yield run_stage(i, name)
    fparams = None if classifier is None else classifier.feature_params
    before = segmenter.cached_features
    t0 = time.perf_counter()
    segmenter.features(fparams, segment_params=params)
    if segmenter.cached_features is not before:
        timings["pixel features"] = time.perf_counter() - t0
        recomputed.append("pixel features")
    yield "pixel features", len(PIPELINE_STAGES) + 1, total
    try:
        seg = segmenter.segment(
            scribbles,
            classifier,
            feature_params=fparams,
            reconstruction=reconstruction and not partial,
            cancel=cancel,
            segment_params=params,
        )
    except PolarsegError as exc:
        return ClassifierOutput(None, classifier is None, problem=str(exc))
    timings["pixel classifier"] = seg.seconds.get("train", 0.0) + seg.seconds.get("predict", 0.0)
    recomputed.append("pixel classifier")

    def output(segmentation: PixelSegmentation, with_reconstruction: bool) -> ClassifierOutput:
        stages = names if with_reconstruction else names[:-1]
        result = replace(
            segmentation.result,
            params=params,
            timings={name: timings.get(name, 0.0) for name in stages},
            recomputed=[name for name in stages if name in recomputed],
        )
        return ClassifierOutput(replace(segmentation, result=result), classifier is None)

    yield "pixel classifier", len(PIPELINE_STAGES) + 2, total
    if not partial:
        return output(seg, reconstruction)
    yield Partial(output(seg, False))
    yield run_stage(total - 1, names[-1])
    result = segmenter.result(seg.prediction.labels, True, seg.seconds, params)
    return output(replace(seg, result=result), True)


@dataclass
class _Entry:
    data: Any
    angles: tuple[float, ...]
    mask_key: str | None
    region: np.ndarray | None
    pipeline: Pipeline
    segmenter: PixelSegmenter | None = None

    def matches(
        self, data: Any, angles: tuple[float, ...], mask_key: str | None, region: Any
    ) -> bool:
        if self.data is not data or self.angles != angles or self.mask_key != mask_key:
            return False
        if self.region is None or region is None:
            return self.region is None and region is None
        return self.region.shape == region.shape and bool(np.array_equal(self.region, region))


class PipelineStore:
    """One cached :class:`Pipeline` per angle-stack layer (keyed by the layer's id).

    The pipeline is rebuilt when the layer's data object, the angles or the mask (its
    ``mask_key`` or the content of its ``region``) change; otherwise the same object is
    reused so cached stages survive parameter changes. Beside each pipeline it keeps one
    :class:`~napari_polarseg.engine.analysis.pixel_segmentation.PixelSegmenter`
    (:meth:`segmenter`), so the scribble mode computes the pixel features once per
    stack and a new stroke only retrains and predicts. Safe to call from a worker thread
    (the slot runs one worker at a time; a lock guards the dict).
    """

    def __init__(self) -> None:
        self._entries: dict[str, _Entry] = {}
        self._lock = threading.Lock()

    def get(self, key: str) -> Pipeline | None:
        """The pipeline kept for ``key``, if any."""
        with self._lock:
            entry = self._entries.get(key)
        return None if entry is None else entry.pipeline

    def obtain(
        self,
        key: str,
        data: Any,
        angles_rad: np.ndarray,
        params: SegmentParams,
        region: np.ndarray | None = None,
        mask_key: str | None = None,
    ) -> Pipeline:
        """The pipeline for ``key`` (made with ``params``), built if missing or out of date.

        ``region`` (H, W) bool (True = use the pixel) or None restricts the segmentation;
        a new pipeline gets the mask :func:`~napari_polarseg.engine.validity_mask` builds
        from the stack (saturated samples at the integer dtype's maximum and black ones at
        or below 0 are left out and counted) and the region. ``mask_key`` names where the
        region came from (e.g. the Labels layer's id); a change of either rebuilds.
        """
        angles = tuple(float(a) for a in np.asarray(angles_rad, dtype=float).ravel())
        if region is not None:
            region = np.asarray(region, dtype=bool)
        with self._lock:
            entry = self._entries.get(key)
        if entry is None or not entry.matches(data, angles, mask_key, region):
            stack = np.asarray(data)
            mask = validity_mask(stack, saturation="auto", dark_level=0, region=region)
            pipeline = Pipeline(stack, np.asarray(angles), params, mask=mask)
            entry = _Entry(data, angles, mask_key, region, pipeline)
            with self._lock:
                self._entries[key] = entry
        return entry.pipeline

    def segmenter(self, key: str, colour_stack: np.ndarray | None = None) -> PixelSegmenter | None:
        """The pixel segmenter beside ``key``'s pipeline (made at the first call; None
        without a pipeline). A rebuilt pipeline, or another ``colour_stack`` (the colour
        stacks of a colour-polarisation frame, :class:`PixelSegmenter`), gets a new one."""
        with self._lock:
            entry = self._entries.get(key)
            if entry is None:
                return None
            if entry.segmenter is None or entry.segmenter.colour_stack is not colour_stack:
                entry.segmenter = PixelSegmenter(entry.pipeline, colour_stack=colour_stack)
            return entry.segmenter

    def discard(self, keep: set[str]) -> None:
        """Forget the pipelines of every key not in ``keep`` (layers that were removed)."""
        with self._lock:
            for key in set(self._entries) - keep:
                del self._entries[key]

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)


@dataclass(frozen=True)
class _Request:
    """What :meth:`WorkerSlot.submit` was asked to run (see there)."""

    job: Job
    args: tuple[Any, ...]
    total: int
    on_result: Callable[[int, Any], None]
    on_partial: Callable[[int, Any], None] | None
    live: bool
    cancellable: bool = False
    reports: bool = False


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
        self._quiet = False  # the running job has delivered its Result: idle work now
        self.run_id = 0
        self.worker: GeneratorWorker | None = None
        self._pending: Callable[[], None] | None = None
        self.last_error: str | None = None

    @property
    def busy(self) -> bool:
        """True while a worker runs or a request waits for it to end."""
        return self.worker is not None or self._pending is not None

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
        worker's thread, it is handled like a yielded stage (throttled the same way).
        """

        request = _Request(job, args, total, on_result, on_partial, live, cancellable, reports)

        def launch() -> None:
            self._launch(request)

        if self.worker is not None:
            self._pending = launch  # replaces any older queued request
            self.worker.quit()
            if not self._quiet:
                self.on_status("stopping the previous run…")
        else:
            launch()

    def cancel(self) -> None:
        """Drop a queued request and ask the running worker to stop after its stage."""
        self._pending = None
        if self.worker is not None:
            self.worker.quit()
            if not self._quiet:
                self.on_status("cancelling…")

    def _launch(self, request: _Request) -> None:
        job, args, total = request.job, request.args, request.total
        on_result, on_partial, live = request.on_result, request.on_partial, request.live
        self.run_id += 1
        run_id = self.run_id
        started: list[GeneratorWorker] = []  # the worker, once made: its stop request

        def stop() -> bool:
            return bool(started) and bool(started[0].abort_requested)

        def report_within(stage: str, index: float, total: int) -> None:
            # the worker's thread: its yielded signal is queued to the GUI thread
            if started:
                started[0].yielded.emit((stage, index, total))

        kwargs: dict[str, Any] = {"cancel": stop} if request.cancellable else {}
        if request.reports:
            kwargs["report"] = report_within
        worker = create_worker(
            guarded, job, *args, _start_thread=False, _ignore_errors=True, **kwargs
        )
        started.append(worker)

        # Handlers may be re-entered: updating napari's progress bar can process pending
        # events, so a later stage (or the result) can be handled before an earlier one
        # finishes. ``ended`` makes stage messages that arrive after the end harmless.
        ended = False
        delivered = False  # the job yielded its Result: what follows is quiet
        partial = False  # a Partial was shown: its status line stays until the result
        done = [0, ""]  # stages finished (a float within a stage), name of the stage
        last = [time.monotonic(), False]  # time of the last report, a report pending

        def report() -> None:
            last[:] = [time.monotonic(), False]
            if ended or delivered or run_id != self.run_id:
                return
            index, stage = done
            if not partial:
                self.on_status(stage_text(stage, index, total))
            self.on_progress(index, total)
            pbar = self.activity
            if pbar is not None and self.worker is worker:
                pbar.set_description(f"{self.desc}: {stage}")
                pbar.update(round(index * PROGRESS_STEPS) - pbar.n)

        def show_activity() -> None:
            if ended or delivered or self.worker is not worker or self.activity is not None:
                return
            from napari.utils import progress

            desc = f"{self.desc}: {done[1] or 'starting'}"
            self.activity = progress(total=total * PROGRESS_STEPS, desc=desc)
            self.activity.update(round(done[0] * PROGRESS_STEPS))

        def deliver(value: Any) -> None:
            if run_id == self.run_id and self._pending is None:
                self.on_progress(total, total)
                on_result(run_id, value)

        def yielded(value: Any) -> None:
            nonlocal delivered, partial
            if ended or delivered or run_id != self.run_id:
                return
            if isinstance(value, Result):
                delivered = True
                self._quiet = True
                self._close_activity()
                deliver(value.value)
                return
            if isinstance(value, Partial):
                if on_partial is not None and self._pending is None:
                    partial = True
                    on_partial(run_id, value.value)
                return
            stage, index, _ = value
            done[:] = [index, stage]
            wait = last[0] + self.report_interval - time.monotonic()
            if wait <= 0:
                report()
            elif not last[1]:
                last[1] = True
                QTimer.singleShot(round(wait * 1000), report)

        def returned(value: Any) -> None:
            nonlocal ended
            ended = True
            if not delivered:
                deliver(value)

        def errored(exc: BaseException) -> None:
            nonlocal ended
            if isinstance(exc, Cancelled):  # stopped inside a stage: as between stages
                aborted()
                return
            ended = True
            if run_id != self.run_id or self._pending is not None or delivered:
                return  # a newer run is queued (it reports its own problems), or idle work
            message = error_message(exc)
            self.last_error = message
            self.on_status(f"error: {message}")
            show_error(message)

        def aborted() -> None:
            nonlocal ended
            ended = True
            if run_id == self.run_id and self._pending is None and not delivered:
                self.on_status("cancelled")

        def finished() -> None:
            # close a generator stopped between stages now (not at garbage collection), so
            # its ``finally`` clauses (the BLAS limit) run at once
            with contextlib.suppress(Exception):
                gen = getattr(worker, "_gen", None)
                if gen is not None:
                    gen.close()
            if self.worker is worker:
                self.worker = None
                self._close_activity()
            if self._pending is not None and self.worker is None:
                pending, self._pending = self._pending, None
                pending()
            elif self.worker is None:
                self.on_idle()

        worker.yielded.connect(yielded)
        worker.returned.connect(returned)
        worker.errored.connect(errored)
        worker.aborted.connect(aborted)
        worker.finished.connect(finished)
        self.worker = worker
        self._quiet = False
        self.last_error = None
        if not live or self.report_interval <= 0:
            report()
        else:
            last[1] = True  # the first report: one interval after the start
            QTimer.singleShot(round(self.report_interval * 1000), report)
        if live:
            pass  # the widget's own progress bar and status line only
        elif self.activity_delay <= 0:
            show_activity()
        else:
            QTimer.singleShot(round(self.activity_delay * 1000), show_activity)
        worker.start()

    def _close_activity(self) -> None:
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
