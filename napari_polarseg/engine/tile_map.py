"""Where the tiles of a large image are worked on: in this process, or on a Dask cluster.

The tiled loops (:mod:`.unsupervised.tiled_regions`, :mod:`.unsupervised.tiled_labels`,
:mod:`.classifier.tiled_prediction`) hand every tile's work to the current *tile map*:
a callable ``(task, payloads)`` that calls ``task(*payload)`` for every payload and
yields the results **in the order of the payloads**. A payload holds only its tile's
arrays (the outer box, with its halo) and a few small values; a result holds only what
the whole image's step needs of the tile (sums per region, border pairs, the core's
labels or class probabilities). So:

- :func:`in_process` runs the tasks one after the other here, as a plain loop would;
- :class:`ThreadTileMap` (the default on a machine of more than one core,
  :data:`~.chunks.N_THREADS`) runs them here on that many threads, at most one tile a
  thread in flight: the filters, the forest and numpy release the GIL, so the tiles'
  work runs on every core, as many tiles at once as the memory limit holds
  (:attr:`~.tiles.TileGrid.at_once`, :func:`tile_map_for`);
- :class:`DaskTileMap` runs them on a ``dask.distributed`` cluster through its client:
  each payload's arrays are scattered to one worker and the task submitted there, with
  at most ``window`` tiles in flight (the client holds no more payloads than that and a
  worker no more than its share); the results are gathered in order, so every sum is
  added in the same order as in this process and the labels are the same to the bit;
- the global steps (node features, clustering, choosing k) stay on the client.

The map is a setting of this module (:func:`tiles_on`), not an argument of the methods:
``polarseg segment --dask`` sets it around the run, every thread of the run reads it
(:func:`current_tile_map`). The engine never imports Dask: the client is used through
its ``scatter``, ``submit`` and ``scheduler_info`` methods only.
"""

from __future__ import annotations

import contextlib
import contextvars
import itertools
import threading
import uuid
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, Protocol, TypeVar

import numpy as np

from . import disk_arrays
from .chunks import N_THREADS
from .errors import PolarsegError
from .tiles import TileGrid

R = TypeVar("R")

#: Arrays smaller than this (bytes) travel inside the task; larger ones are scattered.
SCATTER_BYTES = 1 << 20
#: Share of a worker's memory limit one tile may use (the batch's share too).
WORKER_SHARE = 0.8


class TileMap(Protocol):
    """Calls ``task(*payload)`` for every payload, yielding the results in order."""

    def __call__(self, task: Callable[..., R], payloads: Iterable[tuple]) -> Iterator[R]: ...


def in_process(task: Callable[..., R], payloads: Iterable[tuple]) -> Iterator[R]:
    """The tile map of this process: the tasks one after the other, lazily (one payload
    at a time is made)."""
    for payload in payloads:
        yield task(*payload)


def in_order(
    payloads: Iterator[tuple],
    window: int,
    submit: Callable[[tuple], Any],
    result: Callable[[Any], R],
    drop: Callable[[list[Any]], None],
) -> Generator[R, None, None]:
    """The results of the submitted payloads in their order, with at most ``window``
    of them in flight: ``submit(payload)`` starts one (a handle), ``result(handle)``
    waits for it, and one more payload is submitted as each result is taken;
    ``drop(handles)`` is called with the handles left in flight when the consumer stops
    or a task fails."""
    flight: deque[Any] = deque()
    try:
        for payload in itertools.islice(payloads, window):
            flight.append(submit(payload))
        while flight:
            value = result(flight.popleft())
            for payload in itertools.islice(payloads, 1):
                flight.append(submit(payload))
            yield value
    finally:
        if flight:
            drop(list(flight))


class ThreadTileMap:
    """A tile map of this process on ``threads`` threads (module docstring): at most
    ``threads`` tiles in flight, each task run in a copy of the caller's context (so it
    sees the run's memory limit), the results yielded in the order of the payloads, so
    every sum is added in the same order as by :func:`in_process` and the results are
    the same to the bit."""

    def __init__(self, threads: int) -> None:
        self.threads = max(1, int(threads))

    def __call__(self, task: Callable[..., R], payloads: Iterable[tuple]) -> Iterator[R]:
        return self._results(task, iter(payloads))

    def _results(
        self, task: Callable[..., R], payloads: Iterator[tuple]
    ) -> Generator[R, None, None]:
        with ThreadPoolExecutor(self.threads, thread_name_prefix="polarseg-tile") as pool:

            def submit(payload: tuple) -> Future[R]:
                context = contextvars.copy_context()
                return pool.submit(context.run, task, *payload)

            def drop(flight: list[Future[R]]) -> None:  # not started yet: not run
                for future in flight:
                    future.cancel()

            yield from in_order(payloads, self.threads, submit, Future.result, drop)


