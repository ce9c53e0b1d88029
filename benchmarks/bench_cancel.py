"""How fast Cancel stops a run, in every stage of every method (issue 22).

For each method on a real 1224 × 1024 polarisation-camera frame (``../shared/data/
polanalyser/camera_IMX250MZR.png``, layout 90,45,135,0; the thesis preset at window 4,
78,336 blocks, is the slowest case), one :class:`napari_polarseg.engine.Scene` is run
stage by stage: the run is cancelled ``--delay`` seconds after stage *s* starts (a timer
thread sets the stop flag), and the seconds from the flag to
:class:`~napari_polarseg.engine.errors.Cancelled` are printed with the stage's own
length. The stages before *s* stay cached, so the whole table costs about one run of
each method. Target: at most 1 s in every stage.

Usage: python benchmarks/bench_cancel.py [--delay 0.3] [--frame PATH] [--window 4]
"""

from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path

import numpy as np

from napari_polarseg import io as pio
from napari_polarseg.engine import PRESETS, Scene
from napari_polarseg.engine.errors import Cancelled
from napari_polarseg.engine.synthetic.scenes import scribble_strokes

FRAME = Path(__file__).resolve().parents[2] / "shared/data/polanalyser/camera_IMX250MZR.png"
TARGET_S = 1.0


def cancel_in(scene: Scene, params, inputs, stage: str, delay: float) -> tuple[float, str]:
    """(seconds from the stop flag to Cancelled, how the run ended) when the run is
    stopped ``delay`` s after ``stage`` starts."""
    flag = threading.Event()
    set_at: list[float] = []

    def stop() -> None:
        set_at.append(time.perf_counter())
        flag.set()

    def progress(name: str, index: float, total: int) -> None:
        if name == stage and index == int(index) and not set_at and not flag.is_set():
            timer = threading.Timer(delay, stop)
            timer.daemon = True
            timer.start()

    try:
        scene.segment(params, inputs, cancel=flag.is_set, progress=progress)
    except Cancelled:
        return time.perf_counter() - set_at[0], "cancelled"
    if set_at:
        return time.perf_counter() - set_at[0], "finished"
    return 0.0, "stage ended before the flag"


def stage_lengths(scene: Scene, params, inputs) -> dict[str, float]:
    """Seconds of each stage of one uncached run (a fresh scene of the same stack)."""
    fresh = Scene(pipeline=None, stack=scene.pipeline.stack, angles=scene.pipeline.angles)
    starts: dict[str, float] = {}
    fresh.segment(
        params, inputs, progress=lambda s, i, n: starts.setdefault(s, time.perf_counter())
    )
    names = list(starts)
    return {a: starts[b] - starts[a] for a, b in zip(names[:-1], names[1:], strict=True)}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--delay", type=float, default=0.3)
    parser.add_argument("--frame", type=Path, default=FRAME)
    parser.add_argument("--window", type=int, default=4)
    args = parser.parse_args(argv)
    if not args.frame.exists():
        print(f"skipped: {args.frame} is not there")
        return
    data = pio.read_stack(args.frame, mosaic=(90, 45, 135, 0))
    stack, angles = data.stack, data.angles_rad
    truth = np.zeros(stack.shape[1:], dtype=np.int32)
    truth[:, : truth.shape[1] // 2], truth[:, truth.shape[1] // 2 :] = 0, 1
    runs = [
        (f"thesis, window {args.window}", PRESETS["thesis"].replace(window=args.window), None),
        ("superpixels (auto)", PRESETS["auto"], None),
        ("pixel classifier", PRESETS["auto"], {"scribbles": scribble_strokes(truth)}),
    ]
    print(
        f"frame {args.frame.name} {stack.shape[2]} x {stack.shape[1]}, stop flag "
        f"{args.delay:g} s into the stage; target {TARGET_S:g} s"
    )
    print(f"{'method':<22} {'stage':<15} {'stage s':>8} {'to stop s':>10}  outcome")
    worst = 0.0
    for label, params, inputs in runs:
        t0 = time.perf_counter()
        lengths = stage_lengths(Scene(stack, angles), params, inputs)
        scene = Scene(stack, angles)
        for stage in scene.stages(params, inputs):
            seconds, outcome = cancel_in(scene, params, inputs, stage, args.delay)
            if outcome == "cancelled":
                worst = max(worst, seconds)
            length = lengths.get(stage, float("nan"))
            print(f"{label:<22} {stage:<15} {length:>8.2f} {seconds:>10.3f}  {outcome}")
        print(f"{label:<22} (whole table {time.perf_counter() - t0:.1f} s)")
    verdict = "met" if worst <= TARGET_S else "MISSED"
    print(f"slowest stop: {worst:.3f} s (target {TARGET_S:g} s): {verdict}")


if __name__ == "__main__":
    main()
