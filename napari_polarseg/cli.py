"""The ``polarseg`` command: segment an angle stack, or run the bundled demo.

::

    polarseg segment INPUT --out DIR [--angles 0,30,60,...] [--mosaic 90,45,135,0]
                         [--register] [--window W] [--degree L] [--refractive-index N]
                         [--segments K] [--params FILE.json] [...]
    polarseg demo [--out DIR] [--scene leaves]

Angles are **degrees** on the command line and in every file (comma-separated, one per
frame, in frame order); the engine gets radians. ``segment`` writes into DIR:

=========================== ==========================================================
``labels.tif``              segment of every pixel (uint16, 0 = first segment)
``intensity.tif``           mean intensity Î (float32, input units)
``dop.tif``                 degree of polarisation ρ (float32, 0..1)
``phase.tif``               phase φ (float32, radians in [0, π))
``zenith.tif``              zenith angle θ (float32, radians in [0, π/2])
``reconstruction_error.tif`` \\|Î − Î rebuilt from the harmonics\\| (float32, input units)
``params.json``             every parameter, the input, its angles, the package version,
                            whether registration ran and its shifts (pixels)
``summary.json``            the run's figures (per-stage seconds, number of segments,
                            explained variance, mean reconstruction error) and the
                            seconds spent reading, registering and writing
=========================== ==========================================================

All images are H × W of the angle stack the engine sees: the input's size, except with
``--mosaic``, where a raw H × W camera frame becomes a stack of H/2 × W/2 frames and so do
the outputs. ``demo`` (and ``segment --overview``) also writes ``overview.png``.

Everything (parameters, reading, registration, the whole pipeline, the figure) is done
before the first file is written, and every file is written atomically, so bad input
never leaves a partial file where a good one was. Exit codes: 0 success, 2 bad input or
usage (one line ``polarseg: error: <message>`` on stderr, no traceback), 1 the outputs
could not be written, 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from . import io as pio
from .engine.errors import PolarsegError
from .engine.params import (
    COEFFICIENT_METHODS,
    FEATURE_KINDS,
    MODELS,
    RECOMMENDED,
    SCALE_MODES,
    SPECULAR_BRANCHES,
    SegmentParams,
)
from .engine.pipeline import Pipeline, SegmentationResult
from .engine.registration import register_stack

PROG = "polarseg"
#: Folder of the bundled sample scenes (``<scene>.npz``).
SAMPLE_DIR = Path(__file__).resolve().parent / "sample_data"
DEFAULT_SCENE = "leaves"
DEFAULT_DEMO_OUT = "polarseg-demo"

#: Output images: file name -> (result attribute, TIFF metadata).
FLOAT_OUTPUTS = {
    "intensity.tif": ("intensity", {"quantity": "mean intensity", "unit": "input units"}),
    "dop.tif": ("dop", {"quantity": "degree of polarisation", "unit": "1"}),
    "phase.tif": ("phase", {"quantity": "phase", "unit": "radians", "range": "[0, pi)"}),
    "zenith.tif": ("zenith", {"quantity": "zenith angle", "unit": "radians"}),
    "reconstruction_error.tif": (
        "reconstruction_error",
        {"quantity": "absolute reconstruction error of the mean intensity", "unit": "input units"},
    ),
}


class UsageError(PolarsegError):
    """A command-line syntax error (reported like any bad input)."""


class OutputError(Exception):
    """The outputs could not be written (exit code 1)."""


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


def _threshold_arg(text: str) -> float | str:
    if text.strip().lower() == "none":
        return "none"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'none', got {text!r}") from None


#: SegmentParams field -> (flag, argparse keywords).
PARAM_OPTIONS: dict[str, tuple[str, dict[str, Any]]] = {
    "window": ("--window", {"type": int, "metavar": "W", "help": "block side w, pixels"}),
    "degree": ("--degree", {"type": int, "metavar": "L", "help": "spherical-harmonic degree"}),
    "refractive_index": (
        "--refractive-index",
        {"type": float, "metavar": "N", "help": "assumed refractive index n > 1"},
    ),
    "n_segments": ("--segments", {"type": int, "metavar": "K", "help": "number of segments"}),
    "model": ("--model", {"choices": MODELS, "help": "Fresnel model for the zenith"}),
    "specular_branch": (
        "--specular-branch",
        {"choices": SPECULAR_BRANCHES, "help": "zenith solution of the specular model"},
    ),
    "coefficients": (
        "--coefficients",
        {"choices": COEFFICIENT_METHODS, "help": "block coefficient estimator"},
    ),
    "ridge": ("--ridge", {"type": float, "help": "ridge penalty of the 'ridge' estimator"}),
    "features": (
        "--features",
        {"choices": FEATURE_KINDS, "help": "block features: all, zonal (m=0) or energies"},
    ),
    "variance": ("--variance", {"type": float, "help": "share of variance the PCA keeps"}),
    "scale": ("--scale", {"type": float, "help": "affinity scale s in exp(-D/s)"}),
    "scale_mode": (
        "--scale-mode",
        {"choices": SCALE_MODES, "help": "s as given, or relative to the median distance"},
    ),
    "spatial_radius": (
        "--spatial-radius",
        {"type": float, "metavar": "R", "help": "spatial term radius in blocks (0: off)"},
    ),
    "spatial_sigma": (
        "--spatial-sigma",
        {"type": float, "metavar": "S", "help": "spatial term width in blocks"},
    ),
    "ncut_threshold": (
        "--ncut-threshold",
        {"type": _threshold_arg, "metavar": "T", "help": "stop splitting above this Ncut"},
    ),
    "min_segment_blocks": (
        "--min-segment-blocks",
        {"type": int, "metavar": "B", "help": "smallest segment, in blocks"},
    ),
}


def _param_options() -> dict[str, tuple[str, dict[str, Any]]]:
    """PARAM_OPTIONS plus a plain option for any SegmentParams field it does not know."""
    options = dict(PARAM_OPTIONS)
    for f in fields(SegmentParams):
        if f.name not in options:
            default = getattr(SegmentParams(), f.name)
            kind = _threshold_arg if default is None else type(default)
            flag = "--" + f.name.replace("_", "-")
            options[f.name] = (flag, {"type": kind, "help": f.name.replace("_", " ")})
    return options


PRESETS = {"thesis": SegmentParams(), "recommended": RECOMMENDED}


def _add_param_options(parser: argparse.ArgumentParser, preset: str = "thesis") -> None:
    defaults = SegmentParams()
    group = parser.add_argument_group(
        "segmentation parameters",
        "start from --preset, then --params, then explicit flags; thesis defaults in brackets",
    )
    group.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=preset,
        help="starting parameters: the thesis defaults, or those that score best on the "
        f"synthetic scenes (README, 'Segmentation quality') [{preset}]",
    )
    group.add_argument(
        "--params",
        metavar="FILE.json",
        help="SegmentParams JSON (or a params.json written by polarseg)",
    )
    for name, (flag, kwargs) in _param_options().items():
        kwargs = dict(kwargs)
        kwargs["help"] = f"{kwargs['help']} [{getattr(defaults, name)}]"
        group.add_argument(flag, dest=name, default=None, **kwargs)
    parser.add_argument(
        "--overview", action="store_true", help="also write overview.png (matplotlib figure)"
    )
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="report stages and warnings on stderr"
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``polarseg`` (errors raise :class:`UsageError`)."""
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
    seg.add_argument("input", metavar="INPUT", help="TIFF, .npz/.npy, folder, or raw frame")
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
        "frame's height and width",
    )
    seg.add_argument(
        "--channel", type=int, metavar="C", help="colour channel to use (default: BT.601 luma)"
    )
    seg.add_argument(
        "--register",
        action="store_true",
        help="align the frames to the first by sub-pixel cross-correlation first",
    )
    _add_param_options(seg)
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
    _add_param_options(demo, preset="recommended")
    demo.set_defaults(func=_cmd_demo, overview=True)
    return parser


