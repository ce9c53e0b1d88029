"""Segment an angle stack through the napari plugin's widget, without a visible window.

Opens a stack with the plugin's reader (or the bundled synthetic *leaves* sample), docks
the "Segment by material" widget in a hidden viewer, sets its values, presses Run, waits
for the worker thread and saves the ``segments`` labels layer with the plugin's TIFF
writer. Segment k of the engine is label k + 1 in napari (0 is napari's background).

Usage (napari needs an X display and OpenGL; Xvfb provides both on a headless machine)::

    xvfb-run -a python examples/segment_in_napari.py                      # bundled sample
    xvfb-run -a python examples/segment_in_napari.py stack.tif --out labels.tif \\
        --window 10 --degree 12 --segments 4
    xvfb-run -a python examples/segment_in_napari.py frames/ --angles 0,45,90,135

The same steps work in a notebook or a script with a visible viewer
(``napari.Viewer()`` instead of ``napari.Viewer(show=False)``).
"""

from __future__ import annotations

import argparse
import sys

import napari

from napari_polarseg.widgets import SegmentWidget


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stack", nargs="?", help="TIFF with angles, .npz or folder of frames")
    parser.add_argument("--angles", help="polariser angles in degrees, e.g. 0,45,90,135")
    parser.add_argument("--out", default="labels.tif", help="labels TIFF to write")
    parser.add_argument("--preset", choices=["thesis", "recommended"], default="thesis")
    parser.add_argument("--window", type=int, help="block size w in pixels")
    parser.add_argument("--degree", type=int, help="spherical-harmonic degree L")
    parser.add_argument("--refractive-index", type=float, help="refractive index n")
    parser.add_argument("--segments", type=int, help="number of segments")
    args = parser.parse_args(argv)

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
        (written,) = segments.save(args.out, plugin="napari-polarseg")
        summary = segments.metadata["polarseg_summary"]
        print(f"{stack.name}: {widget.status.value}")
        print(f"wrote {written} ({summary['n_segments']} segments, labels 1..)")
        return 0
    finally:
        viewer.close()


if __name__ == "__main__":
    raise SystemExit(main())