class DaskTileMap:
    """A tile map on a ``dask.distributed`` cluster (module docstring).

    Parameters
    ----------
    client : distributed.Client
        The cluster's client (a local cluster's or a remote scheduler's).
    window : int, optional
        Tiles in flight at once [twice the cluster's threads]: the client holds at most
        that many payloads and results.
    """

    def __init__(self, client: Any, window: int | None = None) -> None:
        self.client = client
        info = client.scheduler_info(n_workers=-1)["workers"]
        self.workers = sorted(info)
        self.threads = max(1, sum(int(w.get("nthreads", 1)) for w in info.values()))
        self.window = max(1, int(window or 2 * self.threads))
        limits = [float(w.get("memory_limit") or 0) for w in info.values()]
        limits = [v for v in limits if v > 0]
        #: The largest memory (bytes) one tile's work may take on a worker: the share
        #: :data:`WORKER_SHARE` of the smallest worker limit (None: no limit).
        self.worker_bytes = WORKER_SHARE * min(limits) if limits else None
        self._turn = itertools.count()
        #: Tasks submitted so far.
        self.tasks = 0

    def _submit(self, task: Callable[..., Any], payload: tuple) -> tuple[Any, list[Any]]:
        """The future of ``task(*payload)`` on the next worker (round robin), its large
        arrays scattered there first; and the futures of those arrays."""
        worker = [self.workers[next(self._turn) % len(self.workers)]] if self.workers else None
        large = [i for i, a in enumerate(payload) if _nbytes(a) > SCATTER_BYTES]
        args = list(payload)
        held: list[Any] = []
        if large:
            arrays = [payload[i] for i in large]
            try:
                held = self.client.scatter(arrays, workers=worker, hash=False)
            except Exception:  # that worker gone: wherever the scheduler puts them
                held = self.client.scatter(arrays, hash=False)
            for i, future in zip(large, held, strict=True):
                args[i] = future
        self.tasks += 1
        key = f"polarseg-tile-{getattr(task, '__name__', 'task')}-{uuid.uuid4().hex}"
        future = self.client.submit(
            task, *args, key=key, pure=False, workers=worker, allow_other_workers=True
        )
        return future, held

    def __call__(self, task: Callable[..., R], payloads: Iterable[tuple]) -> Iterator[R]:
        return self._results(task, iter(payloads))

    def _results(
        self, task: Callable[..., R], payloads: Iterator[tuple]
    ) -> Generator[R, None, None]:
        # a result taken drops its future and its scattered arrays: the worker frees them
        def drop(flight: list[tuple[Any, list[Any]]]) -> None:
            with contextlib.suppress(Exception):
                self.client.cancel([f for f, _ in flight], force=True)

        def submit(payload: tuple) -> tuple[Any, list[Any]]:
            return self._submit(task, payload)

        yield from in_order(payloads, self.window, submit, lambda item: _result(item[0]), drop)


def _result(future: Any) -> Any:
    """The future's result; a worker that died (``KilledWorker``: out of memory, killed)
    as a :class:`~.errors.PolarsegError` that says so."""
    try:
        return future.result()
    except Exception as exc:
        if type(exc).__name__ != "KilledWorker":
            raise
        raise PolarsegError(
            f"a Dask worker died while working on a tile of the image ({exc}); give the "
            "workers more memory (--memory-limit) or use a lower --max-memory"
        ) from None


def _nbytes(value: Any) -> int:
    """Bytes of the arrays in ``value`` (an array, or a tuple or list of them)."""
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, (tuple, list)):
        return sum(_nbytes(v) for v in value)
    return 0


_lock = threading.Lock()
_current: list[TileMap | None] = [None]


#: The tile map of a run that sets none: :data:`~.chunks.N_THREADS` threads of this
#: process (:func:`in_process` on one core).
DEFAULT_MAP: TileMap = ThreadTileMap(N_THREADS) if N_THREADS > 1 else in_process


def current_tile_map() -> TileMap:
    """The tile map set by :func:`tiles_on`, else :data:`DEFAULT_MAP`."""
    return _current[0] or DEFAULT_MAP


def boxes_at_once(
    cap: float, pixels: int, full_size: float, box: float, on_disk: float = 0.0
) -> int:
    """How many outer boxes of ``box`` bytes the memory limit ``cap`` holds at once
    beside a run's ``full_size`` bytes of full-size arrays, which count as ``on_disk``
    bytes a pixel (what stays in memory beside them) where they go to temporary files
    (:func:`~.disk_arrays.on_disk_at`: their pages are given back as they are
    written); at least 1 (:attr:`~.tiles.TileGrid.at_once`). It never changes the tiles
    themselves, so the labels are the same however many run at once
    (:func:`tile_map_for`)."""
    resident = pixels * on_disk if disk_arrays.on_disk_at(pixels, int(cap)) else full_size
    return max(1, int((cap - resident) // box))


def tile_map_for(grid: TileGrid) -> TileMap:
    """The current tile map for the tiles of ``grid`` (a :class:`~.tiles.TileGrid`):
    this process's threads narrowed to ``grid.at_once`` tiles at once when it sets
    fewer (one: :func:`in_process`); any other map as it is."""
    current = current_tile_map()
    if isinstance(current, ThreadTileMap) and 0 < grid.at_once < current.threads:
        return in_process if grid.at_once == 1 else ThreadTileMap(grid.at_once)
    return current


def in_this_process(tile_map: TileMap) -> bool:
    """Whether ``tile_map`` runs its tasks in this process (a stop callback may be
    handed to them)."""
    return tile_map is in_process or isinstance(tile_map, ThreadTileMap)


def worker_bytes() -> float | None:
    """The memory (bytes) one tile may take on the current map's workers (None: this
    process's limit holds)."""
    return getattr(_current[0], "worker_bytes", None)


@contextlib.contextmanager
def tiles_on(tile_map: TileMap | None) -> Iterator[TileMap]:
    """Run the tiles of every tiled loop started inside the block with ``tile_map``
    (None: in this process); the previous map is restored after."""
    with _lock:
        previous, _current[0] = _current[0], tile_map
    try:
        yield current_tile_map()
    finally:
        with _lock:
            _current[0] = previous
