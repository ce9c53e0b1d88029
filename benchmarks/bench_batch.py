"""Batch throughput: scenes per second on the synthetic set, 1 and 2 Dask workers.

::

    .venv/bin/python benchmarks/bench_batch.py              # 12 scenes of 120 x 130
    .venv/bin/python benchmarks/bench_batch.py --scenes 24 --shape 240x260 --workers 1,2,4

Writes the synthetic scenes (leaves, camouflage and fruit with different seeds) to a
temporary folder, then runs :func:`napari_polarseg.batch.run_batch` on them with
``RECOMMENDED`` parameters: inline (one process, no Dask: the baseline) and on a fresh
local cluster of N single-threaded worker processes. Prints one table row per run:
cluster start-up seconds, seconds to segment every scene (start-up excluded), scenes per
second, and the speed-up over one worker. Each worker imports the engine during start-up
(a warm-up task), so the first scene is not charged with it; the inline run is. Numbers
depend on the machine and on whatever else runs on it (the load average is printed).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from napari_polarseg import batch
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.engine.synthetic.scenes import SCENES, make_scene


def write_scenes(folder: Path, n: int, shape: tuple[int, int]) -> list[Path]:
    """``n`` synthetic scenes as .npz (stack, angles in degrees, labels)."""
    paths = []
    for i in range(n):
        name = SCENES[i % len(SCENES)]
        scene = make_scene(name, shape=shape, seed=i)
        path = folder / f"{i:03d}_{name}.npz"
        np.savez(path, stack=scene.stack, angles=scene.angles_deg, labels=scene.labels)
        paths.append(path)
    return paths


def run_once(paths: list[Path], out: Path, scheduler: str | None, workers: int | None) -> dict:
    """One batch; returns start-up and run seconds and the throughput."""
    t0 = time.perf_counter()
    ready: list[float] = []
    gen = batch.iter_batch(
        paths,
        out,
        RECOMMENDED,
        scheduler=scheduler,
        n_workers=workers,
        resume=False,
        on_start=lambda *_: ready.append(time.perf_counter()),
    )
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            result = stop.value
            break
    if not result.ok:
        failed = [r for r in result.records if r["status"] != "done"]
        raise SystemExit(f"scenes failed: {failed[:2]}")
    return {
        "startup": (ready[0] if ready else t0) - t0,
        "run": result.run_seconds,
        "rate": result.count("done") / result.run_seconds,
        "workers": result.n_workers,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=12, help="number of scenes [12]")
    parser.add_argument("--shape", default="120x130", help="scene size HxW [120x130]")
    parser.add_argument("--workers", default="1,2", help="local cluster sizes [1,2]")
    args = parser.parse_args(argv)
    shape = tuple(int(v) for v in args.shape.lower().split("x"))
    sizes = [int(v) for v in args.workers.split(",")]
    with tempfile.TemporaryDirectory(prefix="polarseg-bench-") as tmp:
        root = Path(tmp)
        (root / "in").mkdir()
        paths = write_scenes(root / "in", args.scenes, shape)  # type: ignore[arg-type]
        rows = [("inline (no Dask)", run_once(paths, root / "inline", "inline", None))]
        for n in sizes:
            rows.append((f"local cluster, {n} worker(s)", run_once(paths, root / f"w{n}", None, n)))
    base = next((r["rate"] for label, r in rows if r["workers"] == 1 and "cluster" in label), None)
    cores = os.cpu_count()
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"{args.scenes} scenes of {shape[0]} x {shape[1]} pixels, RECOMMENDED parameters")
    print(f"{cores} cores; load average after the runs {load} (other work skews the figures)")
    print()
    print("| run                        | start-up s | segment s | scenes/s | vs 1 worker |")
    print("|----------------------------|-----------:|----------:|---------:|------------:|")
    for label, r in rows:
        ratio = "" if base is None else f"{r['rate'] / base:.2f}x"
        print(
            f"| {label:<26} | {r['startup']:10.2f} | {r['run']:9.2f} | {r['rate']:8.2f} | "
            f"{ratio:>11} |"
        )


if __name__ == "__main__":
    main()
