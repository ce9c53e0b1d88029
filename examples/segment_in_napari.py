"""Segment an angle stack through the napari plugin's widget, without a visible window.

Opens a stack with the plugin's reader (or the bundled synthetic *leaves* sample), docks
the "Segment by material" widget in a hidden viewer, sets its values, presses Run, waits
for the worker thread and saves the ``segments`` labels layer with the plugin's TIFF
writer. Segment k of the engine is label k + 1 in napari (0 is napari's background).

It starts from the plugin's default, preset ``auto`` (``--preset`` offers every preset of
the plugin's menu). Usage (napari needs an X display and OpenGL; Xvfb provides both on a
headless machine)::

    xvfb-run -a python examples/segment_in_napari.py                      # bundled sample
    xvfb-run -a python examples/segment_in_napari.py examples/data/leaves_stack.tif \\
        --out out/leaves_labels.tif --preset recommended --window 10 --degree 12 --segments 4
    xvfb-run -a python examples/segment_in_napari.py examples/data/leaves_stack.tif \\
        --angles 0,30,60,90,120,150,180 --preset recommended

The same steps work in a notebook or a script with a visible viewer
(``napari.Viewer()`` instead of ``napari.Viewer(show=False)``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from napari_polarseg.engine.params import DEFAULT_PRESET, PRESETS


def build_parser() -> argparse.ArgumentParser:
    """The example's command line; ``--preset`` defaults to the plugin's default."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stack", nargs="?", help="TIFF with angles, .npz or folder of frames")
    parser.add_argument("--angles", help="polariser angles in degrees, e.g. 0,45,90,135")
    parser.add_argument(
        "--out", default="out/labels.tif", help="labels TIFF to write [out/labels.tif]"
    )
    parser.add_argument(
        "--preset",
        choices=list(PRESETS),
        default=DEFAULT_PRESET,
        help=f"starting parameters, as in the plugin's menu (default: {DEFAULT_PRESET})",
    )
    parser.add_argument("--window", type=int, help="block size w in pixels")
    parser.add_argument("--degree", type=int, help="spherical-harmonic degree L")
    parser.add_argument("--refractive-index", type=float, help="refractive index n")
    parser.add_argument("--segments", type=int, help="number of segments")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    import napari  # only now: --help and the parser need no napari

    from napari_polarseg.widgets import SegmentWidget

    viewer = napari.Viewer(show=False)
    try:
        if args.stack:
            (stack,) = viewer.open(args.stack, plugin="napari-polarseg")
        else:
            stack = viewer.open_sample("napari-polarseg", "leaves")[0]
        widget = SegmentWidget(viewer)
        viewer.window.add_dock_widget(widget, name="Segment by material")
        widget.stack_layer.value = stack
        if args.angles:
            widget.angles.value = args.angles
        widget.preset.value = args.preset
        changes = {
            "window": args.window,
            "degree": args.degree,
            "refractive_index": args.refractive_index,
            "n_segments": args.segments,
        }
        widget.set_params(**{k: v for k, v in changes.items() if v is not None})

        widget.run_button.native.click()  # what a user's click does: start the worker
        widget.wait(timeout=None)  # keep the Qt event loop turning until it is done
        if widget.last_error:
            print(f"error: {widget.last_error}", file=sys.stderr)
            return 1
        segments = widget.output("segments")
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        (written,) = segments.save(args.out, plugin="napari-polarseg")
        summary = segments.metadata["polarseg_summary"]
        print(f"{stack.name}: {widget.status.value}")
        print(f"wrote {written} ({summary['n_segments']} segments, labels 1..)")
        return 0
    finally:
        viewer.close()


if __name__ == "__main__":
    raise SystemExit(main())
