"""The ``polarseg`` command: segment an angle stack, or run the bundled demo.

::

    polarseg segment INPUT [INPUT ...] --out DIR [--angles 0,30,60,...]
                         [--mosaic 90,45,135,0 [--bayer RGGB] [--demosaic interpolated]]
                         [--dark-frame FILE] [--offset V] [--saturation LEVEL]
                         [--dark-level LEVEL] [--mask FILE] [--register] [--fit robust]
                         [--window W] [--degree L] [--refractive-index N]
                         [--segments K] [--params FILE.json] [--max-memory SIZE]
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
the analyst's plots as PNGs into ``DIR/plots/``
(:func:`napari_polarseg.outputs.figures.save_plots`). The folder is written by
:func:`napari_polarseg.outputs.write_result_folder`, as the plugin's *Export results…*
does.

``sweep`` segments one stack for every w, L (and n) of a grid with one cached pipeline
(:mod:`napari_polarseg.engine.analysis.sweep`) and writes ``sweep.csv`` (one row per cell: the
setting, segments reached, stability, silhouette, mean Ncut, combined score, ARI with a
ground truth, seconds, error), ``sweep.json`` (the same, the best cell and its parameters,
the total seconds), ``sweep_heatmap.png`` and ``best_params.json`` (SegmentParams JSON for
``segment --params``), written by
:func:`napari_polarseg.outputs.sweep_folder.write_sweep_folder`; ``--apply-best`` also
runs ``segment`` with them into ``DIR/best/``.

Real captures: saturated samples (at or above ``--saturation``, default the integer
type's maximum) and black ones (at or below ``--dark-level``, default 0) are left out of
the fit and the features and counted; ``--dark-frame``/``--offset`` are subtracted after
saturation is found; ``--mask`` restricts the segmentation to a region (a labels image,
non-zero = use); frames at a repeated angle (modulo 180 degrees) are averaged before the
fit; ``--fit robust`` resists a wrong frame (5 or more distinct angles). Before any work
the memory a run needs is estimated from the stack's shape and the method (with the
tiles it would work in; for a method that cuts blocks or with the thesis maps, the
window and the degree). The limit (``--max-memory`` or ``$POLARSEG_MAX_BYTES``, default
16 GiB or three quarters of the machine's memory when that is less) chooses the tiles
of the methods that work tile by tile, so their peak follows it; a run whose estimate
stays above it even tiled is refused with the size it would need.

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

import sys
import warnings
from collections.abc import Sequence

from .. import __version__
from ..engine.errors import PolarsegError
from ..engine.params import ParamSpec
from ..outputs import OutputError
from ..status_line import StatusLine
from . import batch, demo, segment, sweep, timeseries
from .arguments import PROG, CommandParser, UsageError
from .demo import available_scenes
from .options import BLOCK_PRESETS, param_options
from .running import print_messages
from .sweep import sweep_table

__all__ = [
    "BLOCK_PRESETS",
    "PROG",
    "UsageError",
    "available_scenes",
    "build_parser",
    "main",
    "param_options",
    "print_messages",
    "sweep_table",
]

#: The subcommand modules, in the order ``polarseg --help`` lists them; each has
#: ``add_parser(sub, specs)`` and ``run(args)``.
COMMANDS = (segment, demo, sweep, batch, timeseries)


def build_parser(specs: dict[str, ParamSpec] | None = None) -> CommandParser:
    """The argument parser of ``polarseg`` (errors raise :class:`UsageError`); the
    segmentation flags are made from ``specs`` (default:
    :data:`~napari_polarseg.engine.params.PARAM_SPECS`)."""
    parser = CommandParser(
        prog=PROG,
        description="Material segmentation from polarisation images: by default "
        "edge-following superpixels clustered by their polarisation (preset auto); the "
        "thesis's block pipeline with --method thesis (Fresnel normals, spherical "
        "harmonics, PCA, normalized cuts); a pixel classifier trained on painted strokes "
        "with --scribbles.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for command in COMMANDS:
        command.add_parser(sub, specs)
    return parser


def _fail(message: str, code: int) -> int:
    """Print ``polarseg: error: <message>`` (on one line) on stderr; return ``code``."""
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
