"""Where the scenes of a batch run: in this process, or on a Dask cluster.

:class:`InlineRunner` runs the tasks one after the other here (``scheduler="inline"``);
:class:`DaskRunner` starts a local cluster (one single-threaded worker process per core)
or connects to a running scheduler (:func:`~.cluster.open_cluster`, as ``polarseg segment
--dask`` does), and keeps only as many scenes in flight as the
cluster has threads. Both yield ``(job, row or exception)`` as tasks complete.
"""

from __future__ import annotations

import dataclasses
import uuid
from collections.abc import Callable, Generator
from typing import Any

from ..engine.errors import Cancelled
from ..io.read_options import ReadOptions
from .cluster import open_cluster
from .plan import MEMORY_SHARE


def memory_capped(read: ReadOptions, worker_limits: list[float]) -> ReadOptions:
    """``read`` with the memory limit of the smallest worker (share :data:`MEMORY_SHARE`,
    GiB to 3 decimals) unless it has its own."""
    if read.max_memory_gib is not None:
        return read
    limits = [v for v in worker_limits if v and v > 0]
    if not limits:
        return read
    gib = MEMORY_SHARE * min(limits) / 2**30
    return dataclasses.replace(read, max_memory_gib=float(f"{gib:.3f}"))


class InlineRunner:
    """Runs tasks in this process, one after the other (``scheduler="inline"``)."""

    def __init__(self, task: Callable[[dict[str, Any]], dict[str, Any]]) -> None:
        self.task = task

    def run(
        self, jobs: list[dict[str, Any]], cancel: Callable[[], bool]
    ) -> Generator[tuple[dict[str, Any], dict[str, Any] | BaseException], None, None]:
        for job in jobs:
            if cancel():
                return
            try:
                yield job, self.task(job)
            except Exception as exc:  # a task that raises: record it, go on
                yield job, exc


class DaskRunner:
    """Runs tasks on a Dask cluster: a new local one, or an existing scheduler."""

    def __init__(
        self,
        task: Callable[[dict[str, Any]], dict[str, Any]],
        address: str | None,
        n_workers: int,
        memory_limit: str | float | int | None,
        allowed_failures: int,
        timeout: float,
    ) -> None:
        self.task = task
        self.cluster = open_cluster(
            address, n_workers, memory_limit, allowed_failures, timeout, warm_up=_warm_up
        )
        self.client = self.cluster.client
        self.label = self.cluster.label
        self.memory_limits = self.cluster.memory_limits
        self.n_workers = len(self.memory_limits)

    def run(
        self, jobs: list[dict[str, Any]], cancel: Callable[[], bool]
    ) -> Generator[tuple[dict[str, Any], dict[str, Any] | BaseException], None, None]:
        from distributed import wait

        queue = list(jobs)
        futures: dict[Any, dict[str, Any]] = {}

        def refill() -> None:
            # as many scenes in flight as worker threads: each worker holds one scene at a
            # time (memory), and a worker that dies takes no queued scene down with it
            try:
                capacity = max(1, sum(self.client.nthreads().values()))
            except Exception:  # pragma: no cover - scheduler gone; wait() will tell
                capacity = 1
            while queue and len(futures) < capacity:
                job = queue.pop(0)
                key = f"polarseg-scene-{job['name']}-{uuid.uuid4().hex[:8]}"
                futures[self.client.submit(self.task, job, key=key, pure=False)] = job

        refill()
        try:
            while futures:
                if cancel():
                    return
                try:
                    done, _ = wait(list(futures), timeout=0.2, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    continue
                for fut in done:
                    job = futures.pop(fut)
                    if fut.status == "finished":
                        try:
                            value: dict[str, Any] | BaseException = fut.result()
                        except Exception as exc:  # pragma: no cover - lost result
                            value = exc
                    elif fut.status == "cancelled":
                        value = Cancelled("cancelled")
                    else:
                        value = fut.exception()
                    refill()
                    yield job, value
        finally:
            if futures:
                self.client.cancel(list(futures), force=True)

    def close(self) -> None:
        self.cluster.close()


def _warm_up() -> None:
    """Import what a scene needs (about a second), on each worker before the first scene."""
    from sklearn.decomposition import PCA  # noqa: F401

    from .. import jobs  # noqa: F401


def error_text(exc: BaseException) -> str:
    """One line naming what a task raised (a worker that died said so)."""
    name = type(exc).__name__
    text = " ".join(str(exc).split())
    if name == "KilledWorker":
        return f"KilledWorker: the worker process died while segmenting this scene ({text})"
    return f"{name}: {text}" if text else name