# -- parameters -----------------------------------------------------------------------------


def _load_params_file(path: str) -> dict[str, Any]:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise PolarsegError(f"{path}: cannot read the parameters file ({exc.strerror})") from None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise PolarsegError(f"{path}: parameters file is not valid JSON ({exc})") from None
    if isinstance(data, dict) and isinstance(data.get("params"), dict):
        data = data["params"]  # a params.json written by polarseg
    if not isinstance(data, dict):
        raise PolarsegError(f"{path}: parameters file must hold a JSON object")
    return data


def _params_from_args(
    args: argparse.Namespace, base: dict[str, Any] | None = None
) -> SegmentParams:
    """SegmentParams from ``base``, then ``--params``, then explicit flags (validated)."""
    values: dict[str, Any] = PRESETS[getattr(args, "preset", "thesis")].to_dict()
    values.update(base or {})
    source = "parameters"
    if args.params:
        source = args.params
        values.update(_load_params_file(args.params))
    try:
        params = SegmentParams.from_dict(values)
    except PolarsegError as exc:
        raise PolarsegError(f"{source}: {exc}") from None
    except TypeError as exc:
        raise PolarsegError(f"{source}: a parameter has the wrong type ({exc})") from None
    changes = {name: getattr(args, name) for name in _param_options()}
    changes = {k: (None if v == "none" else v) for k, v in changes.items() if v is not None}
    return params.replace(**changes)


