"""Chunked work on the CPU cores: row or point chunks of one array, one thread each.

The engine's heavy loops (harmonic evaluation, sinusoid fits, dense distances and
affinities, products with the graph) are cut into chunks of rows or points that each
worker writes into its own slice of a preallocated output; numpy and LAPACK release the
GIL in their loops, so the threads run in parallel.
"""

from __future__ import annotations

import contextvars
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

import numpy as np

#: Largest bytes of harmonic values one worker evaluates at once (bounds peak memory).
CHUNK_BYTES = 64 * 2**20
#: Worker threads for chunked work; numpy and LAPACK release the GIL in their loops.
N_THREADS = max(1, min(8, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1))
#: Below this many points chunked work stays in the calling thread.
MIN_PARALLEL_POINTS = 50_000

_local = threading.local()

T = TypeVar("T")

_controller: list = []  # the threadpoolctl controller, found once (see below)


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Limit BLAS/LAPACK to one thread (threadpoolctl, shipped with scikit-learn).

    Batched small matrix products and solves (100 × 169 per block) are 5–7 times *slower*
    with OpenBLAS's own two threads than with one; the engine parallelises over chunks of
    blocks instead. The libraries are looked up once: ``threadpool_limits`` scans every
    loaded shared object on each call (about 1–2 ms, paid by every chunked stage).
    """
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - a dependency of scikit-learn
        yield
        return
    if not _controller:
        _controller.append(ThreadpoolController())
    with _controller[0].limit(limits=1, user_api="blas"):
        yield


#: ``progress`` of the chunked functions: called with the share of the work done (0..1].
Progress = Callable[[float], None]


def run_chunks(
    bounds: list[tuple[int, int]],
    work: Callable[[int, int], None],
    n_points: int,
    progress: Progress | None = None,
) -> None:
    """Call ``work(start, stop)`` for every chunk, on :data:`N_THREADS` threads.

    ``work`` must write only to its own slice of preallocated outputs. Small jobs (fewer
    than :data:`MIN_PARALLEL_POINTS` points) run in the calling thread. ``progress`` is
    called in the calling thread with the share of the chunks done after each one (in
    chunk order), the last time with 1; an exception it raises (a stop request) stops
    the work after the chunks already running.
    """
    n = len(bounds)
    with single_threaded_blas():
        if N_THREADS == 1 or n < 2 or n_points < MIN_PARALLEL_POINTS:
            try:
                for i, (a, b) in enumerate(bounds):
                    work(a, b)
                    if progress is not None:
                        progress((i + 1) / n)
            finally:
                _local.__dict__.clear()  # scratch of the calling thread is not kept
            return
        with ThreadPoolExecutor(min(N_THREADS, n)) as pool:
            futures = [pool.submit(work, a, b) for a, b in bounds]
            try:
                for i, f in enumerate(futures):
                    f.result()
                    if progress is not None:
                        progress((i + 1) / n)
            except BaseException:
                # progress may stop the work (Cancel): drop the chunks not yet started, so
                # leaving the pool waits for the running ones only
                for f in futures:
                    f.cancel()
                raise


def chunk_bounds(n: int, step: int) -> list[tuple[int, int]]:
    """The chunks [(0, step), (step, 2 step), …, (…, n)] of ``range(n)``, the last one short."""
    return [(a, min(n, a + step)) for a in range(0, n, step)]


def scratch(name: str, shape: tuple[int, ...]) -> np.ndarray:
    """Per-thread scratch array, reused between chunks (no page faults per chunk)."""
    buf = getattr(_local, name, None)
    size = int(np.prod(shape))
    if buf is None or buf.size < size:
        buf = np.empty(size)
        setattr(_local, name, buf)
    return buf[:size].reshape(shape)


#: Seconds between two looks at the stop flag while :func:`call_stoppable` waits.
STOP_POLL_S = 0.02


def call_stoppable(work: Callable[[], T], check: Callable[[], None]) -> T:
    """``work()`` in a thread of its own, calling ``check()`` every :data:`STOP_POLL_S`
    seconds while it runs; when ``check`` raises (a stop asked for), the exception goes
    up at once and the work's result is dropped when it ends.

    For one long library call with no stop hook of its own that releases the GIL
    (scikit-image's watershed): the run stops within a poll instead of after the call.
    The abandoned call still finishes in the background (bounded by its own length).
    Written by hand: ``concurrent.futures`` has no way to leave a running call behind
    without waiting for it on shutdown.
    """
    return in_background(work)(check)


def in_background(work: Callable[[], T]) -> Callable[..., T]:
    """Start ``work()`` in a thread of its own (a daemon); the returned callable waits
    for it and gives its result (or raises its exception). Called with ``check``, it
    calls ``check()`` every :data:`STOP_POLL_S` seconds while it waits and once after
    (``check`` may raise to stop waiting: :func:`call_stoppable`).

    For numpy work that releases the GIL and is needed later in the same run (the
    second core works while the first draws the superpixels). Written by hand: a
    one-off thread with a result, without an executor to shut down. ``work`` runs in a
    copy of the caller's context (its context variables: the memory limit that places
    the full-size arrays, :func:`~.disk_arrays.full_size_limit`).
    """
    box: dict[str, Any] = {}
    context = contextvars.copy_context()

    def target() -> None:
        try:
            box["value"] = context.run(work)
        except BaseException as exc:  # handed to the caller of the result
            box["error"] = exc

    thread = threading.Thread(target=target, name="polarseg-background", daemon=True)
    thread.start()

    def result(check: Callable[[], None] | None = None) -> T:
        if check is None:
            thread.join()
        while thread.is_alive():
            check()  # type: ignore[misc]
            thread.join(STOP_POLL_S)
        if check is not None:
            check()
        if "error" in box:
            raise box["error"]
        return box["value"]

    return result
