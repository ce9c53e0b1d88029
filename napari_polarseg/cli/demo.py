"""``polarseg demo``: segment a bundled sample scene and report its adjusted Rand index."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import io as pio
from ..engine.errors import PolarsegError
from ..engine.params import DEFAULT_PRESET, ParamSpec
from .arguments import PROG, out_folder_arg
from .options import add_param_options, add_plots_option
from .running import params_from_args, segment_data, status_line

#: Folder of the bundled sample scenes (``<scene>.npz``).
SAMPLE_DIR = Path(__file__).resolve().parents[1] / "sample_data"
DEFAULT_SCENE = "leaves"
DEFAULT_DEMO_OUT = "polarseg-demo"
#: File name ending of a sample scene's bundled strokes (:func:`bundled_strokes`).
STROKES_SUFFIX = "_strokes.tif"


def add_parser(sub: Any, specs: dict[str, ParamSpec] | None = None) -> None:
    """Add the ``demo`` subcommand to ``sub`` (flags of ``specs``, default the table)."""
    demo = sub.add_parser(
        "demo",
        help="segment a bundled sample scene and draw an overview",
        description="Run the segmentation on a bundled sample scene, write the segment "
        "outputs and overview.png, and report the adjusted Rand index against the ground "
        "truth. The number of segments defaults to the ground truth's.",
    )
    demo.add_argument(
        "-o",
        "--out",
        default=DEFAULT_DEMO_OUT,
        metavar="DIR",
        type=out_folder_arg,
        help=f"[./{DEFAULT_DEMO_OUT}]",
    )
    demo.add_argument(
        "--scene",
        default=DEFAULT_SCENE,
        help=f"bundled scene: {', '.join(available_scenes())} [{DEFAULT_SCENE}]",
    )
    demo.add_argument(
        "--sample", metavar="FILE.npz", help="use this .npz (stack, angles, labels) instead"
    )
    demo.add_argument(
        "--scribbles",
        metavar="FILE",
        help="train the pixel classifier on these strokes (a labels image, 0 = unpainted) "
        "instead of the scene's bundled ones",
    )
    demo.add_argument(
        "--unsupervised",
        action="store_true",
        help="segment without strokes (the scene's bundled strokes are used by default "
        "where it has them, unless --preset, --method or --params chooses a method)",
    )
    add_plots_option(demo)
    add_param_options(
        demo,
        specs=specs,
        overview_flag=False,  # the demo always draws overview.png
        default_text={"n_segments": "the scene's number of materials"},
    )
    demo.set_defaults(func=run, overview=True)


def available_scenes(folder: Path | None = None) -> list[str]:
    """Names of the bundled sample scenes (``sample_data/<scene>.npz``)."""
    folder = SAMPLE_DIR if folder is None else folder
    return sorted(p.stem for p in folder.glob("*.npz")) if folder.is_dir() else []


def _sample_path(args: argparse.Namespace) -> Path:
    """The scene file: ``--sample``, else the bundled ``--scene``."""
    if args.sample:
        return Path(args.sample)
    path = SAMPLE_DIR / f"{args.scene}.npz"
    if not path.is_file():
        scenes = ", ".join(available_scenes()) or "none installed"
        raise PolarsegError(f"no bundled sample scene {args.scene!r} (available: {scenes})")
    return path


def bundled_strokes(scene: str, folder: Path | None = None) -> Path | None:
    """The strokes bundled with a sample scene (``sample_data/<scene>_strokes.tif``,
    uint8, 0 = unpainted, k + 1 = material k), or None."""
    path = (SAMPLE_DIR if folder is None else folder) / f"{scene}{STROKES_SUFFIX}"
    return path if path.is_file() else None


def _showcase_strokes(args: argparse.Namespace) -> Path | None:
    """The bundled strokes the demo trains on: those of the ``--scene`` unless the user
    asked for no strokes (``--unsupervised``), gave their own (``--scribbles``), a sample
    file (``--sample``) or a method (``--preset`` other than the default, ``--method``,
    ``--params``)."""
    chose = (
        args.unsupervised
        or args.scribbles
        or args.sample
        or args.preset != DEFAULT_PRESET
        or getattr(args, "method", None) is not None
        or args.params
    )
    return None if chose else bundled_strokes(args.scene)


def _unsupervised_ari(data: pio.StackData, params: Any) -> float:
    """ARI against the ground truth of the default unsupervised method (the comparison
    line of a showcase run)."""
    from sklearn.metrics import adjusted_rand_score

    from ..engine import Scene

    scene = Scene(data.stack, np.deg2rad(data.angles_deg))
    labels = scene.segment(params).labels
    return float(adjusted_rand_score(data.ground_truth.ravel(), labels.ravel()))


def run(args: argparse.Namespace) -> int:
    """Run ``polarseg demo``; return the exit code (0)."""
    path = _sample_path(args)
    strokes = _showcase_strokes(args)
    if strokes is not None:
        args.scribbles = str(strokes)
        print(
            f"{PROG}: demo: the {args.scene} scene's materials differ only in their diffuse "
            "polarisation, where a few painted strokes do best: training the pixel "
            f"classifier on the bundled strokes ({strokes.name}); --unsupervised segments "
            "without them"
        )
    status_line(args).show(f"reading {path.name}")
    t0 = time.perf_counter()
    data = pio.read_stack(path)
    read_seconds = time.perf_counter() - t0
    base = dict(data.metadata.get("params") or {})
    if data.ground_truth is not None and "n_segments" not in base:
        base["n_segments"] = int(np.unique(data.ground_truth).size)
    params = params_from_args(args, base)
    # The bundled scenes are rendered at 0..180 degrees (0 and 180 both, as the thesis
    # captures): one line says so, as `segment` says it of the same file.
    done = segment_data(args, "demo", data, read_seconds, params, {"scene": path.stem})
    if "adjusted_rand_index" in done.summary:
        ari = done.summary["adjusted_rand_index"]
        print(f"{PROG}: adjusted Rand index against the ground truth: {ari:.3f}")
        if strokes is not None:
            plain = _unsupervised_ari(data, params)
            print(f"{PROG}: the unsupervised default (--unsupervised) scores {plain:.3f} here")
    return 0
