"""The ``polarseg`` command: segment an angle stack, or run the bundled demo.

::

    polarseg segment INPUT [INPUT ...] --out DIR [--angles 0,30,60,...]
                         [--mosaic 90,45,135,0 [--bayer RGGB] [--demosaic interpolated]]
                         [--dark-frame FILE] [--offset V] [--saturation LEVEL]
                         [--dark-level LEVEL] [--mask FILE] [--register] [--fit robust]
                         [--window W] [--degree L] [--refractive-index N]
                         [--segments K] [--params FILE.json] [--max-memory GIB]
                         [--scribbles FILE [--save-classifier FILE.polarseg-clf]
                          | --classifier FILE.polarseg-clf] [--ground-truth FILE] [...]
    polarseg demo [--out DIR] [--scene leaves] [--plots]
    polarseg sweep INPUT --out DIR [--windows 8,10,12] [--degrees 4,8,12]
                         [--refractive-indices 1.45,1.6] [--ground-truth FILE]
                         [--score stability|combined|silhouette|ncut|ari] [--apply-best]

Angles are **degrees** on the command line and in every file (comma-separated, one per
frame, in frame order); the engine gets radians. ``segment`` writes into DIR:

=========================== ==========================================================
``labels.tif``              segment of every pixel (uint16, 0 = first segment)
``intensity.tif``           mean intensity Î (float32, input units)
``dop.tif``                 degree of polarisation ρ (float32, 0..1)
``phase.tif``               phase φ (float32, radians in [0, π))
``zenith.tif``              zenith angle θ (float32, radians in [0, π/2])
``reconstruction_error.tif`` \\|Î − Î rebuilt from the harmonics\\| (float32, input units)
``residual.tif``            RMS residual of the sinusoid fit per pixel (float32, input
                            units): large where a frame disagrees (motion, glints)
``mask.tif``                pixels the fit and the features used (uint8, 1 = used, 0 =
                            saturated or black in a frame, not finite, outside --mask,
                            or with no positive intensity); usable again as --mask
``params.json``             every parameter, the input, its angles, the package version,
                            whether registration ran and its shifts (pixels), the
                            demosaicing, dark frame/offset, saturation and dark levels,
                            the mask file and the repeated angles that were averaged
``summary.json``            the run's figures (per-stage seconds, number of segments,
                            explained variance, mean reconstruction error over the used
                            pixels, the pixel counts per exclusion reason under
                            ``mask``) and the seconds spent reading, registering and
                            writing
``segments.csv``            one row per segment: pixels, area fraction, mean Î, ρ,
                            θ (degrees), circular mean of φ (degrees) and the means of
                            the first 3 PCA features
``probabilities.tif``       with ``--scribbles`` or ``--classifier``: probability of
                            each class of the pixel classifier per pixel (float32,
                            K × H × W; class k = the k-th smallest scribble value, as
                            in ``labels.tif``)
``uncertainty.tif``         with ``--scribbles`` or ``--classifier``: 1 − (p1 − p2),
                            one minus the margin of the two most probable classes
                            (float32, H × W; 0 = sure, 1 = a tie)
``evaluation.json``         with ``--ground-truth``: adjusted Rand index, IoU per true
                            segment and its mean, block accuracy (worst, optimistic);
                            the figures are also added to ``summary.json``
``stokes.tif``              linear Stokes components S0, S1, S2 (float32, 3 × H × W):
                            S0 = 2 Î, S1 = S0 ρ cos 2φ, S2 = S0 ρ sin 2φ, angles from
                            the column axis towards the row axis (JSON ImageDescription)
``aolp_dolp.png``           AoLP/DoLP HSV composite (RGB): hue = φ over [0°, 180°),
                            saturation = ρ / ρ_max (ρ_max: the 99th percentile of ρ
                            rounded up to 0.05, in ``params.json``), value = Î / its
                            99th percentile
=========================== ==========================================================

All images are H × W of the angle stack the engine sees: the input's size, except with
``--mosaic``, where a raw H × W camera frame becomes a stack of H/2 × W/2 frames and so do
the outputs (full size with ``--demosaic interpolated``); with ``--bayer`` (a
colour-polarisation frame, 4 × 4 period) H/4 × W/4, the luminance of the R, G, B stacks
being segmented. A raw frame named after a Sony polarisation sensor (``…_IMX250MZR.png``,
``…_IMX250MYR.png``, :func:`napari_polarseg.io.sensor_from_name`) needs neither: it is
read with the sensor's layout (and RGGB order for the colour sensors). ``demo`` (and
``segment --overview``) also writes ``overview.png`` (with the ground truth beside the
segments and the adjusted Rand index in their title when the truth is known); ``--plots``
the analyst's plots as PNGs into ``DIR/plots/`` (:func:`napari_polarseg.figures.save_plots`).
The folder is written by :func:`napari_polarseg.export.write_result_folder`, as the
plugin's *Export results…* does.

``sweep`` segments one stack for every w, L (and n) of a grid with one cached pipeline
(:mod:`napari_polarseg.engine.analysis.sweep`) and writes ``sweep.csv`` (one row per cell: the
setting, segments reached, stability, silhouette, mean Ncut, combined score, ARI with a
ground truth, seconds, error), ``sweep.json`` (the same, the best cell and its parameters,
the total seconds), ``sweep_heatmap.png`` and ``best_params.json`` (SegmentParams JSON for
``segment --params``); ``--apply-best`` also runs ``segment`` with them into ``DIR/best/``.

Real captures: saturated samples (at or above ``--saturation``, default the integer
type's maximum) and black ones (at or below ``--dark-level``, default 0) are left out of
the fit and the features and counted; ``--dark-frame``/``--offset`` are subtracted after
saturation is found; ``--mask`` restricts the segmentation to a region (a labels image,
non-zero = use); frames at a repeated angle (modulo 180 degrees) are averaged before the
fit; ``--fit robust`` resists a wrong frame (5 or more distinct angles). Before any work
the memory a run needs is estimated from the stack's shape, the window and the degree,
and a run above the limit (8 GiB, ``--max-memory`` or ``$POLARSEG_MAX_BYTES``) is refused
with the size it would need.

Progress: on a terminal (stdout and stderr both terminals) ``segment``, ``demo`` and
``sweep`` show the running stage on one stderr line that is rewritten in place and erased
when the command ends (:mod:`napari_polarseg.status_line`), so the output left on the
screen is the same as without it; ``--quiet`` turns it off (and ``batch``'s per-scene
lines, except failures), ``--verbose`` prints permanent stage lines instead. Nothing of it
reaches a file or a pipe, and stdout is never touched.

Everything (parameters, reading, registration, the whole pipeline, the figure) is done
before the first file is written, and every file is written atomically, so bad input
never leaves a partial file where a good one was. Exit codes: 0 success, 2 bad input or
usage (one line ``polarseg: error: <message>`` on stderr, no traceback), 1 the outputs
could not be written, 130 interrupted.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import typing
import warnings
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__, jobs
from . import io as pio
from .engine import STAGES, Pipeline
from .engine.analysis.evaluation import adjusted_rand_index
from .engine.errors import PolarsegError
from .engine.limits import check_pipeline_memory, memory_limit
from .engine.params import (
    PARAM_SPECS,
    PRESET_HELP,
    PRESETS,
    ParamSpec,
    SegmentParams,
)
from .engine.physics.colour_mosaic import BAYER_ORDERS
from .engine.physics.mosaic import DEMOSAIC_METHODS
from .engine.physics.pixel_mask import PixelMask
from .engine.physics.polarimage import validity_mask
from .engine.physics.registration import register_stack, shift_frames
from .export import OutputError
from .export import labels_image as _labels_image
from .status_line import StatusLine

PROG = "polarseg"
#: Folder of the bundled sample scenes (``<scene>.npz``).
SAMPLE_DIR = Path(__file__).resolve().parent / "sample_data"
DEFAULT_SCENE = "leaves"
DEFAULT_DEMO_OUT = "polarseg-demo"


class UsageError(PolarsegError):
    """A command-line syntax error (reported like any bad input)."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser that raises instead of printing usage and exiting."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(message)


