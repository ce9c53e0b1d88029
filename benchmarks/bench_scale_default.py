"""Scale benchmark of the default method (preset ``auto``, issue 39): wall time, time a
pixel and peak RSS at 1.25, 5 and 24 MP (100 MP with ``--huge``), whole image against
tiled.

Inputs are built by tiling the real fruits frame (``../shared/data/polanalyser``, read
with its truth file's mosaic layout as ``benchmarks/baselines.py`` reads the
hand-labelled frames: 4 × 1024 × 1224, uint8). Every run is its own subprocess
(``--child``), which builds its input, then times ``Scene(stack, angles).segment``
with ``PRESETS["auto"]`` (the polarisation fit, the object size estimate, the
superpixels, node features, k chosen, clustering, merge and border refinement; no
thesis maps). Its peak RSS is the child's ``ru_maxrss`` as ``os.wait4`` reports it
(the child's own ``RUSAGE_SELF`` is printed beside it; the parent ends with
``RUSAGE_CHILDREN``, the largest child's).

``whole``: the memory limit far above any estimate (no tiles). ``tiled``: the limit
``--max-memory`` (default 2 GiB) or, where the whole image would fit it, a limit just
below the whole image's estimate (``engine.unsupervised.tiled_regions.region_tiles``),
so that every size is tiled; the tile grid is printed. Where both ran, the tiled labels
are compared with the whole image's (ARI, share of equal pixels). Targets: peak RSS ≤
2 GiB at 24 MP, time a pixel at 24 MP no worse than at 1.25 MP, 24 MP ≤ 20 s.

Usage::

    python benchmarks/bench_scale_default.py [--sizes 1.25,5,24] [--modes whole,tiled]
                                             [--max-memory 2G] [--huge]
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

#: Megapixels of every size and the (rows, columns) copies of the 1024 × 1224 frame.
SIZES = {"1.25": (1, 1), "5": (2, 2), "24": (4, 5), "100": (8, 10)}
FRAME = "fruits"
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "polanalyser"


def frame_input(copies: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(stack (4, H, W), angles (rad)): the fruits frame tiled ``copies`` times."""
    from napari_polarseg import io as pio
    from napari_polarseg.truth import read_truth_file, truth_files

    truth = read_truth_file(next(p for p in truth_files() if FRAME in p.name))
    data = pio.read_stack(DATA / truth.frame, mosaic=list(truth.mosaic))
    return np.tile(data.stack, (1, *copies)), np.asarray(data.angles_rad)


def child(size: str, mode: str, limit: int, labels_out: str | None) -> dict:
    """One run (in this process): its figures as a dict."""
    from napari_polarseg.engine import PRESETS, Scene
    from napari_polarseg.engine.limits import ENV_VAR, KEPT_MAPS
    from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
    from napari_polarseg.engine.unsupervised.tiled_regions import (
        WHOLE_BYTES_PER_PIXEL,
        region_tiles,
    )

    stack, angles = frame_input(SIZES[size])
    shape = stack.shape[1:]
    pixels = int(np.prod(shape))
    whole = pixels * (WHOLE_BYTES_PER_PIXEL + 8 * KEPT_MAPS)
    cap = 2**50 if mode == "whole" else min(limit, whole - 1)
    os.environ[ENV_VAR] = str(cap)
    grid = region_tiles(shape, SurfaceSuperpixels().params, cap)
    t0 = time.perf_counter()
    result = Scene(stack, angles).segment(PRESETS["auto"], maps=False, reconstruction=False)
    wall = time.perf_counter() - t0
    if labels_out:
        np.save(labels_out, result.labels.astype(np.uint8))
    return {
        "size": size,
        "mode": mode,
        "shape": list(stack.shape),
        "wall_s": wall,
        "us_per_pixel": 1e6 * wall / pixels,
        "self_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
        "estimate_gib": whole / 2**30,
        "limit_gib": cap / 2**30,
        "k": int(result.method_record.get("k", 0)),
        "tiles": None if grid is None else f"{len(grid)} of {grid.core} px, halo {grid.halo}",
        "seconds": {k: round(v, 2) for k, v in result.timings.items()},
    }


def run(size: str, mode: str, limit: int, labels_out: str) -> dict:
    """``child`` in a fresh subprocess (one thread for BLAS/OpenMP); its peak RSS from
    ``os.wait4``."""
    cmd = [sys.executable, __file__, "--child", size, mode, str(limit), labels_out]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    out, err = proc.stdout.read(), proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        return {"size": size, "mode": mode, "error": err.decode().strip().splitlines()[-1:]}
    row = json.loads(out.decode().strip().splitlines()[-1])
    row["peak_rss_gib"] = usage.ru_maxrss / 2**20
    return row


def compare(paths: dict[str, str]) -> str:
    """ARI and share of equal pixels of the tiled labels against the whole image's."""
    from sklearn.metrics import adjusted_rand_score

    x, y = (np.load(paths[m]).ravel() for m in ("whole", "tiled"))
    return f"ARI {adjusted_rand_score(x, y):.4f}, {float(np.mean(x == y)):.4%} equal"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args and args[0] == "--child":
        size, mode, limit, out = args[1:5]
        print(json.dumps(child(size, mode, int(limit), out)))
        return 0
    from napari_polarseg.engine.limits import parse_bytes

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="1.25,5,24", help="megapixels: 1.25,5,24[,100]")
    ap.add_argument("--modes", default="whole,tiled")
    ap.add_argument("--max-memory", default="2G", help="the tiled runs' memory limit")
    ap.add_argument("--huge", action="store_true", help="also 100 MP (tiled only)")
    a = ap.parse_args(args)
    sizes = [s.strip() for s in a.sizes.split(",")] + (["100"] if a.huge else [])
    limit = parse_bytes(a.max_memory)
    tmp = Path(os.environ.get("TMPDIR", "/tmp"))
    rows = []
    print(f"{'MP':>5} {'mode':>6} {'wall s':>7} {'µs/px':>6} {'peak GiB':>8} {'k':>2}  tiles")
    for size in sizes:
        paths = {}
        for mode in a.modes.split(","):
            if size == "100" and mode == "whole":
                continue
            path = str(tmp / f"bench_scale_default_{size}_{mode}.npy")
            r = run(size, mode, limit, path)
            rows.append(r)
            if "error" in r:
                print(f"{size:>5} {mode:>6} failed: {r['error']}", flush=True)
                continue
            paths[mode] = path
            print(
                f"{size:>5} {mode:>6} {r['wall_s']:7.1f} {r['us_per_pixel']:6.2f} "
                f"{r['peak_rss_gib']:8.2f} {r['k']:>2}  {r['tiles'] or '-'}  {r['seconds']}",
                flush=True,
            )
        if len(paths) == 2:
            print(f"{size:>5} tiled vs whole: {compare(paths)}", flush=True)
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20
    print(f"largest child's peak RSS (RUSAGE_CHILDREN): {children:.2f} GiB")
    per = {(r["size"], r["mode"]): r["us_per_pixel"] for r in rows if "error" not in r}
    for mode in ("whole", "tiled"):
        if ("1.25", mode) in per and ("24", mode) in per:
            ratio = per["24", mode] / per["1.25", mode]
            print(f"time a pixel, 24 MP / 1.25 MP ({mode}): {ratio:.2f} (target ≤ 1)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
