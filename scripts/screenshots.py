"""Make the README screenshot of the napari plugin: ``docs/screenshot-viewer.png``.

Opens a real napari window, loads the real polarisation-camera sample (apple,
background, orange), docks and runs both widgets ("Polarisation image", then "Segment by
material" from the recommended preset with energy features and 3 segments), shows the
layers side by side in grid mode and saves a screenshot of the whole window with the
widgets docked.

Usage (needs a display; Xvfb provides one on a headless machine)::

    xvfb-run -a -s "-screen 0 1920x1200x24" .venv/bin/python scripts/screenshots.py
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import napari
from qtpy.QtWidgets import QApplication

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "screenshot-viewer.png"
PLUGIN = "napari-polarseg"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help="PNG to write")
    parser.add_argument("--sample", default="fruits_camera", help="sample key of the plugin")
    parser.add_argument("--size", default="1600x1000", help="window size WIDTHxHEIGHT")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.lower().split("x"))

    from napari._qt import qt_main_window

    qt_main_window.SHOW_QT_WARNING = False  # no "PyQt5 is deprecated" toast in the picture
    viewer = napari.Viewer(show=True, title="napari-polarseg")
    try:
        viewer.window.resize(width, height)
        stack = viewer.open_sample(PLUGIN, args.sample)[0]
        _, polarisation = viewer.window.add_plugin_dock_widget(PLUGIN, "Polarisation image")
        _, segment = viewer.window.add_plugin_dock_widget(
            PLUGIN, "Segment by material", tabify=False
        )
        polarisation.stack_layer.value = stack
        segment.stack_layer.value = stack

        polarisation.run_button.native.click()
        polarisation.wait(timeout=300)
        segment.preset.value = "recommended"
        segment.set_params(features="energy", n_segments=3)
        segment.run_button.native.click()
        segment.wait(timeout=600)
        for widget in (polarisation, segment):
            if widget.last_error:
                print(f"error: {widget.last_error}", file=sys.stderr)
                return 1

        # every layer side by side; the segments over a copy of the intensity image
        for layer in viewer.layers:
            if layer.metadata.get("napari_polarseg", {}).get("role") == "error":
                layer.visible = True
        viewer.layers.selection.active = segment.output("segments")
        viewer.grid.enabled = True
        viewer.grid.stride = 1
        viewer.reset_view()
        for _ in range(20):
            QApplication.processEvents()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        viewer.screenshot(str(args.out), canvas_only=False, flash=False)
        print(f"wrote {args.out} ({segment.status.value})")
        return 0
    finally:
        viewer.close()


if __name__ == "__main__":
    raise SystemExit(main())
