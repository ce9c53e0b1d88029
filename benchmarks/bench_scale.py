"""Scale benchmark of the scribbles method (issue 39): wall time, time a pixel and
peak RSS at 1.25, 5 and 24 MP (100 MP with ``--huge``), whole image against tiled.

Inputs are built by tiling the real fruits frame (``../shared/data/polanalyser``,
read as ``benchmarks/materials.py`` reads the hand-labelled frames: 4 × 1024 × 1224)
and its hand-labelled truth; the strokes are one disc per material at its deepest
point in every copy of the frame (``robot_user.initial_scribbles``: "a few discs per
material"). Every run is its own subprocess (``--child``), which builds its input,
then times ``Scene.segment`` with the strokes (the polarisation fit, the features,
training and the prediction with the region walk; no thesis maps) and reports its
peak RSS (``resource.getrusage(RUSAGE_SELF).ru_maxrss`` at its end; the parent also
prints ``RUSAGE_CHILDREN``, the largest child's).

``whole``: the memory limit set far above the estimate (no tiles). ``tiled``: the
limit ``--max-memory`` (default 2 GiB) or, where the whole image would fit it, half
the whole-image estimate (``engine.limits.estimate_scribble_bytes``), so that the
image is tiled at every size; the tile grid is printed. The tiled labels are compared
with the whole image's (ARI) where both ran. Targets: peak RSS ≤ 2 GiB at 24 MP,
time a pixel at 24 MP no worse than at 1.25 MP, 24 MP ≤ 20 s.

Usage::

    python benchmarks/bench_scale.py [--sizes 1.25,5] [--modes whole,tiled]
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

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: Megapixels of every size and the (rows, columns) copies of the 1224 × 1024 frame.
SIZES = {"1.25": (1, 1), "5": (2, 2), "24": (4, 5), "100": (8, 10)}
FRAME = "fruits"


def frame_input(copies: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(stack (4, H, W), angles (rad), strokes (H, W)): the fruits frame tiled
    ``copies`` times, one disc per material at its deepest point in every copy."""
    from robot_user import disc_radius, initial_scribbles, real_scenes

    scene = next(s for s in real_scenes() if FRAME in s.name)
    strokes, _ = initial_scribbles(scene.truth, disc_radius(scene.truth.shape))
    stack = np.tile(scene.stack, (1, *copies))
    return stack, np.asarray(scene.angles_rad), np.tile(strokes, copies)


def child(size: str, mode: str, limit: int, labels_out: str | None) -> dict:
    """One run (in this process): the result's figures as a dict."""
    from napari_polarseg.engine import Scene
    from napari_polarseg.engine.limits import ENV_VAR, estimate_scribble_bytes
    from napari_polarseg.engine.methods.pixel_classification import scribble_session
    from napari_polarseg.engine.params import SegmentParams

    stack, angles, strokes = frame_input(SIZES[size])
    whole = estimate_scribble_bytes(stack.shape[1:])
    cap = 2**50 if mode == "whole" else min(limit, whole // 2)
    os.environ[ENV_VAR] = str(cap)
    t0 = time.perf_counter()
    scene = Scene(stack, angles)
    scene.segment(SegmentParams(), {"scribbles": strokes}, maps=False, reconstruction=False)
    wall = time.perf_counter() - t0
    session = scribble_session(scene)
    labels = session.prediction.labels
    if labels_out:
        np.save(labels_out, labels.astype(np.uint8))
    grid = getattr(session.cached_features, "grid", None)
    pixels = int(np.prod(stack.shape[1:]))
    return {
        "size": size,
        "mode": mode,
        "shape": list(stack.shape),
        "wall_s": wall,
        "us_per_pixel": 1e6 * wall / pixels,
        "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
        "estimate_gib": whole / 2**30,
        "limit_gib": cap / 2**30,
        "tiles": None if grid is None else f"{len(grid)} of {grid.core} px, halo {grid.halo}",
        "seconds": {k: round(v, 2) for k, v in session.seconds.items()},
    }


def run(size: str, mode: str, limit: int, labels_out: str) -> dict:
    """``child`` in a fresh subprocess (one thread for BLAS/OpenMP beyond the engine's)."""
    cmd = [sys.executable, __file__, "--child", size, mode, str(limit), labels_out]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        return {"size": size, "mode": mode, "error": out.stderr.strip().splitlines()[-1:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def parse_size(text: str) -> int:
    from napari_polarseg.engine.limits import parse_bytes

    return parse_bytes(text)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args and args[0] == "--child":
        size, mode, limit, out = args[1:5]
        print(json.dumps(child(size, mode, int(limit), out)))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="1.25,5,24", help="megapixels: 1.25,5,24[,100]")
    ap.add_argument("--modes", default="whole,tiled")
    ap.add_argument("--max-memory", default="2G", help="the tiled runs' memory limit")
    ap.add_argument("--huge", action="store_true", help="also 100 MP (tiled only)")
    a = ap.parse_args(args)
    sizes = [s.strip() for s in a.sizes.split(",")] + (["100"] if a.huge else [])
    limit = parse_size(a.max_memory)
    rows = []
    tmp = Path(os.environ.get("TMPDIR", "/tmp"))
    header = (
        f"{'MP':>5} {'mode':>6} {'wall s':>7} {'µs/px':>6} {'peak GiB':>8} {'est GiB':>7}  tiles"
    )
    print(header)
    for size in sizes:
        labels = {}
        for mode in a.modes.split(","):
            if size == "100" and mode == "whole":
                continue
            path = str(tmp / f"bench_scale_{size}_{mode}.npy")
            r = run(size, mode, limit, path)
            rows.append(r)
            if "error" in r:
                print(f"{size:>5} {mode:>6} failed: {r['error']}")
                continue
            labels[mode] = path
            print(
                f"{size:>5} {mode:>6} {r['wall_s']:7.1f} {r['us_per_pixel']:6.2f} "
                f"{r['peak_rss_gib']:8.2f} {r['estimate_gib']:7.2f}  {r['tiles'] or '-'} "
                f"{r['seconds']}",
                flush=True,
            )
        if len(labels) == 2:
            from sklearn.metrics import adjusted_rand_score

            x, y = (np.load(labels[m]).ravel() for m in ("whole", "tiled"))
            same = float(np.mean(x == y))
            print(
                f"{size:>5} tiled vs whole: ARI {adjusted_rand_score(x, y):.4f}, {same:.4%} equal"
            )
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20
    print(f"largest child's peak RSS (RUSAGE_CHILDREN): {children:.2f} GiB")
    ok = [r for r in rows if "error" not in r]
    per = {(r["size"], r["mode"]): r["us_per_pixel"] for r in ok}
    if ("1.25", "tiled") in per and ("24", "tiled") in per:
        ratio = per["24", "tiled"] / per["1.25", "tiled"]
        print(f"time a pixel, 24 MP / 1.25 MP (tiled): {ratio:.2f} (target ≤ 1)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
