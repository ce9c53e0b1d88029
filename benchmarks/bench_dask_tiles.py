"""The default method's tiles on a 2-worker Dask ``LocalCluster`` against the same tiles
in one process (issue 39, point 3): wall time, peak RSS of the client and of every
worker, and whether the labels are equal.

Inputs as ``benchmarks/bench_scale.py`` builds them (the real fruits frame tiled:
5 MP by default, 100 MP with ``--sizes 100``). Every run is its own subprocess
(``--child``) with the memory limit just below the whole image's estimate (or
``--max-memory``, whichever is smaller), so the image is tiled the same way in both
modes:

- ``single``: the tiles one after the other in the process;
- ``dask``: ``polarseg segment --dask local:2`` as the command line does it
  (:func:`napari_polarseg.batch.cluster.tiles_on_cluster`): 2 single-threaded worker
  processes with ``--worker-memory`` each (default 2 GiB); the cluster is started
  before the clock (its start is printed apart).

Peak RSS: the client's own ``ru_maxrss`` (the local cluster's scheduler runs in it),
each worker process's own (``client.run``), and ``os.wait4``'s figure for the child.

Usage::

    python benchmarks/bench_dask_tiles.py [--sizes 5] [--modes single,dask]
                                          [--max-memory 2G] [--worker-memory 2GiB]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_scale import SIZES, frame_input  # noqa: E402


def _worker_rss() -> float:
    """This process's peak RSS, GiB (run on every worker)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def child(size: str, mode: str, limit: int, worker_memory: str, labels_out: str) -> dict:
    """One run in this process: its figures as a dict."""
    from napari_polarseg.batch.cluster import tiles_on_cluster
    from napari_polarseg.engine import PRESETS, Scene
    from napari_polarseg.engine.limits import ENV_VAR, KEPT_MAPS
    from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
    from napari_polarseg.engine.unsupervised.tiled_regions import (
        WHOLE_BYTES_PER_PIXEL,
        region_tiles,
    )

    stack, angles = frame_input(SIZES[size])
    pixels = int(np.prod(stack.shape[1:]))
    cap = min(limit, pixels * (WHOLE_BYTES_PER_PIXEL + 8 * KEPT_MAPS) - 1)
    os.environ[ENV_VAR] = str(cap)
    grid = region_tiles(stack.shape[1:], SurfaceSuperpixels().params, cap)
    row: dict = {"size": size, "mode": mode, "shape": list(stack.shape), "limit_gib": cap / 2**30}
    row["tiles"] = None if grid is None else f"{len(grid)} of {grid.core} px, halo {grid.halo}"

    def segment() -> tuple[np.ndarray, float, int]:
        t0 = time.perf_counter()
        result = Scene(stack, angles).segment(PRESETS["auto"], maps=False, reconstruction=False)
        return result.labels, time.perf_counter() - t0, int(result.method_record.get("k", 0))

    if mode == "dask":
        t0 = time.perf_counter()
        with tiles_on_cluster("local:2", memory_limit=worker_memory) as cluster:
            row["cluster_start_s"] = time.perf_counter() - t0
            labels, row["wall_s"], row["k"] = segment()
            row["tasks"] = cluster.tile_map.tasks if cluster.tile_map else 0
            row["worker_rss_gib"] = sorted(cluster.client.run(_worker_rss).values())
    else:
        labels, row["wall_s"], row["k"] = segment()
    np.save(labels_out, labels)
    row["client_rss_gib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    row["us_per_pixel"] = 1e6 * row["wall_s"] / pixels
    return row


def run(size: str, mode: str, limit: int, worker_memory: str, labels_out: str) -> dict:
    """``child`` in a fresh subprocess (one thread for BLAS/OpenMP)."""
    cmd = [sys.executable, __file__, "--child", size, mode, str(limit), worker_memory, labels_out]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    out, err = proc.communicate()
    if proc.returncode != 0:
        return {"size": size, "mode": mode, "error": err.decode().strip().splitlines()[-1:]}
    return json.loads(out.decode().strip().splitlines()[-1])


def _line(r: dict) -> str:
    workers = " ".join(f"{v:.2f}" for v in r.get("worker_rss_gib", [])) or "-"
    start = f"{r['cluster_start_s']:.1f}" if "cluster_start_s" in r else "-"
    return (
        f"{r['size']:>5} {r['mode']:>6} {r['wall_s']:7.1f} {r['us_per_pixel']:6.2f} "
        f"{r['client_rss_gib']:10.2f} {workers:>11} {start:>7} {r['k']:>2}  "
        f"{r['tiles'] or '-'}" + (f", {r['tasks']} tasks" if "tasks" in r else "")
    )


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args and args[0] == "--child":
        size, mode, limit, worker_memory, out = args[1:6]
        print(json.dumps(child(size, mode, int(limit), worker_memory, out)))
        return 0
    from napari_polarseg.engine.limits import parse_bytes

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="5", help="megapixels: 1.25,5,24,100")
    ap.add_argument("--modes", default="single,dask")
    ap.add_argument("--max-memory", default="2G", help="the client's memory limit")
    ap.add_argument("--worker-memory", default="2GiB", help="each worker's memory limit")
    a = ap.parse_args(args)
    limit = parse_bytes(a.max_memory)
    tmp = Path(os.environ.get("TMPDIR", "/tmp"))
    print(
        f"{'MP':>5} {'mode':>6} {'wall s':>7} {'µs/px':>6} {'client GiB':>10} "
        f"{'worker GiB':>11} {'start s':>7} {'k':>2}  tiles"
    )
    for size in [s.strip() for s in a.sizes.split(",")]:
        paths = {}
        for mode in a.modes.split(","):
            path = str(tmp / f"bench_dask_tiles_{size}_{mode}.npy")
            r = run(size, mode, limit, a.worker_memory, path)
            if "error" in r:
                print(f"{size:>5} {mode:>6} failed: {r['error']}", flush=True)
                continue
            paths[mode] = path
            print(_line(r), flush=True)
        if len(paths) == 2:
            x, y = (np.load(p) for p in paths.values())
            print(f"{size:>5} labels equal: {bool(np.array_equal(x, y))}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
