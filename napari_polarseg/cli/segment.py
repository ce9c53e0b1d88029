"""``polarseg segment``: segment an angle stack into a result folder."""

from __future__ import annotations

import argparse
from typing import Any

from .. import io as pio
from .. import jobs
from ..engine.errors import PolarsegError
from ..engine.params import ParamSpec
from ..outputs.image_formats import IMAGE_FORMATS
from .arguments import PROG
from .dask_options import add_dask_options, dask_tiles
from .options import (
    STACK_INPUT_HELP,
    add_inputs_and_out,
    add_param_options,
    add_plots_option,
    add_read_options,
)
from .running import (
    output_options,
    params_from_args,
    print_messages,
    progress_report,
    read_options,
    status_line,
)

#: The real-capture options: dark frame, offset, saturation and dark levels, mask, memory
#: limit, colour channel, registration (:class:`~napari_polarseg.io.ReadOptions` fields).
CAPTURE_OPTIONS = (
    "dark_frame",
    "offset",
    "saturation",
    "dark_level",
    "mask",
    "max_memory_gib",
    "channel",
    "register",
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
    add_read_options(seg, ("angles_deg", "mosaic_deg", "bayer", "demosaic"))
    add_read_options(seg, CAPTURE_OPTIONS)
    add_read_options(seg, ("lazy",))
    labels_from = seg.add_mutually_exclusive_group()
    add_read_options(labels_from, ("scribbles", "classifier"))
    seg.add_argument(
        "--save-classifier",
        metavar="FILE",
        help="with --scribbles: also write the trained classifier to FILE (.polarseg-clf)",
    )
    add_read_options(seg, ("ground_truth",))
    add_plots_option(seg)
    seg.add_argument(
        "--thesis-maps",
        action="store_true",
        help="also compute the thesis maps when the method does not need them: the "
        "reconstruction-error map (reconstruction_error.tif) and the PCA features of the "
        "blocks (feature columns of segments.csv); always on with --method thesis and "
        "with --plots",
    )
    seg.add_argument(
        "--format",
        dest="image_format",
        choices=tuple(IMAGE_FORMATS),
        default="tiff",
        help="the label and map images as TIFF (labels.tif, ...; a tiled BigTIFF from "
        "4096 x 4096 pixels) or as OME-Zarr directories (labels.zarr, ...: NGFF 0.4 "
        "multiscale, opened lazily by zarr and napari-ome-zarr) [tiff]",
    )
    add_dask_options(seg)
    add_param_options(seg, specs=specs)
    seg.set_defaults(func=run)


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
    with dask_tiles(args):
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
