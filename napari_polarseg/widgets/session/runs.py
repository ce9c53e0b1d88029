"""What a worker job yields and how it is run: stages, :class:`Partial` and
:class:`Result`, errors kept visible, BLAS threads shared with the GUI thread.

No Qt here: :class:`~napari_polarseg.widgets._runner.WorkerSlot` (the Qt side) runs a
job through :func:`guarded` in a napari worker and tells these values apart.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from typing import Any

#: What a job yields between stages: ``(stage name, stages done, stages in all)``.
Stage = tuple[str, int, int]
#: A job: a generator function calling the engine, yielding :data:`Stage` tuples.
Job = Callable[..., Generator[Any, None, Any]]


@dataclass(frozen=True)
class Result:
    """The result of a job that goes on with idle-time work (e.g. precomputing).

    :class:`~napari_polarseg.widgets._runner.WorkerSlot` hands ``value`` to ``on_result`` at once,
    as if the job had
    returned it; the rest of the job reports nothing and the next request stops it at its
    next yield.
    """

    value: Any


@dataclass(frozen=True)
class Partial:
    """A result a job yields before it ends (e.g. the segments before the error map).

    :class:`~napari_polarseg.widgets._runner.WorkerSlot` hands ``value`` to the ``on_partial``
    callback of the run in the
    GUI thread, unless a newer run has been requested since.
    """

    value: Any


class StageFailed(Exception):
    """An unexpected error inside a worker (re-raised so the worker reports it).

    superqt's generator worker swallows ``RuntimeError`` raised by the generator (it
    takes it for a deleted Qt object); wrapping keeps such errors visible.
    """


#: Fewest cores on which workers leave one to the GUI thread (:class:`BlasShare`).
MIN_CORES_TO_SHARE = 3


class BlasShare:
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


blas_share = BlasShare()


def guarded(job: Job, *args: Any, **kwargs: Any) -> Generator[Stage, None, Any]:
    """Run ``job(*args, **kwargs)`` as a generator with BLAS threads limited
    (:class:`BlasShare`), turning a ``RuntimeError`` into :class:`StageFailed`."""
    with blas_share():
        try:
            result = yield from job(*args, **kwargs)
        except RuntimeError as exc:
            raise StageFailed(f"{type(exc).__name__}: {exc}") from exc
    return result


def relay(items: Iterator[Any], stage: Callable[[Any], Stage]) -> Generator[Stage, None, Any]:
    """Yield ``stage(item)`` for every item of the generator ``items`` and return what it
    returns: an engine iterator (a batch's rows, a sweep's cells) as a job's stages."""
    while True:
        try:
            item = next(items)
        except StopIteration as stop:
            return stop.value
        yield stage(item)
