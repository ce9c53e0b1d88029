"""``polarseg segment``: segment an angle stack into a result folder."""

from __future__ import annotations

import argparse
from typing import Any

from .. import io as pio
from .. import jobs
from ..engine.errors import PolarsegError
from ..engine.params import ParamSpec
from ..engine.physics.mosaic import DEMOSAIC_METHODS
from .arguments import PROG, angles_arg, dark_level_arg, gib_arg, level_arg, number_arg
from .options import (
    STACK_INPUT_HELP,
    add_bayer_option,
    add_inputs_and_out,
    add_param_options,
    add_plots_option,
)
from .running import (
    output_options,
    params_from_args,
    print_messages,
    progress_report,
    read_options,
    status_line,
)


def add_parser(sub: Any, specs: dict[str, ParamSpec] | None = None) -> None:
    """Add the ``segment`` subcommand to ``sub`` (flags of ``specs``, default the table)."""
    seg = sub.add_parser(
        "segment",
        help="segment an angle stack and write labels, maps and JSON reports",
        description="Segment an angle stack (multi-page TIFF, .npz, folder of frames, or a "
        "raw polarisation-camera frame with --mosaic) and write the results into --out.",
    )
    add_inputs_and_out(seg, STACK_INPUT_HELP)
    seg.add_argument(
        "--angles",
        type=angles_arg,
        metavar="A,B,...",
        help="polariser angle of each frame in degrees, in frame order (overrides the file)",
    )
    seg.add_argument(
        "--mosaic",
        type=angles_arg,
        metavar="A,B,C,D",
        help="INPUT is one raw polarisation-camera frame; the 2x2 super-pixel angles in "
        "row-major order (Sony IMX250MZR: 90,45,135,0). Outputs are then half the raw "
        "frame's height and width (full size with --demosaic interpolated). A frame named "
        "after a Sony sensor (..._IMX250MZR.png, ..._IMX250MYR.png) needs no --mosaic",
    )
    add_bayer_option(seg)
    seg.add_argument(
        "--demosaic",
        choices=DEMOSAIC_METHODS,
        default="superpixel",
        help="mosaic decoding: one output pixel per 2x2 super-pixel, or full resolution by "
        "bilinear interpolation of each angle [superpixel]",
    )
    _add_capture_options(seg)
    _add_labels_options(seg)
    add_plots_option(seg)
    add_param_options(seg, specs=specs)
    seg.set_defaults(func=run)


def _add_capture_options(seg: argparse.ArgumentParser) -> None:
    """The real-capture options: dark frame, offset, saturation and dark levels, mask,
    memory limit, colour channel, registration."""
    seg.add_argument(
        "--dark-frame",
        metavar="FILE",
        help="dark frame (lens capped) subtracted from every frame, or from the raw mosaic",
    )
    seg.add_argument(
        "--offset",
        type=number_arg,
        metavar="V",
        help="constant black level subtracted from every sample (after --dark-frame)",
    )
    seg.add_argument(
        "--saturation",
        type=level_arg,
        default="auto",
        metavar="LEVEL",
        help="samples at or above LEVEL (in the file's units, before --dark-frame/--offset) "
        "are saturated and their pixels left out; 'auto' = the integer type's maximum (255, "
        "65535; 4095 for a 12-bit TIFF), 'none' = no check [auto]",
    )
    seg.add_argument(
        "--dark-level",
        type=dark_level_arg,
        default=0.0,
        metavar="LEVEL",
        help="samples at or below LEVEL (after subtraction) are black and their pixels left "
        "out; 'none' = no check [0]",
    )
    seg.add_argument(
        "--mask",
        metavar="FILE",
        help="a region (labels image: TIFF, PNG, .npy; non-zero = use): only its pixels "
        "enter the fit and the block features",
    )
    seg.add_argument(
        "--max-memory",
        type=gib_arg,
        metavar="GIB",
        help="refuse inputs and runs that would need more memory than this many GiB "
        "[$POLARSEG_MAX_BYTES or 8]",
    )
    seg.add_argument(
        "--channel", type=int, metavar="C", help="colour channel to use (default: BT.601 luma)"
    )
    seg.add_argument(
        "--thesis-maps",
        action="store_true",
        help="also compute the thesis maps when the method does not need them: the "
        "reconstruction-error map (reconstruction_error.tif) and the PCA features of the "
        "blocks (feature columns of segments.csv); always on with --method thesis and "
        "with --plots",
    )
    seg.add_argument(
        "--register",
        action="store_true",
        help="align the frames to the first by sub-pixel phase correlation first (shifts "
        "are reported and written to params.json)",
    )


def _add_labels_options(seg: argparse.ArgumentParser) -> None:
    """Where the labels come from (--scribbles or --classifier), --save-classifier and
    --ground-truth."""
    labels_from = seg.add_mutually_exclusive_group()
    labels_from.add_argument(
        "--scribbles",
        metavar="FILE",
        help="strokes (labels image: TIFF, PNG, .npy/.npz; the outputs' height x width; 0 = "
        "unlabelled, 1, 2, ... = materials, at least two): the labels come from a pixel "
        "classifier (random forest on multi-scale polarisation features) trained on the "
        "scribbled pixels instead of the normalized cut; also writes probabilities.tif and "
        "uncertainty.tif",
    )
    labels_from.add_argument(
        "--classifier",
        metavar="FILE",
        help="apply a saved pixel classifier (.polarseg-clf, from --save-classifier or the "
        "plugin's Save classifier...) instead of the normalized cut; nothing is retrained",
    )
    seg.add_argument(
        "--save-classifier",
        metavar="FILE",
        help="with --scribbles: also write the trained classifier to FILE (.polarseg-clf)",
    )
    seg.add_argument(
        "--ground-truth",
        metavar="FILE",
        help="true materials (labels image, the outputs' size): writes evaluation.json "
        "(adjusted Rand index, IoU per segment, block accuracy) and adds it to summary.json",
    )


def _check_demosaic_args(args: argparse.Namespace) -> None:
    """--demosaic and --bayer apply to a raw frame: --mosaic, or a sensor-named file."""
    named = len(args.input) == 1 and pio.sensor_from_name(args.input[0]) is not None
    if args.mosaic is None and not named:
        if args.demosaic != "superpixel":
            raise PolarsegError("--demosaic applies to a raw mosaic frame: give --mosaic too")
        if args.bayer is not None:
            raise PolarsegError("--bayer applies to a raw mosaic frame: give --mosaic too")


def run(args: argparse.Namespace) -> int:
    """Run ``polarseg segment``; return the exit code (0)."""
    params = params_from_args(args)
    _check_demosaic_args(args)
    status = status_line(args)
    done = jobs.segment_to_folder(
        args.input[0] if len(args.input) == 1 else args.input,
        args.out,
        params,
        read_options(args),
        output_options(args),
        status=status,
        progress=progress_report(args.verbose, status),
    )
    warning = done.run.data.metadata.get("mosaic_warning")
    if warning:
        print_messages([jobs.Message(f"{PROG}: warning: {warning}", "stderr")])
    print_messages(done.messages)
    return 0