# -- argument parsing -----------------------------------------------------------------------


def _angles_arg(text: str) -> np.ndarray:
    try:
        return pio.parse_angles(text)
    except PolarsegError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers in degrees (e.g. 0,45,90,135), got {text!r}"
        ) from None


def _level_arg(text: str) -> float | str:
    word = text.strip().lower()
    if word in ("none", "auto"):
        return word
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a number, 'auto' or 'none', got {text!r}")
    return value


def _dark_level_arg(text: str) -> float | str:
    if text.strip().lower() == "none":
        return "none"
    try:
        return _number_arg(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected a number or 'none', got {text!r}") from None


def _number_arg(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _gib_arg(text: str) -> float:
    value = _number_arg(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number of GiB, got {text!r}")
    return value


def _threshold_arg(text: str) -> float | str:
    if text.strip().lower() == "none":
        return "none"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'none', got {text!r}") from None


def _field_types() -> dict[str, Any]:
    """The resolved type of every SegmentParams field."""
    return typing.get_type_hints(SegmentParams)


def param_options(
    specs: dict[str, ParamSpec] | None = None,
) -> dict[str, tuple[str, dict[str, Any]]]:
    """SegmentParams field -> (flag, argparse keywords), made from the parameter table.

    The type comes from the field's type (int, float; str for a field the table has but
    SegmentParams has not); an ``optional`` spec takes the ``none``-accepting threshold
    parser; a spec with choices gets them instead of a type; the help is the spec's.
    """
    specs = PARAM_SPECS if specs is None else specs
    types = _field_types()
    options: dict[str, tuple[str, dict[str, Any]]] = {}
    for name, spec in specs.items():
        kwargs: dict[str, Any] = {}
        if spec.choices:
            kwargs["choices"] = spec.choices
        elif spec.optional:
            kwargs["type"] = _threshold_arg
        else:
            kind = types.get(name, str)
            kwargs["type"] = kind if kind in (int, float, str) else str
        if spec.metavar:
            kwargs["metavar"] = spec.metavar
        kwargs["help"] = spec.help
        options[name] = (spec.flag, kwargs)
    return options


def _preset_help(presets: Sequence[str]) -> str:
    """What each of ``presets`` is, for --help."""
    return "; ".join(f"{name}: {PRESET_HELP[name]}" for name in presets)


#: Presets of the commands whose own analysis cuts the block graph (sweep, timeseries).
BLOCK_PRESETS = ("thesis", "recommended")


def _add_param_options(
    parser: argparse.ArgumentParser,
    preset: str = "auto",
    presets: tuple[str, ...] = tuple(PRESETS),
    specs: dict[str, ParamSpec] | None = None,
) -> None:
    defaults = {f.name: f.default for f in fields(SegmentParams)}
    group = parser.add_argument_group(
        "segmentation parameters",
        "start from --preset, then --params, then explicit flags; thesis defaults in brackets",
    )
    group.add_argument(
        "--preset",
        choices=presets,
        default=preset,
        help=f"starting parameters ({_preset_help(presets)}) [{preset}]",
    )
    group.add_argument(
        "--params",
        metavar="FILE.json",
        help="SegmentParams JSON (or a params.json written by polarseg)",
    )
    for name, (flag, kwargs) in param_options(specs).items():
        kwargs = dict(kwargs)
        kwargs["help"] = f"{kwargs['help']} [{defaults.get(name)}]".replace("%", "%%")
        group.add_argument(flag, dest=name, default=None, **kwargs)
    parser.add_argument(
        "--overview", action="store_true", help="also write overview.png (matplotlib figure)"
    )
    talk = parser.add_mutually_exclusive_group()
    talk.add_argument(
        "-v", "--verbose", action="store_true", help="report stages and warnings on stderr"
    )
    talk.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="no progress on stderr (by default a terminal shows the running stage on one "
        "line, erased at the end; never shown when stdout or stderr is not a terminal)",
    )


def _add_input_options(parser: argparse.ArgumentParser, unit: str) -> None:
    """Reading options shared by ``batch`` and ``timeseries`` (one INPUT per ``unit``)."""
    parser.add_argument(
        "--angles", type=_angles_arg, metavar="A,B,...", help=f"polariser angles of every {unit}"
    )
    parser.add_argument(
        "--mosaic", type=_angles_arg, metavar="A,B,C,D", help="every INPUT is a raw mosaic frame"
    )
    parser.add_argument("--demosaic", choices=DEMOSAIC_METHODS, default="superpixel")
    _add_bayer_option(parser)
    parser.add_argument("--channel", type=int, metavar="C", help="colour channel to use")
    parser.add_argument("--register", action="store_true", help=f"align the frames of each {unit}")
    parser.add_argument(
        "--max-memory", type=_gib_arg, metavar="GIB", help=f"memory limit of one {unit}, GiB"
    )


def _bayer_arg(text: str) -> str:
    order = text.strip().upper()
    if order not in BAYER_ORDERS:
        raise argparse.ArgumentTypeError(
            f"a Bayer order is one of {', '.join(BAYER_ORDERS)}, got {text!r}"
        )
    return order


def _add_bayer_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--bayer",
        type=_bayer_arg,
        metavar="ORDER",
        help="with --mosaic: the raw frame is a colour-polarisation mosaic whose 2x2 "
        "polariser super-pixels lie under this Bayer colour order, row-major "
        f"({', '.join(BAYER_ORDERS)}; Sony IMX250MYR/IMX253MYR: RGGB). Outputs are then a "
        "quarter of the raw frame's height and width (full size with --demosaic "
        "interpolated); the luminance 0.299 R + 0.587 G + 0.114 B is segmented",
    )


def _add_plots_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--plots",
        action="store_true",
        help="also write the analyst's plots as PNGs into OUT/plots/ (I-rho/phi scatter, "
        "explained variance, coefficient and component maps, reconstruction histograms, "
        "error table)",
    )


