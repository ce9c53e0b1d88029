"""``polarseg segment`` at the default, whole process, on real 1224 × 1024 frames.

Issue 22's target: at most 3 s from start to exit (reading the raw frame, the shared
polarisation image, the default method, writing the result folder; no thesis maps) on a
2-core machine, in a fresh process each time. Prints each run's seconds, the median per
frame and met/missed; also the same with ``--thesis-maps`` for comparison.

Usage: python benchmarks/bench_cli.py [--runs 3] [--folder ../shared/data/polanalyser]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FOLDER = Path(__file__).resolve().parents[2] / "shared/data/polanalyser"
TARGET_S = 3.0


def run_once(frame: Path, extra: list[str]) -> float:
    """Seconds of one ``polarseg segment`` process (python -m napari_polarseg.cli)."""
    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "napari_polarseg.cli", "segment", str(frame)]
        cmd += ["--out", out, "--quiet", *extra]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--folder", type=Path, default=FOLDER)
    args = parser.parse_args(argv)
    frames = sorted(args.folder.glob("*_IMX250MZR.png"))
    if not frames:
        print(f"skipped: no *_IMX250MZR.png frames in {args.folder}")
        return
    print(f"polarseg segment FRAME --out DIR, whole process, {args.runs} runs (median)")
    for label, extra in (("default", []), ("--thesis-maps", ["--thesis-maps"])):
        for frame in frames:
            seconds = [run_once(frame, extra) for _ in range(args.runs)]
            median = statistics.median(seconds)
            verdict = ""
            if not extra:
                verdict = "met" if median <= TARGET_S else f"MISSED (target {TARGET_S:g} s)"
            runs = " ".join(f"{s:.2f}" for s in seconds)
            print(f"{label:<14} {frame.name:<26} {median:6.2f} s  [{runs}]  {verdict}")


if __name__ == "__main__":
    main()
