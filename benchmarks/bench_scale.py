"""Scale benchmark (issue 39): wall time, time a pixel and peak RSS of the default method
(preset ``auto``) and of the scribbles method at 1.25, 5 and 24 MP (100 MP with
``--huge``), whole image against tiled.

Inputs are built by tiling the real fruits frame (``../shared/data/polanalyser``, read
with its truth file's mosaic layout as ``robot_user.real_scenes`` reads the
hand-labelled frames: 4 × 1024 × 1224, uint8); the scribbles are one disc per material
at its deepest point in every copy (``robot_user.initial_scribbles``). Every run is a
subprocess of its own (``--child``), which builds its input, then times
``Scene(stack, angles).segment`` (no thesis maps):

- ``default``: ``PRESETS["auto"]`` (the polarisation fit, the object size estimate, the
  superpixels, node features, k chosen, clustering, merge and border refinement);
- ``scribbles``: the pixel classifier on the strokes (features, training, the
  prediction with the region walk).

Its peak RSS is the child's ``ru_maxrss`` as ``os.wait4`` reports it, its CPU seconds
(``cpu s``: user and system, every thread) from the same call, which depend less than
the wall time on what else the machine runs; the parent ends with ``RUSAGE_CHILDREN``,
the largest child's peak.

``whole``: the memory limit far above any estimate (no tiles). ``tiled``: the limit
``--max-memory`` (default 2 GiB) or, where the whole image would fit it, a limit just
below the whole image's estimate (the default) or half of it (scribbles), so that every
size is tiled; the tile grid computed from that limit is printed (the run's own grid,
from the limit less the stack, is a little smaller). Where both ran, the tiled labels
are compared with the whole image's (ARI, share of equal pixels). The 1.25 MP runs,
about a second each and the reference of the time a pixel, vary by up to 2 × from run to
run (docs/performance.md); each is run ``--repeats`` times (default 5), and its row and
the ratios read the run of median wall time (the range printed beside it). Targets: peak RSS ≤
2 GiB at 24 and 100 MP, time a pixel at 24 MP no worse than at 1.25 MP, 24 MP ≤ 20 s.
The 100 MP run on a Dask cluster: ``bench_dask_tiles.py``.

``--kernel-limit`` (Linux, as root): each child runs in a memory cgroup of its own
limited to ``--max-memory``, counting the page cache of the temporary files that hold a
large image's full-size arrays (``engine/disk_arrays.py``), with their pages left
mapped (``disk_arrays.RELEASE_PAGES = False``): whether the run finishes under a limit
the kernel enforces, and how often the kernel had to reclaim pages to keep it.

Usage::

    python benchmarks/bench_scale.py [--methods default,scribbles] [--sizes 1.25,5,24]
                                     [--modes whole,tiled] [--max-memory 2G] [--huge]
                                     [--repeats 5] [--kernel-limit]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: Megapixels of every size and the (rows, columns) copies of the 1024 × 1224 frame.
SIZES = {"1.25": (1, 1), "5": (2, 2), "24": (4, 5), "100": (8, 10)}
FRAME = "fruits"
DATA = HERE.parents[1] / "shared" / "data" / "polanalyser"
METHODS = ("default", "scribbles")


def frame_input(copies: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(stack (4, H, W), angles (rad)): the fruits frame tiled ``copies`` times (read
    without the robot user's imports, which would add to the default's peak RSS)."""
    from napari_polarseg import io as pio
    from napari_polarseg.truth import read_truth_file, truth_files

    truth = read_truth_file(next(p for p in truth_files() if FRAME in p.name))
    data = pio.read_stack(DATA / truth.frame, mosaic=list(truth.mosaic))
    return np.tile(data.stack, (1, *copies)), np.asarray(data.angles_rad)


def frame_strokes(copies: tuple[int, int]) -> np.ndarray:
    """(H, W) strokes: one disc per material at its deepest point in every copy."""
    from robot_user import disc_radius, initial_scribbles, real_scenes

    scene = next(s for s in real_scenes() if FRAME in s.name)
    strokes, _ = initial_scribbles(scene.truth, disc_radius(scene.truth.shape))
    return np.tile(strokes, copies)