def build_parser(specs: dict[str, ParamSpec] | None = None) -> argparse.ArgumentParser:
    """The argument parser of ``polarseg`` (errors raise :class:`UsageError`); the
    segmentation flags are made from ``specs`` (default: :data:`PARAM_SPECS`)."""
    parser = _Parser(
        prog=PROG,
        description="Material segmentation from polarisation images (thesis pipeline: "
        "polarisation image, Fresnel normals, spherical harmonics, PCA, normalized cuts).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    seg = sub.add_parser(
        "segment",
        help="segment an angle stack and write labels, maps and JSON reports",
        description="Segment an angle stack (multi-page TIFF, .npz, folder of frames, or a "
        "raw polarisation-camera frame with --mosaic) and write the results into --out.",
    )
    seg.add_argument(
        "input",
        metavar="INPUT",
        nargs="+",
        help="TIFF, .npz/.npy, folder, raw frame, or several frame files (one per angle)",
    )
    seg.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder")
    seg.add_argument(
        "--angles",
        type=_angles_arg,
        metavar="A,B,...",
        help="polariser angle of each frame in degrees, in frame order (overrides the file)",
    )
    seg.add_argument(
        "--mosaic",
        type=_angles_arg,
        metavar="A,B,C,D",
        help="INPUT is one raw polarisation-camera frame; the 2x2 super-pixel angles in "
        "row-major order (Sony IMX250MZR: 90,45,135,0). Outputs are then half the raw "
        "frame's height and width (full size with --demosaic interpolated). A frame named "
        "after a Sony sensor (..._IMX250MZR.png, ..._IMX250MYR.png) needs no --mosaic",
    )
    _add_bayer_option(seg)
    seg.add_argument(
        "--demosaic",
        choices=DEMOSAIC_METHODS,
        default="superpixel",
        help="mosaic decoding: one output pixel per 2x2 super-pixel, or full resolution by "
        "bilinear interpolation of each angle [superpixel]",
    )
    seg.add_argument(
        "--dark-frame",
        metavar="FILE",
        help="dark frame (lens capped) subtracted from every frame, or from the raw mosaic",
    )
    seg.add_argument(
        "--offset",
        type=_number_arg,
        metavar="V",
        help="constant black level subtracted from every sample (after --dark-frame)",
    )
    seg.add_argument(
        "--saturation",
        type=_level_arg,
        default="auto",
        metavar="LEVEL",
        help="samples at or above LEVEL (in the file's units, before --dark-frame/--offset) "
        "are saturated and their pixels left out; 'auto' = the integer type's maximum (255, "
        "65535; 4095 for a 12-bit TIFF), 'none' = no check [auto]",
    )
    seg.add_argument(
        "--dark-level",
        type=_dark_level_arg,
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
        type=_gib_arg,
        metavar="GIB",
        help="refuse inputs and runs that would need more memory than this many GiB "
        "[$POLARSEG_MAX_BYTES or 8]",
    )
    seg.add_argument(
        "--channel", type=int, metavar="C", help="colour channel to use (default: BT.601 luma)"
    )
    seg.add_argument(
        "--register",
        action="store_true",
        help="align the frames to the first by sub-pixel phase correlation first (shifts "
        "are reported and written to params.json)",
    )
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
    _add_plots_option(seg)
    _add_param_options(seg, specs=specs)
    seg.set_defaults(func=_cmd_segment)

    demo = sub.add_parser(
        "demo",
        help="segment a bundled sample scene and draw an overview",
        description="Run the segmentation on a bundled sample scene, write the segment "
        "outputs and overview.png, and report the adjusted Rand index against the ground "
        "truth. The number of segments defaults to the ground truth's.",
    )
    demo.add_argument(
        "-o", "--out", default=DEFAULT_DEMO_OUT, metavar="DIR", help=f"[./{DEFAULT_DEMO_OUT}]"
    )
    demo.add_argument("--scene", default=DEFAULT_SCENE, help=f"bundled scene [{DEFAULT_SCENE}]")
    demo.add_argument(
        "--sample", metavar="FILE.npz", help="use this .npz (stack, angles, labels) instead"
    )
    _add_plots_option(demo)
    _add_param_options(demo, specs=specs)
    demo.set_defaults(func=_cmd_demo, overview=True)
    _add_sweep_parser(sub, specs)

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
    bat.add_argument(
        "input", metavar="INPUT", nargs="+", help="scene files, folders or glob patterns"
    )
    bat.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder")
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
    bat.add_argument(
        "--classifier",
        metavar="FILE",
        help="label every scene with this saved pixel classifier (.polarseg-clf) instead of "
        "the normalized cut",
    )
    _add_input_options(bat, "scene")
    _add_param_options(bat, specs=specs)
    bat.set_defaults(func=_cmd_batch)

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
    ts.add_argument(
        "input", metavar="INPUT", nargs="+", help="one angle stack per day, in time order"
    )
    ts.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder")
    ts.add_argument(
        "--method",
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
    _add_input_options(ts, "day")
    _add_param_options(ts, preset="recommended", presets=BLOCK_PRESETS, specs=specs)
    ts.set_defaults(func=_cmd_timeseries)
    return parser


# -- parameters -----------------------------------------------------------------------------


def _params_from_args(
    args: argparse.Namespace, base: dict[str, Any] | None = None
) -> SegmentParams:
    """SegmentParams from ``base``, then ``--params``, then explicit flags (validated)."""
    values: dict[str, Any] = PRESETS[getattr(args, "preset", "auto")].to_dict()
    values.update(base or {})
    source = "parameters"
    if args.params:
        source = args.params
        values.update(pio.read_params_dict(args.params))
    try:
        params = SegmentParams.from_dict(values)
    except PolarsegError as exc:
        raise PolarsegError(f"{source}: {exc}") from None
    except TypeError as exc:
        raise PolarsegError(f"{source}: a parameter has the wrong type ({exc})") from None
    changes = {name: getattr(args, name) for name in PARAM_SPECS}
    changes = {k: (None if v == "none" else v) for k, v in changes.items() if v is not None}
    return params.replace(**changes)


# -- running --------------------------------------------------------------------------------


def _progress(verbose: bool, status: StatusLine | None = None) -> jobs.Progress | None:
    """Pipeline progress callback: permanent lines with ``verbose``, else the status line
    (which names the stage now running), else None."""
    if verbose:

        def report(stage: str, index: int, total: int) -> None:
            print(f"{PROG}: [{index}/{total}] {stage}", file=sys.stderr, flush=True)

        return report
    if status is None or not status.enabled:
        return None

    def show(stage: str, index: int, total: int) -> None:
        if index < total:
            status.stage(STAGES[index], index + 1, total, "segmenting:")

    return show


def _status(args: argparse.Namespace) -> StatusLine:
    """The terminal status line of this command (disabled if not wanted or possible)."""
    status = getattr(args, "status_line", None)
    return status if isinstance(status, StatusLine) else StatusLine(False, PROG)


def _max_bytes(args: argparse.Namespace) -> int:
    gib = getattr(args, "max_memory", None)
    return memory_limit(None if gib is None else gib * 2**30)


def _angles(values: np.ndarray | None) -> tuple[float, ...] | None:
    return None if values is None else tuple(float(v) for v in values)


def _read_options(args: argparse.Namespace) -> jobs.ReadOptions:
    """The reading options of a command line (a command without an option: its default)."""
    saturation = getattr(args, "saturation", "auto")
    dark_level = getattr(args, "dark_level", 0.0)
    return jobs.ReadOptions(
        angles_deg=_angles(getattr(args, "angles", None)),
        mosaic_deg=_angles(getattr(args, "mosaic", None)),
        demosaic=getattr(args, "demosaic", "superpixel"),
        bayer=getattr(args, "bayer", None),
        channel=getattr(args, "channel", None),
        dark_frame=getattr(args, "dark_frame", None),
        offset=getattr(args, "offset", None),
        saturation=None if saturation == "none" else saturation,
        dark_level=None if dark_level == "none" else dark_level,
        mask=getattr(args, "mask", None),
        register=bool(getattr(args, "register", False)),
        max_memory_gib=getattr(args, "max_memory", None),
        scribbles=getattr(args, "scribbles", None),
        classifier=getattr(args, "classifier", None),
        ground_truth=getattr(args, "ground_truth", None),
    )


def _output_options(args: argparse.Namespace) -> jobs.OutputOptions:
    return jobs.OutputOptions(
        overview=bool(args.overview),
        plots=bool(getattr(args, "plots", False)),
        save_classifier=getattr(args, "save_classifier", None),
    )


def print_messages(messages: Sequence[jobs.Message]) -> None:
    """Print a job's messages, each on its stream, in order."""
    for message in messages:
        if message.stream == "stderr":
            sys.stdout.flush()  # keep the order of the two streams on a terminal
            print(message.text, file=sys.stderr, flush=True)
        else:
            print(message.text)


def _job(
    args: argparse.Namespace,
    command: str,
    data: pio.StackData,
    read_seconds: float,
    params: SegmentParams,
    extra: dict[str, Any] | None = None,
    note_repeated: bool = True,
) -> jobs.FolderResult:
    """Segment already-read data into ``args.out`` and print what the job says."""
    status = _status(args)
    done = jobs.data_to_folder(
        data,
        args.out,
        params,
        _read_options(args),
        _output_options(args),
        read_seconds=read_seconds,
        command=command,
        extra=extra,
        note_repeated=note_repeated,
        status=status,
        progress=_progress(args.verbose, status),
    )
    print_messages(done.messages)
    return done


def _check_demosaic_args(args: argparse.Namespace) -> None:
    """--demosaic and --bayer apply to a raw frame: --mosaic, or a sensor-named file."""
    named = len(args.input) == 1 and pio.sensor_from_name(args.input[0]) is not None
    if args.mosaic is None and not named:
        if args.demosaic != "superpixel":
            raise PolarsegError("--demosaic applies to a raw mosaic frame: give --mosaic too")
        if args.bayer is not None:
            raise PolarsegError("--bayer applies to a raw mosaic frame: give --mosaic too")


def _cmd_segment(args: argparse.Namespace) -> int:
    params = _params_from_args(args)
    _check_demosaic_args(args)
    status = _status(args)
    done = jobs.segment_to_folder(
        args.input[0] if len(args.input) == 1 else args.input,
        args.out,
        params,
        _read_options(args),
        _output_options(args),
        status=status,
        progress=_progress(args.verbose, status),
    )
    print_messages(done.messages)
    return 0


def available_scenes(folder: Path | None = None) -> list[str]:
    """Names of the bundled sample scenes (``sample_data/<scene>.npz``)."""
    folder = SAMPLE_DIR if folder is None else folder
    return sorted(p.stem for p in folder.glob("*.npz")) if folder.is_dir() else []


def _sample_path(args: argparse.Namespace) -> Path:
    if args.sample:
        return Path(args.sample)
    path = SAMPLE_DIR / f"{args.scene}.npz"
    if not path.is_file():
        scenes = ", ".join(available_scenes()) or "none installed"
        raise PolarsegError(f"no bundled sample scene {args.scene!r} (available: {scenes})")
    return path


def _cmd_demo(args: argparse.Namespace) -> int:
    path = _sample_path(args)
    _status(args).show(f"reading {path.name}")
    t0 = time.perf_counter()
    data = pio.read_stack(path)
    read_seconds = time.perf_counter() - t0
    base = dict(data.metadata.get("params") or {})
    if data.ground_truth is not None and "n_segments" not in base:
        base["n_segments"] = int(np.unique(data.ground_truth).size)
    params = _params_from_args(args, base)
    # The bundled scenes are rendered at 0..180 degrees (0 and 180 both, as the thesis
    # captures): saying they were averaged would be a notice about our data, not the
    # user's, on the first command a user runs. A --sample file is the user's: said.
    done = _job(args, "demo", data, read_seconds, params, {"scene": path.stem}, bool(args.sample))
    if "adjusted_rand_index" in done.summary:
        ari = done.summary["adjusted_rand_index"]
        print(f"{PROG}: adjusted Rand index against the ground truth: {ari:.3f}")
    return 0


# -- parameter sweep ------------------------------------------------------------------------


def _number_list_arg(kind: type, what: str):
    def parse(text: str) -> tuple:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        try:
            values = [kind(p) for p in parts]
        except ValueError:
            values = []
        if not values or not all(np.isfinite(v) for v in values):
            example = "8,10,12" if kind is int else "1.4,1.6"
            raise argparse.ArgumentTypeError(
                f"expected comma-separated {what} (e.g. {example}), got {text!r}"
            )
        return tuple(values)

    return parse


def _add_sweep_parser(sub: Any, specs: dict[str, ParamSpec] | None = None) -> None:
    from .engine.analysis.sweep_result import DEFAULT_SCORE, SCORES

    sw = sub.add_parser(
        "sweep",
        help="segment one stack over a grid of window sizes, degrees and refractive indices",
        description="Run the segmentation for every window size w, harmonic degree L and "
        "refractive index n of a grid (one cached pipeline), score every cell without "
        "ground truth (stability: mean adjusted Rand index with the neighbouring w and L "
        "cells; silhouette of the blocks in the whitened PCA space; mean Ncut value of the "
        "cuts; a combined score) and, with a ground truth, by its adjusted Rand index. "
        "Writes sweep.csv, sweep.json, sweep_heatmap.png and best_params.json (give it to "
        "'polarseg segment --params') into --out; --apply-best also segments with the best "
        "parameters into OUT/best/.",
    )
    sw.add_argument(
        "input",
        metavar="INPUT",
        nargs="+",
        help="TIFF, .npz/.npy, folder, raw frame, or several frame files (one per angle)",
    )
    sw.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder")
    sw.add_argument(
        "--windows",
        type=_number_list_arg(int, "window sizes in pixels"),
        default=(8, 10, 12),
        metavar="W,W,...",
        help="window sizes w in pixels [8,10,12]",
    )
    sw.add_argument(
        "--degrees",
        type=_number_list_arg(int, "harmonic degrees"),
        default=(4, 8, 12),
        metavar="L,L,...",
        help="harmonic degrees L [4,8,12]",
    )
    sw.add_argument(
        "--refractive-indices",
        type=_number_list_arg(float, "refractive indices"),
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
    _add_input_options(sw, "stack")
    _add_plots_option(sw)
    _add_param_options(sw, preset="recommended", presets=BLOCK_PRESETS, specs=specs)
    sw.set_defaults(func=_cmd_sweep)


def _fmt(value: Any, digits: int = 3) -> str:
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


def _cmd_sweep(args: argparse.Namespace) -> int:
    from . import figures
    from .engine.analysis.sweep import sweep

    params = _params_from_args(args)
    for flag, value in (("--plots", args.plots), ("--overview", args.overview)):
        if value and not args.apply_best:
            raise PolarsegError(f"{flag} draws the best cell's segmentation: give --apply-best")
    status = _status(args)
    status.show(f"reading {Path(args.input[0]).name}")
    t0 = time.perf_counter()
    data = pio.read_stack(
        args.input[0] if len(args.input) == 1 else args.input,
        angles_deg=args.angles,
        mosaic=args.mosaic,
        channel=args.channel,
        demosaic=args.demosaic,
        bayer=args.bayer,
        max_bytes=_max_bytes(args),
    )
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
    mask = jobs.pixel_mask(data, _read_options(args))
    stack, shifts = data.stack, None
    if args.register:
        status.show("registering the frames")
        stack, shifts = register_stack(stack)
        mask = mask.shifted(shifts)
    status.show("sweep: first cell")
    started = status.elapsed()

    def progress(done: int, total: int) -> None:
        if args.verbose:
            print(f"{PROG}: sweep cell {done}/{total}", file=sys.stderr, flush=True)
            return
        left = (status.elapsed() - started) / done * (total - done)
        status.show(f"sweep: {done}/{total} cells done, about {left:.0f} s left")

    result = sweep(
        stack,
        data.angles_rad,
        params,
        args.windows,
        args.degrees,
        args.refractive_indices,
        ground_truth=truth,
        score=args.score,
        progress=progress if args.verbose or status.enabled else None,
        mask=mask,
        max_bytes=_max_bytes(args),
        keep_labels=False,
    )
    failed = [c for c in result.cells if not c.ok]
    if len(failed) == len(result.cells):
        raise PolarsegError(f"no cell of the sweep could run: {failed[0].error}")
    best_cell = result.best_cell()  # raises if no cell reached two segments
    best = best_cell.params(result.base)
    status.show(f"writing the sweep to {args.out}")
    heatmap = figures.png_bytes(figures.sweep_heatmap_figure(result))
    summary = {
        "polarseg_version": __version__,
        "command": "sweep",
        "input": str(Path(data.source).resolve()),
        "stack_shape": list(stack.shape),
        "angles_deg": data.angles_deg.tolist(),
        "registration_shifts_px": None if shifts is None else shifts.tolist(),
        "ground_truth": truth_from,
        "read_seconds": round(read_seconds, 6),
        **result.to_dict(),
    }
    out = Path(args.out)
    name = str(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        name = str(out / "sweep.csv")
        with pio.atomic_output(out / "sweep.csv") as tmp:
            tmp.write_text(result.to_csv(), encoding="utf-8")
        name = str(out / "sweep_heatmap.png")
        with pio.atomic_output(out / "sweep_heatmap.png") as tmp:
            tmp.write_bytes(heatmap)
        name = str(out / "best_params.json")
        with pio.atomic_output(out / "best_params.json") as tmp:
            tmp.write_text(best.to_json() + "\n", encoding="utf-8")
        name = str(out / "sweep.json")
        pio.write_json(out / "sweep.json", summary)
    except OSError as exc:
        raise OutputError(f"cannot write {name}: {exc.strerror or exc}") from exc
    status.clear()
    for line in sweep_table(result, best_cell):
        print(line)
    extra = "" if not result.has_ground_truth else f", ARI {best_cell.ari:.3f}"
    print(
        f"{PROG}: best by {result.score}: w = {best.window}, L = {best.degree}, "
        f"n = {best.refractive_index:g} ({best_cell.n_segments} segments{extra})"
    )
    print(
        f"{PROG}: {len(result.cells)} cells ({len(failed)} failed) in "
        f"{result.total_seconds:.2f} s; wrote sweep.csv, sweep.json, sweep_heatmap.png, "
        f"best_params.json to {out}"
    )
    print(f"{PROG}: to use it: {PROG} segment INPUT --params {out / 'best_params.json'} --out DIR")
    if args.apply_best:
        best_args = argparse.Namespace(**{**vars(args), "out": str(out / "best")})
        _job(best_args, "segment", data, read_seconds, best)
    return 0


# -- entry point ----------------------------------------------------------------------------


def _fail(message: str, code: int) -> int:
    text = " ".join(str(message).split())
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``polarseg`` with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    status = StatusLine(False, PROG)
    try:
        args = parser.parse_args(argv)
        status = StatusLine.for_terminal(
            getattr(args, "quiet", False) or getattr(args, "verbose", False), PROG
        )
        args.status_line = status
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                code = args.func(args)
            finally:
                status.clear()  # before an error line, and on an interrupt
        if args.verbose:
            for message in dict.fromkeys((str(w.message).splitlines() or [""])[0] for w in caught):
                print(f"{PROG}: warning: {message}", file=sys.stderr)
        return code
    except PolarsegError as exc:
        return _fail(str(exc), 2)
    except OutputError as exc:
        return _fail(str(exc), 1)
    except OSError as exc:
        return _fail(str(exc), 2)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except SystemExit as exc:  # --help and --version
        return exc.code if isinstance(exc.code, int) else 0


# -- batch and time series ------------------------------------------------------------------


def _batch_options(args: argparse.Namespace) -> tuple[jobs.ReadOptions, jobs.OutputOptions]:
    """The reading and output options a ``batch`` command line gives every scene."""
    read = jobs.ReadOptions(
        angles_deg=_angles(args.angles),
        mosaic_deg=_angles(args.mosaic),
        demosaic=args.demosaic,
        bayer=args.bayer,
        channel=args.channel,
        register=bool(args.register),
        max_memory_gib=args.max_memory,
        classifier=None if args.classifier is None else str(Path(args.classifier).resolve()),
    )
    return read, jobs.OutputOptions(overview=bool(args.overview))


def _cmd_batch(args: argparse.Namespace) -> int:
    from . import batch

    params = _params_from_args(args)
    if args.workers is not None and args.workers < 1:
        raise PolarsegError(f"--workers must be at least 1, got {args.workers}")
    if args.classifier:
        from .classifier_file import load_pixel_classifier

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
            print(
                f"{PROG}: warning: {row['scene']}: degenerate result: "
                f"{row.get('degenerate_reason')}; try --preset recommended, fewer or more "
                "segments (--segments), a larger window (--window), or scribbles (--scribbles)",
                file=sys.stderr,
                flush=True,
            )
        if args.verbose and row.get("log"):
            print(row["log"].rstrip(), file=sys.stderr, flush=True)

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
        progress=progress,
        on_start=started,
    )
    rate = result.scenes_per_second
    rate_text = "" if rate is None else f", {rate:.3g} scenes/s"
    print(
        f"{PROG}: {result.count('done')} done, {result.count('skipped')} skipped, "
        f"{result.count('failed')} failed, {result.count('cancelled')} cancelled in "
        f"{time.perf_counter() - t0:.1f} s{rate_text}; summary in "
        f"{Path(args.out) / batch.SUMMARY_CSV}"
    )
    return 0 if result.ok else 3


def _classify_days(
    result: Any,
    stacks: list[np.ndarray],
    days: list[pio.StackData],
    masks: list[PixelMask],
    params: SegmentParams,
    path: str,
) -> Any:
    """The time series with every day labelled by the saved pixel classifier at ``path``
    (the same classes every day, so a label means the same material on every day)."""
    from .classifier_file import load_pixel_classifier
    from .engine.analysis.pixel_segmentation import PixelSegmenter

    classifier = load_pixel_classifier(path)
    labels = np.stack(
        [
            PixelSegmenter(
                Pipeline(stack, day.angles_rad, params, mask=mask), colour_stack=day.colour_stack
            )
            .segment(classifier=classifier, reconstruction=False)
            .result.labels.astype(np.int32)
            for stack, day, mask in zip(stacks, days, masks, strict=True)
        ]
    )
    return dataclasses.replace(result, labels=labels, changes=labels[1:] != labels[:-1])


def _cmd_timeseries(args: argparse.Namespace) -> int:
    from .batch import expand_inputs
    from .engine.analysis.timeseries import segment_timeseries

    params = _params_from_args(args)
    paths = expand_inputs(args.input)
    if len(paths) < 2:
        raise PolarsegError(f"a time series needs at least 2 inputs, got {len(paths)}")
    t0 = time.perf_counter()
    days: list[pio.StackData] = []
    stacks, masks = [], []
    for path in paths:
        data = pio.read_stack(
            path,
            angles_deg=args.angles,
            mosaic=args.mosaic,
            channel=args.channel,
            demosaic=args.demosaic,
            bayer=args.bayer,
            max_bytes=_max_bytes(args),
        )
        check_pipeline_memory(data.stack.shape, params, _max_bytes(args))
        stack = data.stack
        mask = validity_mask(
            stack, saturation=data.metadata.get("saturation_level"), saturated=data.saturated
        )
        if args.register:
            stack, shifts = register_stack(stack)
            mask = mask.shifted(shifts)
            if data.colour_stack is not None:
                data.colour_stack = shift_frames(data.colour_stack, shifts)
        days.append(data)
        stacks.append(stack)
        masks.append(mask)
    read_seconds = time.perf_counter() - t0
    result = segment_timeseries(
        stacks,
        [d.angles_rad for d in days],
        params,
        method=args.method,
        change_window=args.change_window,
        false_alarm=args.false_alarm,
        change_from=args.change_from,
        masks=masks,
        progress=_progress(args.verbose),
    )
    if args.classifier:
        result = _classify_days(result, stacks, days, masks, params, args.classifier)
    summary = result.summary()
    if args.classifier:
        summary["labels_from"] = "classifier"
    summary["io_seconds"] = {"read": round(read_seconds, 6)}
    aris = [
        None if d.ground_truth is None else adjusted_rand_index(d.ground_truth, labels)
        for d, labels in zip(days, result.labels, strict=True)
    ]
    if any(a is not None for a in aris):
        summary["adjusted_rand_index"] = aris
    info = {
        "polarseg_version": __version__,
        "command": "timeseries",
        "inputs": [str(Path(d.source).resolve()) for d in days],
        "angles_deg": [d.angles_deg.tolist() for d in days],
        "method": args.method,
        "registered": bool(args.register),
        "files": {
            "labels": "labels_DD.tif: segment of every pixel on day DD (0 = first segment, "
            "the same numbering every day)",
            "change": "change_DD.tif: 1 where the block changed segment from day DD to DD+1",
            "score": "score_DD.tif: change score of the pixel's change block between day DD "
            "and DD+1 (normal deviate of the p-value that its polarisation image did not "
            f"change; significant above {summary['score_threshold']:.2f})",
            "distance": "distance_DD.tif: Mahalanobis distance of the block's features "
            "between day DD and DD+1 (shared basis)",
        },
        "change_window": result.change_window,
        "false_alarm": result.false_alarm,
        "change_from": result.change_from,
        "params": params.to_dict(),
    }
    out = Path(args.out)
    written: list[str] = []
    name = str(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        for t, labels in enumerate(result.labels):
            name = str(out / f"labels_{t + 1:02d}.tif")
            meta = {"quantity": "segment labels", "first_label": 0, "day": t + 1}
            pio.write_tiff(name, _labels_image(labels), meta)
            written.append(Path(name).name)
        pairs = zip(result.changes, result.change_score, result.feature_distance, strict=True)
        for t, (change, score, dist) in enumerate(pairs):
            name = str(out / f"change_{t + 1:02d}.tif")
            meta = {"quantity": "segment changed", "from_day": t + 1, "to_day": t + 2}
            pio.write_tiff(name, change.astype(np.uint8), meta)
            written.append(Path(name).name)
            name = str(out / f"score_{t + 1:02d}.tif")
            meta = {"quantity": "change score (normal deviate)", "from_day": t + 1}
            pio.write_tiff(name, score.astype(np.float32), {**meta, "to_day": t + 2})
            written.append(Path(name).name)
            name = str(out / f"distance_{t + 1:02d}.tif")
            meta = {"quantity": "feature distance (Mahalanobis)", "from_day": t + 1}
            pio.write_tiff(name, dist.astype(np.float32), {**meta, "to_day": t + 2})
            written.append(Path(name).name)
        name = str(out / "params.json")
        pio.write_json(name, info)
        name = str(out / "summary.json")
        pio.write_json(name, summary)
        written += ["params.json", "summary.json"]
    except OSError as exc:
        raise OutputError(f"cannot write {name}: {exc.strerror or exc}") from exc
    h, w = result.labels.shape[1:]
    print(
        f"{PROG}: {result.n_days} days of {h} x {w} pixels, {result.n_segments} segments "
        f"({args.method}, {summary['n_components']} shared PCA components)"
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
    print(f"{PROG}: wrote {', '.join(written)} to {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