# -- running --------------------------------------------------------------------------------


@dataclass
class Run:
    """One segmentation job, everything computed in memory."""

    data: pio.StackData
    params: SegmentParams
    stack: np.ndarray
    result: SegmentationResult
    shifts: np.ndarray | None
    seconds: dict[str, float] = field(default_factory=dict)


def _progress(verbose: bool):
    if not verbose:
        return None

    def report(stage: str, index: int, total: int) -> None:
        print(f"{PROG}: [{index}/{total}] {stage}", file=sys.stderr, flush=True)

    return report


def _segment(data: pio.StackData, params: SegmentParams, register: bool, verbose: bool) -> Run:
    seconds: dict[str, float] = {}
    stack, shifts = data.stack, None
    if register:
        t0 = time.perf_counter()
        stack, shifts = register_stack(stack)
        seconds["register"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = Pipeline(stack, data.angles_rad, params).run(progress=_progress(verbose))
    seconds["segment"] = time.perf_counter() - t0
    return Run(data, params, stack, result, shifts, seconds)


def _labels_image(labels: np.ndarray) -> np.ndarray:
    dtype = np.uint16 if labels.max(initial=0) < 2**16 else np.uint32
    return labels.astype(dtype)


def _run_info(run: Run, command: str, args: argparse.Namespace) -> dict[str, Any]:
    data = run.data
    return {
        "polarseg_version": __version__,
        "command": command,
        "input": str(Path(data.source).resolve()),
        "input_format": data.metadata.get("format"),
        "input_files": data.metadata.get("files"),
        "stack_shape": list(run.stack.shape),
        "output_shape": list(run.result.labels.shape),
        "angles_deg": data.angles_deg.tolist(),
        "angles_from": data.metadata.get("angles_from"),
        "mosaic_layout_deg": data.metadata.get("mosaic_layout_deg"),
        "raw_shape": data.metadata.get("raw_shape"),
        "channel": getattr(args, "channel", None),
        "registration": {
            "ran": run.shifts is not None,
            "reference_frame": 0 if run.shifts is not None else None,
            "shifts_px": None if run.shifts is None else run.shifts.tolist(),
        },
        "params": run.params.to_dict(),
    }


def _write_outputs(
    out: Path, run: Run, info: dict[str, Any], summary: dict[str, Any], overview: np.ndarray | None
) -> list[str]:
    """Write every output file atomically; returns their names. Raises OutputError."""
    t0 = time.perf_counter()
    written: list[str] = []
    name = str(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        name = str(out / "labels.tif")
        pio.write_tiff(
            out / "labels.tif",
            _labels_image(run.result.labels),
            {"quantity": "segment labels", "first_label": 0},
        )
        written.append("labels.tif")
        for fname, (attr, meta) in FLOAT_OUTPUTS.items():
            name = str(out / fname)
            pio.write_tiff(out / fname, np.asarray(getattr(run.result, attr), np.float32), meta)
            written.append(fname)
        if overview is not None:
            name = str(out / "overview.png")
            pio.write_png(out / "overview.png", overview)
            written.append("overview.png")
        name = str(out / "params.json")
        pio.write_json(out / "params.json", info)
        written.append("params.json")
        summary["io_seconds"]["write"] = round(time.perf_counter() - t0, 6)
        name = str(out / "summary.json")
        pio.write_json(out / "summary.json", summary)
        written.append("summary.json")
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputError(f"cannot write {name}: {reason}") from exc
    return written


def _summary(run: Run, read_seconds: float) -> dict[str, Any]:
    summary = run.result.summary()
    summary["io_seconds"] = {
        "read": round(read_seconds, 6),
        "register": round(run.seconds.get("register", 0.0), 6),
    }
    summary["segment_seconds"] = round(run.seconds["segment"], 6)
    summary["output_shape"] = list(run.result.labels.shape)
    return summary


def _report(out: Path, run: Run, written: list[str]) -> None:
    result = run.result
    err = result.mean_reconstruction_error
    err_text = "n/a" if err is None else f"{err:.4g}"
    h, w = result.labels.shape
    print(
        f"{PROG}: {result.n_segments} segments over {h} x {w} pixels, "
        f"mean reconstruction error {err_text}"
    )
    print(f"{PROG}: wrote {', '.join(written)} to {out}")


def _job(
    args: argparse.Namespace,
    command: str,
    data: pio.StackData,
    read_seconds: float,
    params: SegmentParams,
    register: bool,
    extra: dict[str, Any] | None = None,
) -> tuple[Run, dict[str, Any]]:
    """Segment, render and write: everything is computed before the first file is written."""
    run = _segment(data, params, register, args.verbose)
    summary = {**_summary(run, read_seconds), **(extra or {})}
    if data.ground_truth is not None:
        summary["adjusted_rand_index"] = adjusted_rand_index(data.ground_truth, run.result.labels)
    overview = render_overview(run.stack[0], run.result) if args.overview else None
    out = Path(args.out)
    written = _write_outputs(out, run, _run_info(run, command, args), summary, overview)
    _report(out, run, written)
    return run, summary


def _cmd_segment(args: argparse.Namespace) -> int:
    params = _params_from_args(args)
    t0 = time.perf_counter()
    data = pio.read_stack(
        args.input, angles_deg=args.angles, mosaic=args.mosaic, channel=args.channel
    )
    _job(args, "segment", data, time.perf_counter() - t0, params, args.register)
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
    t0 = time.perf_counter()
    data = pio.read_stack(path)
    read_seconds = time.perf_counter() - t0
    base = dict(data.metadata.get("params") or {})
    if data.ground_truth is not None and "n_segments" not in base:
        base["n_segments"] = int(np.unique(data.ground_truth).size)
    params = _params_from_args(args, base)
    _, summary = _job(args, "demo", data, read_seconds, params, False, {"scene": path.stem})
    if "adjusted_rand_index" in summary:
        ari = summary["adjusted_rand_index"]
        print(f"{PROG}: adjusted Rand index against the ground truth: {ari:.3f}")
    return 0


def adjusted_rand_index(truth: np.ndarray, labels: np.ndarray) -> float:
    """Adjusted Rand index of two labellings of the same pixels (1 = identical partition)."""
    from sklearn.metrics import adjusted_rand_score

    truth, labels = np.asarray(truth), np.asarray(labels)
    if truth.shape != labels.shape:
        raise PolarsegError(f"ground truth is {truth.shape} but the labels are {labels.shape}")
    return float(adjusted_rand_score(truth.ravel(), labels.ravel()))


# -- overview figure ------------------------------------------------------------------------


def render_overview(first_frame: np.ndarray, result: SegmentationResult) -> np.ndarray:
    """Draw input, Î, ρ, φ, segments and reconstruction error side by side.

    Uses matplotlib's object-oriented API on an Agg canvas (no pyplot, so no global
    backend is switched and no window opens).

    Parameters
    ----------
    first_frame : array (H, W)
        First frame of the angle stack.
    result : SegmentationResult
        The pipeline's result.

    Returns
    -------
    ndarray (rows, columns, 4) uint8
        The RGBA figure, ready for :func:`napari_polarseg.io.write_png`.
    """
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    k = max(result.n_segments, 1)
    base = "tab10" if k <= 10 else "tab20"
    seg_cmap = ListedColormap(colormaps[base](np.arange(k) % colormaps[base].N))
    error = result.reconstruction_error
    error = np.zeros_like(result.intensity) if error is None else error
    finite_err = error[np.isfinite(error)]
    err_max = float(np.percentile(finite_err, 99)) if finite_err.size else 1.0
    panels = [
        ("input (first frame)", first_frame, "gray", None, None),
        ("Î mean intensity", result.intensity, "gray", None, None),
        ("ρ degree of polarisation", result.dop, "viridis", 0.0, None),
        ("φ phase (rad)", result.phase, "twilight", 0.0, np.pi),
        (f"segments ({result.n_segments})", result.labels, seg_cmap, -0.5, k - 0.5),
        ("reconstruction error", error, "magma", 0.0, err_max or None),
    ]
    h, w = result.labels.shape
    panel_w = 3.2
    fig = Figure(figsize=(panel_w * len(panels), panel_w * h / w + 0.8), dpi=100)
    canvas = FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels))
    for ax, (title, image, cmap, vmin, vmax) in zip(axes, panels, strict=True):
        shown = ax.imshow(
            np.asarray(image, dtype=float), cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest"
        )
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
        bar = fig.colorbar(shown, ax=ax, fraction=0.046, pad=0.02)
        if cmap is seg_cmap:
            bar.set_ticks(np.arange(k) if k <= 12 else np.linspace(0, k - 1, 5).round())
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba()).copy()


# -- entry point ----------------------------------------------------------------------------


def _fail(message: str, code: int) -> int:
    text = " ".join(str(message).split())
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``polarseg`` with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            code = args.func(args)
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
