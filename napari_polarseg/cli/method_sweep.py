"""``polarseg sweep --vary NAME=V,V,...``: sweep the chosen method's own parameters
(:func:`napari_polarseg.engine.analysis.param_sweep.param_sweep`) and write ``sweep.csv``,
``sweep.json`` and ``best_params.json``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from .. import __version__
from ..engine.errors import PolarsegError
from ..engine.params import SegmentParams
from ..status_line import StatusLine
from .arguments import PROG


def vary_arg(text: str) -> tuple[str, tuple[str, ...]]:
    """``NAME=V1,V2,...`` → (name, the values as written); argparse error otherwise."""
    name, sep, values = text.partition("=")
    words = tuple(w.strip() for w in values.split(",") if w.strip())
    if not sep or not name.strip() or not words:
        raise argparse.ArgumentTypeError(
            f"expected NAME=V,V,... (e.g. object_size=20,40), got {text!r}"
        )
    return name.strip().replace("-", "_"), words


def sweep_axes(params: SegmentParams, given: list[tuple[str, tuple[str, ...]]]) -> dict:
    """The axes of ``--vary`` (parameter name → values of its type, in order)."""
    from ..engine.analysis.param_sweep import value_from_text

    axes: dict[str, list[Any]] = {}
    for name, words in given:
        if name in axes:
            raise PolarsegError(f"--vary {name} given twice")
        axes[name] = [value_from_text(params, name, w) for w in words]
    return axes


def param_sweep_lines(result: Any, best: Any) -> list[str]:
    """The table ``polarseg sweep --vary`` prints (best cell marked ``*``)."""
    cols = [*result.axes, "segs", "stability"] + (["ARI"] if result.has_ground_truth else [])
    lines = ["  " + " ".join(f"{c:>12}" for c in [*cols, "s"])]
    for c in result.cells:
        mark = "*" if c is best else " "
        values = [str(c.values[a]) for a in result.axes]
        if not c.ok:
            lines.append(f"{mark} " + " ".join(f"{v:>12}" for v in values) + f"  error: {c.error}")
            continue
        scores = [c.stability] + ([c.ari] if result.has_ground_truth else []) + [c.seconds]
        shown = [f"{v:.3f}" if v == v else "-" for v in scores]  # NaN: -
        row = [*values, str(c.n_segments), *shown]
        lines.append(f"{mark} " + " ".join(f"{v:>12}" for v in row))
    return lines


def run_param_sweep(
    args: argparse.Namespace, params: SegmentParams, stack: Any, status: StatusLine
) -> int:
    """Sweep the ``--vary`` axes of ``params.method`` on the read ``stack`` (a
    :class:`~napari_polarseg.cli.sweep.SweptStack`) and write the folder; returns 0."""
    from ..engine.analysis.param_sweep import param_sweep
    from ..outputs.sweep_folder import write_param_sweep_folder

    axes = sweep_axes(params, args.vary)
    score = "ari" if args.score == "ari" else None
    if args.score not in ("stability", "ari"):
        raise PolarsegError(f"--vary scores cells by stability or ari, not {args.score}")

    def progress(done: int, total: int) -> None:
        if args.verbose:
            print(f"{PROG}: sweep cell {done}/{total}", file=sys.stderr, flush=True)
        else:
            status.show(f"sweep: {done}/{total} cells done")

    result = param_sweep(
        stack.stack,
        stack.data.angles_rad,
        params,
        axes,
        ground_truth=stack.truth,
        mask=stack.mask,
        progress=progress,
        keep_labels=False,
        score=score,
    )
    best_cell = result.best_cell()
    best = best_cell.params(params)
    out = Path(args.out)
    summary = {
        "polarseg_version": __version__,
        "command": "sweep",
        "input": str(Path(stack.data.source).resolve()),
        "ground_truth": stack.truth_from,
        **result.to_dict(),
        "best": {"by": result.score, "values": dict(best_cell.values)},
    }
    write_param_sweep_folder(out, result, best, summary)
    status.clear()
    for line in param_sweep_lines(result, best_cell):
        print(line)
    chosen = ", ".join(f"{k} = {v}" for k, v in best_cell.values.items())
    print(f"{PROG}: best by {result.score}: {chosen} ({best_cell.n_segments} segments)")
    print(f"{PROG}: wrote sweep.csv, sweep.json, best_params.json to {out}")
    return 0
