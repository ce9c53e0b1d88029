"""``polarseg sweep``: segment one stack over a grid of w, L and n (the thesis method's
block grid) or, with ``--vary``, of the chosen method's own parameters
(:mod:`.method_sweep`), score every cell and write the sweep folder
(:mod:`napari_polarseg.outputs.sweep_folder`)."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__, jobs
from .. import io as pio
from ..engine.errors import PolarsegError
from ..engine.params import ParamSpec
from ..engine.physics.pixel_mask import PixelMask
from ..engine.registered import computes_block_maps
from ..status_line import StatusLine
from .arguments import PROG, number_list_arg
from .method_sweep import run_param_sweep, vary_arg
from .options import (
    STACK_INPUT_HELP,
    add_input_options,
    add_inputs_and_out,
    add_param_options,
    add_plots_option,
)
from .running import (
    max_bytes,
    params_from_args,
    read_input,
    read_options,
    segment_data,
    status_line,
)


def add_parser(sub: Any, specs: dict[str, ParamSpec] | None = None) -> None:
    """Add the ``sweep`` subcommand to ``sub`` (flags of ``specs``, default the table)."""
    from ..engine.analysis.sweep_result import DEFAULT_SCORE, SCORES

    sw = sub.add_parser(
        "sweep",
        help="segment one stack over a grid of window sizes, degrees and refractive "
        "indices, or of the chosen method's own parameters (--vary)",
        description="Run the segmentation for every window size w, harmonic degree L and "
        "refractive index n of a grid (one cached pipeline), score every cell without "
        "ground truth (stability: mean adjusted Rand index with the neighbouring w and L "
        "cells; silhouette of the blocks in the whitened PCA space; mean Ncut value of the "
        "cuts; a combined score) and, with a ground truth, by its adjusted Rand index. "
        "Writes sweep.csv, sweep.json, sweep_heatmap.png and best_params.json (give it to "
        "'polarseg segment --params') into --out; --apply-best also segments with the best "
        "parameters into OUT/best/. The window/degree grid is the thesis method's; "
        "--vary NAME=V,V,... sweeps the chosen method's own parameters instead.",
    )
    add_inputs_and_out(sw, STACK_INPUT_HELP)
    sw.add_argument(
        "--windows",
        type=number_list_arg(int, "window sizes in pixels"),
        default=(8, 10, 12),
        metavar="W,W,...",
        help="window sizes w in pixels [8,10,12]",
    )
    sw.add_argument(
        "--degrees",
        type=number_list_arg(int, "harmonic degrees"),
        default=(4, 8, 12),
        metavar="L,L,...",
        help="harmonic degrees L [4,8,12]",
    )
    sw.add_argument(
        "--refractive-indices",
        type=number_list_arg(float, "refractive indices"),
        metavar="N,N,...",
        help="refractive indices n [the parameters' n]",
    )
    sw.add_argument(
        "--ground-truth",
        metavar="FILE",
        help="true materials (labels image, the outputs' size): adds the adjusted Rand "
        "index of every cell [the input's own labels, e.g. a bundled sample's]",
    )
    sw.add_argument(
        "--score",
        choices=SCORES,
        default=DEFAULT_SCORE,
        help="what picks the best cell: stability, the combined label-free score, "
        "silhouette, the smallest mean Ncut, or the adjusted Rand index against the ground "
        f"truth [{DEFAULT_SCORE}]",
    )
    sw.add_argument(
        "--apply-best",
        action="store_true",
        help="also segment with the best parameters into OUT/best/ (as 'polarseg segment')",
    )
    sw.add_argument(
        "--vary",
        action="append",
        type=vary_arg,
        metavar="NAME=V,V,...",
        help="sweep the chosen method's own parameters instead (repeat for more axes): "
        "NAME is a parameter of --method (its group below) or a shared one it reads "
        "(e.g. n_segments); every combination is scored by its stability and, with a "
        "ground truth, its adjusted Rand index; writes sweep.csv, sweep.json and "
        "best_params.json",
    )
    add_input_options(sw, "stack")
    add_plots_option(sw)
    add_param_options(sw, preset="recommended", specs=specs)
    sw.set_defaults(func=run)


def _fmt(value: Any, digits: int = 3) -> str:
    """A table entry: ``-`` for None or not finite, floats with ``digits`` decimals."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def sweep_table(result: Any, best: Any = None) -> list[str]:
    """Lines of the short table ``polarseg sweep`` prints (best cell marked ``*``)."""
    cols = ["n", "w", "L", "segs", "stability", "silhouette", "ncut", "score"]
    if result.has_ground_truth:
        cols.append("ARI")
    cols.append("s")
    lines = ["  " + " ".join(f"{c:>10}" for c in cols)]
    for c in result.cells:
        mark = "*" if c is best else " "
        if not c.ok:
            head = [f"{c.refractive_index:g}", str(c.window), str(c.degree)]
            lines.append(f"{mark} " + " ".join(f"{v:>10}" for v in head) + f"  error: {c.error}")
            continue
        values = [
            f"{c.refractive_index:g}",
            str(c.window),
            str(c.degree),
            str(c.n_segments),
            _fmt(c.stability),
            _fmt(c.silhouette),
            _fmt(c.mean_ncut),
            _fmt(c.score),
        ]
        if result.has_ground_truth:
            values.append(_fmt(c.ari))
        values.append(_fmt(c.seconds, 2))
        lines.append(f"{mark} " + " ".join(f"{v:>10}" for v in values))
    return lines


