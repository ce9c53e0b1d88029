"""Where the scenes of a batch run: in this process, or on a Dask cluster.

:class:`InlineRunner` runs the tasks one after the other here (``scheduler="inline"``);
:class:`DaskRunner` starts a local cluster (one single-threaded worker process per core)
or connects to a running scheduler, and keeps only as many scenes in flight as the
cluster has threads. Both yield ``(job, row or exception)`` as tasks complete.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import uuid
from collections.abc import Callable, Generator
from typing import Any

from ..engine.errors import Cancelled, PolarsegError
from ..io.read_options import ReadOptions
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
        import dask
        from distributed import Client, LocalCluster

        self.task = task
        self.cluster = None
        if address is None:
            config = {
                "distributed.scheduler.allowed-failures": allowed_failures,
            }
            with dask.config.set(config):
                self.cluster = LocalCluster(
                    n_workers=n_workers,
                    threads_per_worker=1,
                    processes=True,
                    memory_limit="auto" if memory_limit is None else memory_limit,
                    host="127.0.0.1",
                    dashboard_address=None,
                    silence_logs=logging.ERROR,
                )
            self.client = Client(self.cluster, timeout=timeout)
            self.label = f"local cluster ({n_workers} worker process(es), 1 thread each)"
        else:
            try:
                self.client = Client(address, timeout=timeout)
            except (OSError, TimeoutError, ValueError) as exc:
                raise PolarsegError(
                    f"cannot reach the Dask scheduler at {address} within {timeout:g} s "
                    f"({type(exc).__name__}: {exc})"
                ) from None
            self.label = f"scheduler {address}"
        try:
            self.client.wait_for_workers(1, timeout=timeout)
        except Exception as exc:
            self.close()
            raise PolarsegError(
                f"no Dask worker joined {self.label} within {timeout:g} s ({exc})"
            ) from None
        with contextlib.suppress(Exception):  # imports once per worker, before the clock
            self.client.run(_warm_up)
        workers = self.client.scheduler_info(n_workers=-1)["workers"]
        self.n_workers = len(workers)
        self.memory_limits = [float(w.get("memory_limit") or 0) for w in workers.values()]

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
        with contextlib.suppress(Exception):
            self.client.close(timeout=10)
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close(timeout=10)


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
