"""The Dask options of ``polarseg segment``: run a large image's tiles on a cluster."""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Iterator
from typing import Any

from .arguments import PROG


def add_dask_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--dask SCHEDULER``, ``--workers N`` and ``--memory-limit SIZE`` (the local
    cluster's, as ``polarseg batch`` names them)."""
    group = parser.add_argument_group("Dask cluster (large images)")
    group.add_argument(
        "--dask",
        metavar="SCHEDULER",
        help="run the tiles of an image too large for the memory limit (--max-memory) on a "
        "Dask cluster: 'local' (a new local cluster of single-threaded worker processes), "
        "'local:N' (of N workers) or the address of a running dask.distributed scheduler "
        "(tcp://host:8786; its workers need napari-polarseg installed). An image that fits "
        "the limit runs whole in this process [no Dask: the tiles on this process's "
        "threads, one a core]",
    )
    group.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="with --dask local: worker processes of the local cluster [number of cores]",
    )
    group.add_argument(
        "--memory-limit",
        metavar="SIZE",
        default="auto",
        help="with --dask local: memory limit of each worker, e.g. 2GiB; the tiles are made "
        "small enough for 80%% of the smallest worker's [auto: the machine's memory shared "
        "out]",
    )


@contextlib.contextmanager
def dask_tiles(args: argparse.Namespace) -> Iterator[Any]:
    """The block's large images tiled on the cluster of ``--dask`` (None without it);
    a line on stderr names the cluster (unless --quiet) and, after, says when no tile
    ran on it."""
    from ..engine.errors import PolarsegError

    if not getattr(args, "dask", None):
        if getattr(args, "workers", None) is not None:
            raise PolarsegError("--workers applies to a local Dask cluster: give --dask local")
        yield None
        return
    if args.workers is not None and args.workers < 1:
        raise PolarsegError(f"--workers must be at least 1, got {args.workers}")
    from ..batch.cluster import tiles_on_cluster

    quiet = getattr(args, "quiet", False)
    with tiles_on_cluster(args.dask, args.workers, args.memory_limit) as cluster:
        if not quiet:
            print(f"{PROG}: large images' tiles on {cluster.label}", file=sys.stderr, flush=True)
        yield cluster
        if not quiet and cluster.tile_map is not None and cluster.tile_map.tasks == 0:
            print(
                f"{PROG}: the image fits the memory limit and ran whole in this process "
                "(a lower --max-memory tiles it)",
                file=sys.stderr,
                flush=True,
            )
