"""``polarseg timeseries``: segment the days of one view in a shared basis, test every
block for a change between consecutive days, and write the time-series folder
(:mod:`napari_polarseg.outputs.timeseries_folder`)."""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .. import io as pio
from ..engine import Pipeline
from ..engine.analysis.evaluation import adjusted_rand_index
from ..engine.errors import PolarsegError
from ..engine.params import ParamSpec, SegmentParams
from ..engine.physics.pixel_mask import PixelMask, validity_mask
from ..engine.run_memory import check_pipeline_memory
from .arguments import PROG
from .options import BLOCK_PRESETS, add_input_options, add_inputs_and_out, add_param_options
from .running import max_bytes, params_from_args, progress_report, read_input


def add_parser(sub: Any, specs: dict[str, ParamSpec] | None = None) -> None:
    """Add the ``timeseries`` subcommand to ``sub`` (flags of ``specs``, default the table)."""
    ts = sub.add_parser(
        "timeseries",
        help="segment scenes of one view over time in a shared basis, with change maps",
        description="Segment INPUT1 INPUT2 ... (the same view on consecutive days, in time "
        "order) so that a segment means the same material every day, test every block for a "
        "change of its polarisation between consecutive days (the geometry of a static view "
        "cancels), and map the blocks that changed segment. Writes labels_01.tif, "
        "labels_02.tif, ... (one per day), change_01.tif (day 1 -> 2), ... (uint8, 1 = "
        "changed segment), score_01.tif, ... (float32 change score: the normal deviate of "
        "the block's p-value, 3.09 = p 0.001), distance_01.tif, ... (feature distance of "
        "each block between the two days), params.json and summary.json into --out.",
    )
    add_inputs_and_out(ts, "one angle stack per day, in time order")
    ts.add_argument(
        "--method",
        dest="change_method",
        choices=("tracked", "reference", "joint"),
        default="tracked",
        help="tracked: cut day 1 and move only the blocks whose polarisation changed "
        "significantly, to the segment of what they changed into; reference: give every "
        "day's blocks the nearest day-1 segment; joint: one cut over all days' blocks "
        "[tracked]",
    )
    ts.add_argument(
        "--false-alarm",
        type=float,
        default=0.001,
        metavar="P",
        help="probability that a block without change is flagged, per block and pair of "
        "days [0.001]",
    )
    ts.add_argument(
        "--change-window",
        type=int,
        default=None,
        metavar="PX",
        help="side of the change-test blocks in pixels [half the window, at least 6]",
    )
    ts.add_argument(
        "--change-from",
        choices=("all", "polarisation", "intensity"),
        default="all",
        help="what the change test compares: intensity and polarisation, or only one "
        "(polarisation: when the lighting changes between days) [all]",
    )
    ts.add_argument(
        "--classifier",
        metavar="FILE",
        help="label every day with this saved pixel classifier (.polarseg-clf): "
        "labels_DD.tif and change_DD.tif (pixels whose class changed) come from it; the "
        "change scores and distances stay those of the change test",
    )
    add_input_options(ts, "day")
    add_param_options(ts, preset="recommended", presets=BLOCK_PRESETS, specs=specs)
    ts.set_defaults(func=run)


@dataclasses.dataclass
class _Days:
    """The days of a time series, read, masked and (with --register) aligned."""

    data: list[pio.StackData]
    stacks: list[np.ndarray]
    masks: list[PixelMask]
    read_seconds: float


def _read_days(args: argparse.Namespace, params: SegmentParams) -> _Days:
    """Read every INPUT (at least two), check its memory, mask it, register if asked."""
    from ..batch import expand_inputs

    paths = expand_inputs(args.input)
    if len(paths) < 2:
        raise PolarsegError(f"a time series needs at least 2 inputs, got {len(paths)}")
    t0 = time.perf_counter()
    days = _Days([], [], [], 0.0)
    for path in paths:
        data = read_input(path, args)
        # every day's block coefficients, whatever the method
        check_pipeline_memory(data.stack.shape, params, max_bytes(args), blocks=True)
        stack = data.stack
        mask = validity_mask(
            stack, saturation=data.metadata.get("saturation_level"), saturated=data.saturated
        )
        if args.register:
            from ..engine.physics.registration import register_stack, shift_frames

            stack, shifts = register_stack(stack)
            mask = mask.shifted(shifts)
            if data.colour_stack is not None:
                data.colour_stack = shift_frames(data.colour_stack, shifts)
        days.data.append(data)
        days.stacks.append(stack)
        days.masks.append(mask)
    days.read_seconds = time.perf_counter() - t0
    return days


