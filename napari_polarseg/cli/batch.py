"""``polarseg batch``: segment many scenes with the same parameters, in parallel (Dask)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import jobs
from ..engine.errors import PolarsegError
from ..engine.params import ParamSpec, SegmentParams
from ..messages import degenerate_advice
from .arguments import PROG
from .options import add_input_options, add_inputs_and_out, add_param_options, add_read_options
from .running import params_from_args, read_options, running_method


def add_parser(sub: Any, specs: dict[str, ParamSpec] | None = None) -> None:
    """Add the ``batch`` subcommand to ``sub`` (flags of ``specs``, default the table)."""
    bat = sub.add_parser(
        "batch",
        help="segment many scenes with the same parameters, in parallel (Dask)",
        description="Segment every INPUT (stack file, folder of frames, raw mosaic frame with "
        "--mosaic, or a glob pattern) with the same parameters, each into OUT/<scene>/ as "
        "'segment' would, in parallel on a local Dask cluster (one single-threaded worker "
        "process per core) or on a running dask.distributed scheduler (--scheduler). "
        "Writes OUT/batch_summary.csv and OUT/batch_summary.json. A rerun skips the scenes "
        "already complete for the same input and parameters. Exit code 3 if a scene failed.",
    )
    add_inputs_and_out(bat, "scene files, folders or glob patterns")
    bat.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="address of a running dask.distributed scheduler (tcp://host:port); its workers "
        "must see INPUT and DIR under the same paths. 'inline': no Dask, one scene after "
        "the other in this process [a new local cluster]",
    )
    bat.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes of the local cluster [number of cores, at most one per scene]",
    )
    bat.add_argument(
        "--memory-limit",
        metavar="SIZE",
        default="auto",
        help="memory limit of each local worker, e.g. 4GiB; a scene estimated to need more "
        "than 80%% of it is refused [auto: the machine's memory shared out]",
    )
    bat.add_argument(
        "--no-resume",
        dest="resume",
        action="store_false",
        help="redo every scene, also those already complete",
    )
    add_read_options(
        bat,
        ("classifier",),
        helps={
            "classifier": "label every scene with this saved pixel classifier "
            "(.polarseg-clf) instead of the unsupervised method"
        },
    )
    add_input_options(bat, "scene")
    add_param_options(bat, specs=specs)
    bat.set_defaults(func=run)


def _batch_options(args: argparse.Namespace) -> tuple[jobs.ReadOptions, jobs.OutputOptions]:
    """The reading and output options a ``batch`` command line gives every scene."""
    read = read_options(args)
    if read.classifier is not None:  # the record in each scene's marker, wherever it runs
        read = dataclasses.replace(read, classifier=str(Path(read.classifier).resolve()))
    return read, jobs.OutputOptions(overview=bool(args.overview))


def _scene_report(
    args: argparse.Namespace, params: SegmentParams
) -> Callable[[int, int, dict[str, Any]], None]:
    """The per-scene progress callback: one stderr line per scene (only failures with
    --quiet), a warning for a degenerate result with what to try (the flags the running
    method reads: :func:`~napari_polarseg.messages.degenerate_advice`), the scene's log
    with --verbose."""
    advice: list[str] = []  # made at the first degenerate scene (it reads the methods)

    def progress(index: int, total: int, row: dict[str, Any]) -> None:
        status = row["status"]
        if status == "done":
            ari = row.get("adjusted_rand_index")
            extra = "" if ari is None else f", adjusted Rand index {ari:.3f}"
            text = f"done in {row['task_seconds']:.2f} s ({row['n_segments']} segments{extra})"
        elif status == "skipped":
            text = "skipped (complete)"
        else:
            text = f"{status}: {row.get('error')}"
        if not args.quiet or status in ("failed", "cancelled"):
            print(f"{PROG}: [{index}/{total}] {row['scene']}: {text}", file=sys.stderr, flush=True)
        if status == "done" and row.get("degenerate"):
            advice[:] = advice or [degenerate_advice(running_method(params, args), params)]
            print(
                f"{PROG}: warning: {row['scene']}: degenerate result: "
                f"{row.get('degenerate_reason')}; {advice[0]}",
                file=sys.stderr,
                flush=True,
            )
        if args.verbose and row.get("log"):
            print(row["log"].rstrip(), file=sys.stderr, flush=True)

    return progress


def run(args: argparse.Namespace) -> int:
    """Run ``polarseg batch``; return the exit code (0, or 3 if a scene failed)."""
    from .. import batch

    params = params_from_args(args)
    if args.workers is not None and args.workers < 1:
        raise PolarsegError(f"--workers must be at least 1, got {args.workers}")
    if args.classifier:
        from ..classifier_file import load_pixel_classifier

        load_pixel_classifier(args.classifier)  # a bad file stops here, not in every scene
    read, outputs = _batch_options(args)
    scenes = batch.plan(args.input, args.out)
    if not scenes:
        raise PolarsegError("no input scenes (every INPUT is inside --out)")
    t0 = time.perf_counter()

    def started(n_run: int, n_skip: int, label: str) -> None:
        if args.quiet:
            return
        where = f" on {label}" if n_run else ""
        print(
            f"{PROG}: {len(scenes)} scene(s) into {args.out}: {n_run} to segment{where}, "
            f"{n_skip} already complete",
            file=sys.stderr,
            flush=True,
        )

    result = batch.run_batch(
        scenes,
        args.out,
        params,
        read=read,
        outputs=outputs,
        scheduler=args.scheduler,
        n_workers=args.workers,
        memory_limit=args.memory_limit,
        resume=args.resume,
        progress=_scene_report(args, params),
        on_start=started,
    )
    print(
        f"{PROG}: {result.count('done')} done, {result.count('skipped')} skipped, "
        f"{result.count('failed')} failed, {result.count('cancelled')} cancelled in "
        f"{time.perf_counter() - t0:.1f} s{result.rate_text()}; summary in "
        f"{Path(args.out) / batch.SUMMARY_CSV}"
    )
    return 0 if result.ok else 3