def default_run(stack: np.ndarray, angles: np.ndarray, mode: str, limit: int) -> dict:
    """The default method at the mode's limit: labels, figures."""
    from napari_polarseg.engine import PRESETS, Scene
    from napari_polarseg.engine.limits import ENV_VAR, KEPT_MAPS
    from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
    from napari_polarseg.engine.unsupervised.tiled_regions import (
        WHOLE_BYTES_PER_PIXEL,
        region_tiles,
    )

    shape = stack.shape[1:]
    whole = int(np.prod(shape)) * (WHOLE_BYTES_PER_PIXEL + 8 * KEPT_MAPS)
    cap = 2**50 if mode == "whole" else min(limit, whole - 1)
    os.environ[ENV_VAR] = str(cap)
    grid = region_tiles(shape, SurfaceSuperpixels().params, cap)
    t0 = time.perf_counter()
    result = Scene(stack, angles).segment(PRESETS["auto"], maps=False, reconstruction=False)
    wall = time.perf_counter() - t0
    seconds = {k: round(v, 2) for k, v in result.timings.items()}
    return {"labels": result.labels, "wall_s": wall, "whole": whole, "cap": cap,
            "grid": grid, "seconds": seconds}  # fmt: skip


def scribbles_run(
    stack: np.ndarray, angles: np.ndarray, strokes: np.ndarray, mode: str, limit: int
) -> dict:
    """The scribbles method at the mode's limit: labels, figures."""
    from napari_polarseg.engine import Scene
    from napari_polarseg.engine.limits import ENV_VAR, estimate_scribble_bytes
    from napari_polarseg.engine.methods.pixel_classification import scribble_session
    from napari_polarseg.engine.params import SegmentParams

    whole = estimate_scribble_bytes(stack.shape[1:])
    cap = 2**50 if mode == "whole" else min(limit, whole // 2)
    os.environ[ENV_VAR] = str(cap)
    t0 = time.perf_counter()
    scene = Scene(stack, angles)
    scene.segment(SegmentParams(), {"scribbles": strokes}, maps=False, reconstruction=False)
    wall = time.perf_counter() - t0
    session = scribble_session(scene)
    grid = getattr(session.cached_features, "grid", None)
    seconds = {k: round(v, 2) for k, v in session.seconds.items()}
    return {"labels": session.prediction.labels, "wall_s": wall, "whole": whole, "cap": cap,
            "grid": grid, "seconds": seconds}  # fmt: skip


#: Environment variable telling a child to leave the disk arrays' pages mapped.
KEEP_PAGES = "POLARSEG_BENCH_KEEP_PAGES"
#: Memory cgroups (v1 controller, v2 hierarchy) a child of ``--kernel-limit`` runs in.
CGROUP_ROOTS = (
    Path("/sys/fs/cgroup/memory"),
    Path("/sys/fs/cgroup/unified"),
    Path("/sys/fs/cgroup"),
)


def memory_cgroup(limit: int) -> Path:
    """A new memory cgroup limited to ``limit`` bytes (page cache counted): v1's
    ``memory.limit_in_bytes`` or v2's ``memory.max``."""
    for root in CGROUP_ROOTS:
        controllers = root / "cgroup.controllers"
        if (root / "memory.limit_in_bytes").exists():
            name = "memory.limit_in_bytes"
        elif controllers.exists() and "memory" in controllers.read_text().split():
            (root / "cgroup.subtree_control").write_text("+memory")
            name = "memory.max"
        else:
            continue
        group = root / f"polarseg-bench-{os.getpid()}"
        group.mkdir(exist_ok=True)
        (group / name).write_text(str(int(limit)))
        return group
    raise SystemExit("--kernel-limit: no memory cgroup to make (Linux, as root)")


def cgroup_report(group: Path) -> str:
    """How often the kernel hit the group's limit and whether it killed the run."""
    if (group / "memory.failcnt").exists():  # v1
        oom = (group / "memory.oom_control").read_text().split()
        killed = oom[oom.index("oom_kill") + 1] if "oom_kill" in oom else "?"
        reached = (group / "memory.failcnt").read_text().strip()
        return f"limit reached {reached} times, oom kills {killed}"
    events = dict(line.split() for line in (group / "memory.events").read_text().splitlines())
    return f"limit reached {events.get('max', '?')} times, oom kills {events.get('oom_kill', '?')}"


def save_labels(path: str, labels: np.ndarray) -> None:
    """``np.save`` of ``labels`` as uint8, written a band of rows at a time with the
    pages of labels on disk given back after each: saving them for the comparison
    adds nothing to the run's peak RSS (a whole ``astype`` of 100 MP int32 labels in a
    temporary file made every page resident at once, 0.4 GiB)."""
    from napari_polarseg.engine import disk_arrays
    from napari_polarseg.engine.tiles import row_bands

    header = {"descr": "|u1", "fortran_order": False, "shape": labels.shape}
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, header)
        for band in row_bands(labels.shape[0], 512):
            f.write(np.ascontiguousarray(labels[band], dtype=np.uint8).tobytes())
            disk_arrays.release(labels)


