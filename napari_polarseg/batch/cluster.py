"""The one way polarseg reaches a Dask cluster: a new local cluster, or a running
scheduler.

:func:`open_cluster` is used by the batch (:class:`~.runners.DaskRunner`: one scene a
task) and by ``polarseg segment --dask`` (:func:`tiles_on_cluster`: one tile of a large
image a task, :class:`~napari_polarseg.engine.tile_map.DaskTileMap`). A local cluster
runs single-threaded workers, each with a memory limit; a remote scheduler's workers
must have napari-polarseg installed (and, for a batch, see the inputs and the output
folder under the same paths).

``SCHEDULER`` on the command line (:func:`parse_scheduler`): ``local`` (a new local
cluster), ``local:N`` (of N workers), or an address (``tcp://host:8786``).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from ..engine.errors import PolarsegError
from ..engine.tile_map import DaskTileMap, tiles_on


@dataclass
class Cluster:
    """A Dask client and, when started here, its local cluster.

    Attributes
    ----------
    client : distributed.Client
    cluster : distributed.LocalCluster or None
        The local cluster started by :func:`open_cluster` (None: a remote scheduler).
    label : str
        What the cluster is, for messages.
    tile_map : DaskTileMap or None
        The tile map of :func:`tiles_on_cluster` (its ``tasks``: the tiles run).
    """

    client: Any
    cluster: Any
    label: str
    tile_map: DaskTileMap | None = None

    @property
    def memory_limits(self) -> list[float]:
        """Every worker's memory limit, bytes (0: none)."""
        workers = self.client.scheduler_info(n_workers=-1)["workers"]
        return [float(w.get("memory_limit") or 0) for w in workers.values()]

    @property
    def n_workers(self) -> int:
        return len(self.client.scheduler_info(n_workers=-1)["workers"])

    def close(self) -> None:
        """Close the client and the local cluster (errors ignored)."""
        with contextlib.suppress(Exception):
            self.client.close(timeout=10)
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close(timeout=10)


def _local_client(
    n_workers: int,
    memory_limit: str | float | int | None,
    allowed_failures: int,
    timeout: float,
    processes: bool,
) -> tuple[Any, Any, str]:
    """(client, cluster, label) of a new local cluster of single-threaded workers."""
    import dask
    from distributed import Client, LocalCluster

    config = {"distributed.scheduler.allowed-failures": allowed_failures}
    with dask.config.set(config):
        cluster = LocalCluster(
            n_workers=n_workers,
            threads_per_worker=1,
            processes=processes,
            memory_limit="auto" if memory_limit is None else memory_limit,
            host="127.0.0.1",
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
    kind = "worker process(es)" if processes else "worker thread(s)"
    return (
        Client(cluster, timeout=timeout),
        cluster,
        f"local cluster ({n_workers} {kind}, 1 thread each)",
    )


def open_cluster(
    address: str | None,
    n_workers: int,
    memory_limit: str | float | int | None = None,
    allowed_failures: int = 1,
    timeout: float = 30.0,
    processes: bool = True,
    warm_up: Callable[[], None] | None = None,
) -> Cluster:
    """A new local cluster of ``n_workers`` single-threaded workers (``address`` None;
    worker processes, or threads of this process without ``processes``), each with
    ``memory_limit`` (bytes or a size like ``"4GiB"``; ``"auto"``/None: the machine's
    memory shared out), or a client of the scheduler at ``address``; ready when a first
    worker has joined, ``warm_up`` then run on every worker.

    Raises
    ------
    PolarsegError
        If the scheduler cannot be reached or no worker joins within ``timeout`` s.
    """
    from distributed import Client

    if address is None:
        client, cluster, label = _local_client(
            n_workers, memory_limit, allowed_failures, timeout, processes
        )
    else:
        try:
            client, cluster, label = Client(address, timeout=timeout), None, f"scheduler {address}"
        except (OSError, TimeoutError, ValueError) as exc:
            raise PolarsegError(
                f"cannot reach the Dask scheduler at {address} within {timeout:g} s "
                f"({type(exc).__name__}: {exc})"
            ) from None
    found = Cluster(client, cluster, label)
    try:
        client.wait_for_workers(1, timeout=timeout)
    except Exception as exc:
        found.close()
        raise PolarsegError(f"no Dask worker joined {label} within {timeout:g} s ({exc})") from None
    if warm_up is not None:
        with contextlib.suppress(Exception):  # imports once per worker, before the clock
            client.run(warm_up)
    return found


def parse_scheduler(text: str) -> tuple[str | None, int | None]:
    """(address or None for a new local cluster, its workers or None) of a
    ``SCHEDULER``: ``local``, ``local:N`` or an address."""
    text = str(text).strip()
    head, _, count = text.partition(":")
    if head.lower() != "local":
        if not text:
            raise PolarsegError("the Dask scheduler is empty: give local, local:N or an address")
        return text, None
    if not count:
        return None, None
    if not count.isdigit() or int(count) < 1:
        raise PolarsegError(f"local:N needs a number of workers N ≥ 1, got {text!r}")
    return None, int(count)


def _warm_tiles() -> None:
    """Import what a tile needs, on each worker before the first tile."""
    from ..engine.unsupervised import tiled_labels, tiled_region_tasks  # noqa: F401


@contextlib.contextmanager
def tiles_on_cluster(
    scheduler: str,
    n_workers: int | None = None,
    memory_limit: str | float | int | None = None,
    timeout: float = 30.0,
    processes: bool = True,
) -> Iterator[Cluster]:
    """Run the tiles of every large image segmented inside the block on the Dask
    cluster ``scheduler`` (:func:`parse_scheduler`; a local one of ``n_workers``
    [cores] with ``memory_limit`` each), then close what was opened here."""
    import os

    address, count = parse_scheduler(scheduler)
    workers = count or n_workers or max(1, os.cpu_count() or 1)
    cluster = open_cluster(
        address, workers, memory_limit, timeout=timeout, processes=processes, warm_up=_warm_tiles
    )
    try:
        cluster.tile_map = DaskTileMap(cluster.client)
        with tiles_on(cluster.tile_map):
            yield cluster
    finally:
        cluster.close()