def _classify_days(result: Any, days: _Days, params: SegmentParams, path: str) -> Any:
    """The time series with every day labelled by the saved pixel classifier at ``path``
    (the same classes every day, so a label means the same material on every day; each
    labelled with its scribble value, as ``segment`` writes ``labels.tif``)."""
    from ..classifier_file import load_pixel_classifier
    from ..engine.classifier.pixel_segmentation import PixelSegmenter

    classifier = load_pixel_classifier(path)
    labels = np.stack(
        [
            PixelSegmenter(
                Pipeline(stack, day.angles_rad, params, mask=mask), colour_stack=day.colour_stack
            )
            .segment(classifier=classifier, reconstruction=False)
            .result.labels.astype(np.int32)
            for stack, day, mask in zip(days.stacks, days.data, days.masks, strict=True)
        ]
    )
    labels = np.asarray(classifier.classes, dtype=np.int32)[labels]  # the scribble values
    return dataclasses.replace(result, labels=labels, changes=labels[1:] != labels[:-1])


def _params_json(
    args: argparse.Namespace, days: _Days, result: Any, params: SegmentParams, summary: dict
) -> dict[str, Any]:
    """The content of ``params.json``."""
    from ..outputs.timeseries_folder import timeseries_files

    return {
        "polarseg_version": __version__,
        "command": "timeseries",
        "inputs": [str(Path(d.source).resolve()) for d in days.data],
        "angles_deg": [d.angles_deg.tolist() for d in days.data],
        "method": args.change_method,
        "registered": bool(args.register),
        "files": timeseries_files(summary["score_threshold"]),
        "change_window": result.change_window,
        "false_alarm": result.false_alarm,
        "change_from": result.change_from,
        "params": params.to_dict(),
    }


def _report(
    args: argparse.Namespace,
    result: Any,
    summary: dict[str, Any],
    aris: list[float | None],
    written: list[str],
) -> None:
    """Print the days, the changes between them, the ARIs and what was written."""
    h, w = result.labels.shape[1:]
    print(
        f"{PROG}: {result.n_days} days of {h} x {w} pixels, {result.n_segments} segments "
        f"({args.change_method}, {summary['n_components']} shared PCA components)"
    )
    for t, frac in enumerate(result.changed_fraction()):
        st = result.change_statistics[t]
        print(
            f"{PROG}: day {t + 1} -> {t + 2}: {frac:.1%} of the pixels changed segment; "
            f"{int(st.significant.sum())} of {st.significant.size} change blocks changed "
            f"significantly (false-alarm rate {result.false_alarm:g}, noise inflation "
            f"{st.inflation:.2f}, intensity gain {st.gain:.3f})"
        )
    for t, ari in enumerate(aris):
        if ari is not None:
            print(f"{PROG}: day {t + 1}: adjusted Rand index against the ground truth {ari:.3f}")
    print(f"{PROG}: wrote {', '.join(written)} to {Path(args.out)}")


def run(args: argparse.Namespace) -> int:
    """Run ``polarseg timeseries``; return the exit code (0)."""
    from ..engine.analysis.timeseries import segment_timeseries
    from ..engine.methods.scene import pipeline_labels
    from ..outputs.timeseries_folder import write_timeseries_folder

    params = params_from_args(args)
    days = _read_days(args, params)
    result = segment_timeseries(
        days.stacks,
        [d.angles_rad for d in days.data],
        params,
        method=args.change_method,
        change_window=args.change_window,
        false_alarm=args.false_alarm,
        change_from=args.change_from,
        masks=days.masks,
        progress=progress_report(args.verbose),
        day_labels=pipeline_labels,  # a method that does not cut blocks labels day 1
    )
    if args.classifier:
        result = _classify_days(result, days, params, args.classifier)
    summary = result.summary()
    if args.classifier:
        summary["labels_from"] = "classifier"  # labels_DD.tif: the scribble values
    summary["io_seconds"] = {"read": round(days.read_seconds, 6)}
    aris = [
        None if d.ground_truth is None else adjusted_rand_index(d.ground_truth, labels)
        for d, labels in zip(days.data, result.labels, strict=True)
    ]
    if any(a is not None for a in aris):
        summary["adjusted_rand_index"] = aris
    info = _params_json(args, days, result, params, summary)
    written = write_timeseries_folder(args.out, result, info, summary)
    _report(args, result, summary, aris, written)
    return 0