def child(method: str, size: str, mode: str, limit: int, labels_out: str | None) -> dict:
    """One run (in this process): its figures as a dict."""
    if os.environ.get(KEEP_PAGES) == "1":
        from napari_polarseg.engine import disk_arrays

        disk_arrays.RELEASE_PAGES = False
    stack, angles = frame_input(SIZES[size])
    if method == "default":
        r = default_run(stack, angles, mode, limit)
    else:
        r = scribbles_run(stack, angles, frame_strokes(SIZES[size]), mode, limit)
    if labels_out:
        save_labels(labels_out, r["labels"])
    grid = r["grid"]
    return {
        "method": method,
        "size": size,
        "mode": mode,
        "wall_s": r["wall_s"],
        "us_per_pixel": 1e6 * r["wall_s"] / int(np.prod(stack.shape[1:])),
        "estimate_gib": r["whole"] / 2**30,
        "tiles": None if grid is None else f"{len(grid)} of {grid.core} px, halo {grid.halo}",
        "seconds": r["seconds"],
    }


def run(
    method: str, size: str, mode: str, limit: int, labels_out: str, group: Path | None = None
) -> dict:
    """``child`` in a fresh subprocess (one thread for BLAS/OpenMP), in the memory cgroup
    ``group`` with the disk arrays' pages left mapped when given; its peak RSS from
    ``os.wait4``."""
    cmd = [sys.executable, __file__, "--child", method, size, mode, str(limit), labels_out]
    env = {**os.environ, "OMP_NUM_THREADS": "1", **({KEEP_PAGES: "1"} if group else {})}

    def enter() -> None:  # in the child, before it runs Python
        if group is not None:
            (group / "cgroup.procs").write_text(str(os.getpid()))

    with tempfile.TemporaryFile() as err:  # a file: a full pipe would stall the child
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, env=env, preexec_fn=enter)
        out = proc.stdout.read()  # type: ignore[union-attr]
        _, status, usage = os.wait4(proc.pid, 0)  # the child's own peak, before it is reaped
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        text = err.read().decode()
    if proc.returncode != 0:
        cgroup = [cgroup_report(group)] if group is not None else []
        return {"size": size, "mode": mode, "error": text.strip().splitlines()[-1:] + cgroup}
    row = json.loads(out.decode().strip().splitlines()[-1])
    row["peak_rss_gib"] = usage.ru_maxrss / 2**20
    row["cpu_s"] = usage.ru_utime + usage.ru_stime
    if group is not None:
        row["seconds"] = (
            f"{row['seconds']}; in a {limit / 2**30:g} GiB cgroup: {cgroup_report(group)}"
        )
    return row


