"""Slider-to-result times of the napari plugin on the issue-5 reference input.

Opens a real napari viewer (run it under Xvfb: ``xvfb-run -a .venv/bin/python
benchmarks/bench_gui.py``), docks *Segment by material* on the 720 × 660, 19-angle
synthetic leaves stack, turns *live update* on and changes one value at a time as a user
dragging a slider would, timing each change from the value change to the new layers being
shown, minus the widget's live-update debounce (``LIVE_DELAY_MS``). Prints one table
with the issue's targets and, per row, the seconds of the engine's recomputed stages and
of the widget showing the result (layers, plots); the rest is the worker thread and the
Qt event loop. Not part of the test run.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

CACHE = Path("/tmp/napari-polarseg-bench")
TARGETS = {"n_segments": 0.2, "scale": 0.5, "refractive_index": 1.0, "window": 1.0}


def reference_stack(cache: Path) -> tuple[np.ndarray, np.ndarray]:
    """The reference input (the same file ``bench_speed.py`` caches), built if missing."""
    path = cache / "leaves_ref_720x660_19.npz"
    if path.exists():
        with np.load(path, allow_pickle=False) as f:
            return f["stack"], np.asarray(f["angles"], dtype=float)
    from napari_polarseg.engine.synthetic import make_scene

    scene = make_scene("leaves", shape=(720, 660), angles_deg=np.arange(0, 181, 10))
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, stack=scene.stack, angles=scene.angles)
    return scene.stack, scene.angles


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="recommended", choices=["recommended", "thesis"])
    parser.add_argument("--cache", type=Path, default=CACHE)
    args = parser.parse_args(argv)

    import napari
    from qtpy.QtWidgets import QApplication

    from napari_polarseg.widgets.segment import LIVE_DELAY_MS, PRESETS

    stack, angles = reference_stack(args.cache)
    viewer = napari.Viewer(show=True)
    app = QApplication.instance()
    viewer.add_image(stack, name="reference", metadata={"angles_deg": list(np.rad2deg(angles))})
    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")

    # where the time goes: the engine's recomputed stages (from the result) and the
    # widget's _show (layers, plots) of each result
    split: dict[str, float] = {}
    show = widget._show

    def timed_show(layer, angles_deg, result, *args, **kwargs):  # noqa: ANN001, ANN202
        res = getattr(result, "result", None) or result
        split["engine"] = sum(res.timings.get(s, 0.0) for s in res.recomputed)
        t = time.perf_counter()
        try:
            return show(layer, angles_deg, result, *args, **kwargs)
        finally:
            split["show"] = time.perf_counter() - t

    widget._show = timed_show

    def wait() -> float:
        t0 = time.perf_counter()
        while widget.busy or widget._waiting():
            app.processEvents()
            time.sleep(0.002)
        return time.perf_counter() - t0

    widget.set_params(PRESETS[args.preset].replace(n_segments=3))
    t0 = time.perf_counter()
    widget.run_button.clicked.emit()
    wait()
    rows = [("cold run (Run button)", time.perf_counter() - t0, 1.5, dict(split))]
    widget.live.value = True
    base = widget.params()
    changes = [
        ("n_segments", base.n_segments + 1),
        ("scale", base.scale * 1.5),
        ("refractive_index", 1.6),
        ("window", base.window + 2),
    ]
    for name, value in changes:
        t0 = time.perf_counter()
        widget.set_params(**{name: value})
        # the live update starts LIVE_DELAY_MS after the last change (debounce)
        while not (widget.busy or widget._waiting()):
            app.processEvents()
            time.sleep(0.002)
            if time.perf_counter() - t0 > 5:
                break
        wait()
        seconds = time.perf_counter() - t0 - LIVE_DELAY_MS / 1000
        rows.append((f"change {name} -> {value:g}", seconds, TARGETS[name], dict(split)))
    print(f"napari plugin, 720x660x19 reference stack, preset {args.preset}")
    print(f"{'change':<34}| seconds | engine | show  | target | result")
    for label, seconds, target, parts in rows:
        verdict = "met" if seconds <= target else f"MISSED by {seconds - target:.2f} s"
        engine, shown = parts.get("engine", float("nan")), parts.get("show", float("nan"))
        times = f"{seconds:7.3f} | {engine:6.3f} | {shown:5.3f}"
        print(f"{label:<34}| {times} | {target:6.2f} | {verdict}")
    viewer.close()


if __name__ == "__main__":
    main()