@dataclass
class SweptStack:
    """The stack a sweep runs on, read, masked and (with --register) aligned."""

    data: pio.StackData
    read_seconds: float
    stack: np.ndarray
    mask: PixelMask
    shifts: np.ndarray | None
    truth: np.ndarray | None
    truth_from: str | None


def _read_scene(args: argparse.Namespace, status: StatusLine) -> SweptStack:
    """Read INPUT and its ground truth, make the pixel mask, register if asked."""
    status.show(f"reading {Path(args.input[0]).name}")
    t0 = time.perf_counter()
    data = read_input(args.input[0] if len(args.input) == 1 else args.input, args)
    read_seconds = time.perf_counter() - t0
    shape = data.stack.shape[1:]
    truth, truth_from = None, None
    if args.ground_truth:
        truth = pio.read_labels(args.ground_truth, shape, "ground truth")
        truth_from = str(Path(args.ground_truth).resolve())
    elif data.ground_truth is not None:
        truth, truth_from = np.asarray(data.ground_truth), "input"
    if args.score == "ari" and truth is None:
        raise PolarsegError("--score ari needs --ground-truth (or an input with its labels)")
    mask = jobs.pixel_mask(data, read_options(args))
    stack, shifts = data.stack, None
    if args.register:
        from ..engine.physics.registration import register_stack  # scipy.signal: slow import

        status.show("registering the frames")
        stack, shifts = register_stack(stack)
        mask = mask.shifted(shifts)
    return SweptStack(data, read_seconds, stack, mask, shifts, truth, truth_from)


def _cell_progress(
    args: argparse.Namespace, status: StatusLine
) -> Callable[[int, int], None] | None:
    """The sweep's progress callback: a line per cell with --verbose, else the status line
    with the time left (None when neither is shown)."""
    started = status.elapsed()

    def progress(done: int, total: int) -> None:
        if args.verbose:
            print(f"{PROG}: sweep cell {done}/{total}", file=sys.stderr, flush=True)
            return
        left = (status.elapsed() - started) / done * (total - done)
        status.show(f"sweep: {done}/{total} cells done, about {left:.0f} s left")

    return progress if args.verbose or status.enabled else None


def _summary(scene: SweptStack, result: Any) -> dict[str, Any]:
    """The content of ``sweep.json``."""
    return {
        "polarseg_version": __version__,
        "command": "sweep",
        "input": str(Path(scene.data.source).resolve()),
        "stack_shape": list(scene.stack.shape),
        "angles_deg": scene.data.angles_deg.tolist(),
        "registration_shifts_px": None if scene.shifts is None else scene.shifts.tolist(),
        "ground_truth": scene.truth_from,
        "read_seconds": round(scene.read_seconds, 6),
        **result.to_dict(),
    }


def _report(result: Any, best_cell: Any, best: Any, n_failed: int, out: Path) -> None:
    """Print the table, the best cell (``best``: its parameters) and what was written."""
    for line in sweep_table(result, best_cell):
        print(line)
    extra = "" if not result.has_ground_truth else f", ARI {best_cell.ari:.3f}"
    print(
        f"{PROG}: best by {result.score}: w = {best.window}, L = {best.degree}, "
        f"n = {best.refractive_index:g} ({best_cell.n_segments} segments{extra})"
    )
    print(
        f"{PROG}: {len(result.cells)} cells ({n_failed} failed) in "
        f"{result.total_seconds:.2f} s; wrote sweep.csv, sweep.json, sweep_heatmap.png, "
        f"best_params.json to {out}"
    )
    print(f"{PROG}: to use it: {PROG} segment INPUT --params {out / 'best_params.json'} --out DIR")


def run(args: argparse.Namespace) -> int:
    """Run ``polarseg sweep``; return the exit code (0)."""
    from ..engine.analysis.param_sweep import sweepable
    from ..engine.analysis.sweep import sweep
    from ..outputs.sweep_folder import write_sweep_folder

    params = params_from_args(args, maps=False)
    for flag, value in (("--plots", args.plots), ("--overview", args.overview)):
        if value and not args.apply_best:
            raise PolarsegError(f"{flag} draws the best cell's segmentation: give --apply-best")
    if not args.vary and not computes_block_maps(params.method):
        raise PolarsegError(
            f"the window/degree grid is the thesis method's; to sweep method {params.method}, "
            "give --vary NAME=V,V,... (its parameters: " + ", ".join(sweepable(params)) + ")"
        )
    status = status_line(args)
    scene = _read_scene(args, status)
    if args.vary:
        return run_param_sweep(args, params, scene, status)
    status.show("sweep: first cell")
    result = sweep(
        scene.stack,
        scene.data.angles_rad,
        params,
        args.windows,
        args.degrees,
        args.refractive_indices,
        ground_truth=scene.truth,
        score=args.score,
        progress=_cell_progress(args, status),
        mask=scene.mask,
        max_bytes=max_bytes(args),
        keep_labels=False,
    )
    failed = [c for c in result.cells if not c.ok]
    if len(failed) == len(result.cells):
        raise PolarsegError(f"no cell of the sweep could run: {failed[0].error}")
    best_cell = result.best_cell()  # raises if no cell reached two segments
    best = best_cell.params(result.base)
    status.show(f"writing the sweep to {args.out}")
    out = Path(args.out)
    write_sweep_folder(out, result, best, _summary(scene, result))
    status.clear()
    _report(result, best_cell, best, len(failed), out)
    if args.apply_best:
        best_args = argparse.Namespace(**{**vars(args), "out": str(out / "best")})
        segment_data(best_args, "segment", scene.data, scene.read_seconds, best)
    return 0