def median_run(rows: list[dict]) -> dict:
    """The row of median wall time of repeated runs (the first failure if any failed),
    its ``seconds`` led by every run's wall time when there were several."""
    failed = [r for r in rows if "error" in r]
    if failed:
        return failed[0]
    ordered = sorted(rows, key=lambda r: r["wall_s"])
    row = dict(ordered[(len(ordered) - 1) // 2])
    if len(rows) > 1:
        walls = ", ".join(f"{r['wall_s']:.2f}" for r in rows)
        row["seconds"] = f"median of {len(rows)} runs ({walls} s) {row['seconds']}"
    return row


def compare(paths: dict[str, str]) -> str:
    """ARI and share of equal pixels of the tiled labels against the whole image's."""
    from sklearn.metrics import adjusted_rand_score

    x, y = (np.load(paths[m]).ravel() for m in ("whole", "tiled"))
    return f"ARI {adjusted_rand_score(x, y):.4f}, {float(np.mean(x == y)):.4%} equal"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args and args[0] == "--child":
        method, size, mode, limit, out = args[1:6]
        print(json.dumps(child(method, size, mode, int(limit), out)))
        return 0
    from napari_polarseg.engine.limits import parse_bytes

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--sizes", default="1.25,5,24", help="megapixels: 1.25,5,24[,100]")
    ap.add_argument("--modes", default="whole,tiled")
    ap.add_argument("--max-memory", default="2G", help="the tiled runs' memory limit")
    ap.add_argument("--huge", action="store_true", help="also 100 MP (tiled only)")
    ap.add_argument(
        "--repeats",
        type=int,
        default=5,
        help="runs of each 1.25 MP child; the median's row is printed and read",
    )
    ap.add_argument(
        "--kernel-limit",
        action="store_true",
        help="run the tiled children in a memory cgroup of --max-memory, pages left mapped "
        "(Linux, as root)",
    )
    a = ap.parse_args(args)
    sizes = [s.strip() for s in a.sizes.split(",")] + (["100"] if a.huge else [])
    limit = parse_bytes(a.max_memory)
    tmp = Path(os.environ.get("TMPDIR", "/tmp"))
    print(f"{'method':>9} {'MP':>5} {'mode':>6} {'wall s':>7} {'µs/px':>6} {'peak GiB':>8} "
          f"{'est GiB':>7} {'cpu s':>6}  tiles")  # fmt: skip
    per: dict[tuple[str, str, str], float] = {}
    for method in a.methods.split(","):
        for size in sizes:
            paths = {}
            for mode in a.modes.split(","):
                if size == "100" and mode == "whole":
                    continue
                path = str(tmp / f"bench_scale_{method}_{size}_{mode}.npy")
                group = memory_cgroup(limit) if a.kernel_limit and mode == "tiled" else None
                try:
                    repeats = max(1, a.repeats) if size == "1.25" else 1
                    r = median_run(
                        [run(method, size, mode, limit, path, group) for _ in range(repeats)]
                    )
                finally:
                    if group is not None:
                        group.rmdir()
                if "error" in r:
                    print(f"{method:>9} {size:>5} {mode:>6} failed: {r['error']}", flush=True)
                    continue
                paths[mode] = path
                per[method, size, mode] = r["us_per_pixel"]
                print(
                    f"{method:>9} {size:>5} {mode:>6} {r['wall_s']:7.1f} "
                    f"{r['us_per_pixel']:6.2f} {r['peak_rss_gib']:8.2f} "
                    f"{r['estimate_gib']:7.2f} {r['cpu_s']:6.1f}  "
                    f"{r['tiles'] or '-'}  {r['seconds']}",
                    flush=True,
                )
            if len(paths) == 2:
                print(f"{method:>9} {size:>5} tiled vs whole: {compare(paths)}", flush=True)
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20
    print(f"largest child's peak RSS (RUSAGE_CHILDREN): {children:.2f} GiB")
    for (method, size, mode), value in per.items():
        # the reference is the 1.25 MP frame as a user runs it: whole (a tiled
        # 1.25 MP run, forced by a limit below its estimate, reads its halos 2-5 times)
        reference = next((r for r in ("whole", mode) if (method, "1.25", r) in per), None)
        if size != "1.25" and reference is not None:
            ratio = value / per[method, "1.25", reference]
            print(
                f"{method}: time a pixel, {size} MP {mode} / 1.25 MP {reference}: "
                f"{ratio:.2f} (target ≤ 1)"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
