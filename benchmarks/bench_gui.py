"""Slider-to-result and stroke-to-result times of the napari plugin on the issue-5
reference input.

Opens a real napari viewer (run it under Xvfb: ``xvfb-run -a .venv/bin/python
benchmarks/bench_gui.py``), docks *Segment by material* on the 720 × 660, 19-angle
synthetic leaves stack, turns *live update* on and changes one value at a time as a user
dragging a slider would, timing each change from the value change to the new layers being
shown, minus the widget's live-update debounce (``LIVE_DELAY_MS``). Then the scribble
mode (issue 12): strokes of every material set into a new scribbles layer (the pixel
features are computed once), and single brush strokes painted one after the other, each
timed from the end of the stroke to the updated segments (the pixel classifier retrained
on the kept features and predicted again; target ≤ 1 s). Prints one table with the
issues' targets and, per row, the seconds of the engine's recomputed stages and of the
widget showing the result (layers, plots); the rest is the worker thread and the Qt event
loop. Not part of the test run.

With ``--frame PATH`` (a camera frame, e.g. a 1224 × 1024 polarisation mosaic read with
``--mosaic 90,45,135,0``) it times the default preset (the superpixel method) in a fresh
viewer instead: segments k → k + 1 and a change of parameters the method does not read
(refractive index, window), each from the change to the labels on screen, split into the
engine's stages and the widget's own time (its overhead). With ``--frame PATH
--scribbles`` (a hand-labelled real frame, e.g. ``fruits_IMX250MZR.png``) it times the
scribble loop there instead (``bench_gui_scribbles.py``, issue 23): the pixel features
computed in the background once a scribbles layer is made, the first strokes → labels
on screen (target 2 s) and painted corrections → labels on screen (target median 0.3 s).

With ``--first PATH`` (a raw camera frame) it times the GUI thread while the first
results appear (issue 25, :func:`first_result_main`): the longest stall of the event
loop, the widget's handlers, contrast limits on the GUI thread and napari's layer
additions; then opening the *Polarisation plots* dock and its histograms.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

CACHE = Path("/tmp/napari-polarseg-bench")
#: Seconds of idle event loop before each change (the previous result gets drawn).
SETTLE = 0.5
TARGETS = {"n_segments": 0.2, "scale": 0.5, "refractive_index": 1.0, "window": 1.0}
#: Issue 22: targets of the default method on a camera frame (--frame).
FRAME_TARGETS = {"n_segments": 0.3, "refractive_index": 0.05, "window": 0.05}
#: Issue 12: a painted stroke to the updated segments on the reference stack.
STROKE_TARGET = 1.0
#: Strokes per material of the first scribbles, and their length (pixels).
FIRST_STROKES, STROKE_LENGTH = 6, 48
#: Brush strokes painted one at a time after the first scribbles, and the brush size.
STROKES, BRUSH_SIZE = 3, 5


def run_events(
    until: Callable[[], bool],
    timeout: float,
    interval_ms: int = 2,
    ticks: list[float] | None = None,
) -> None:
    """Turn the Qt event loop (idle in between, as in a running napari) until ``until()``
    or ``timeout`` seconds; ``ticks`` gets the time of every timer tick (the longest gap
    is the GUI's stall)."""
    from qtpy.QtCore import QEventLoop, QTimer

    loop, timer = QEventLoop(), QTimer()
    deadline = time.perf_counter() + timeout

    def tick() -> None:
        now = time.perf_counter()
        if ticks is not None:
            ticks.append(now)
        if until() or now > deadline:
            loop.quit()

    timer.setInterval(interval_ms)
    timer.timeout.connect(tick)
    timer.start()
    loop.exec()
    timer.stop()


def widget_idle(widget) -> bool:  # noqa: ANN001
    """Whether the Segment widget has nothing running or pending."""
    return not (widget.busy or widget._waiting())


def reference_stack(cache: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference input and its true materials (the file ``bench_speed.py`` caches),
    built if missing (or written by an older version of this script, without labels)."""
    path = cache / "leaves_ref_720x660_19.npz"
    if path.exists():
        with np.load(path, allow_pickle=False) as f:
            if "labels" in f.files:
                return f["stack"], np.asarray(f["angles"], dtype=float), f["labels"]
    from napari_polarseg.engine.synthetic.scenes import make_scene

    scene = make_scene("leaves", shape=(720, 660), angles_deg=np.arange(0, 181, 10))
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, stack=scene.stack, angles=scene.angles, labels=scene.labels)
    return scene.stack, scene.angles, scene.labels


def brush_strokes(labels: np.ndarray, seed: int) -> list[tuple[int, np.ndarray]]:
    """One stroke per material (scribble value, (n, 2) pixel positions along it), drawn
    by ``synthetic.scribble_strokes``; painted with a brush of ``BRUSH_SIZE``."""
    from napari_polarseg.engine.synthetic.scenes import scribble_strokes

    line = scribble_strokes(labels, seed=seed, per_material=1, length=STROKE_LENGTH)
    return [(int(v), np.argwhere(line == v)) for v in np.unique(line) if v > 0]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="recommended", choices=["recommended", "thesis"])
    parser.add_argument("--cache", type=Path, default=CACHE)
    parser.add_argument("--stages", action="store_true", help="print the seconds per stage")
    parser.add_argument("--frame", type=Path, help="time the default preset on this frame")
    parser.add_argument("--mosaic", default="90,45,135,0", help="the frame's mosaic angles")
    parser.add_argument(
        "--first",
        type=Path,
        help="time the GUI thread while the first result of this frame is shown (and the "
        "Polarisation image of it), then the Polarisation plots dock",
    )
    parser.add_argument(
        "--scribbles",
        action="store_true",
        help="with --frame: time the scribble loop (first strokes, then corrections)",
    )
    parser.add_argument(
        "--crop", help="with --frame: use the top-left HxW of the frame, e.g. 768x1024"
    )
    args = parser.parse_args(argv)
    if args.first is not None:
        first_result_main(args.first, tuple(int(a) for a in args.mosaic.split(",")))
        return
    if args.frame is not None:
        mosaic = tuple(int(a) for a in args.mosaic.split(","))
        if args.scribbles:
            from bench_gui_scribbles import scribble_frame_main

            crop = None if not args.crop else tuple(int(v) for v in args.crop.split("x"))
            scribble_frame_main(args.frame, mosaic, crop)
        else:
            frame_main(args.frame, mosaic)
        return

    import napari

    from napari_polarseg.widgets.segment import LIVE_DELAY_MS, PRESETS

    stack, angles, labels = reference_stack(args.cache)
    viewer = napari.Viewer(show=True)
    viewer.add_image(stack, name="reference", metadata={"angles_deg": list(np.rad2deg(angles))})
    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")

    # where the time goes: the engine's recomputed stages (from the result) and the
    # widget's _show (layers, plots) of each result; ``shown`` records when the segments
    # (a partial result, before the error map) and the whole result were on screen
    split: dict[str, float] = {}
    shown: dict[str, float] = {}
    show = widget._show

    def timed_show(layer, angles_deg, result, seconds, inputs=None, partial=False, *rest):  # noqa: ANN001, ANN002, ANN202
        res = getattr(result, "result", None) or result
        t = time.perf_counter()
        try:
            return show(layer, angles_deg, result, seconds, inputs, partial, *rest)
        finally:
            now = time.perf_counter()
            shown.setdefault("segments", now)
            if not partial:
                shown["all"] = now
                split["engine"] = sum(res.timings.get(s, 0.0) for s in set(res.recomputed))
                split["stages"] = {s: res.timings.get(s, 0.0) for s in res.recomputed}
                seg = getattr(result, "segmentation", None)  # the pixel classifier's
                if seg is not None:
                    split["stages"].update({f"  {k}": v for k, v in seg.seconds.items()})
            split["show"] = split.get("show", 0.0) + now - t

    widget._show = timed_show
    later = widget._later._next

    def timed_later() -> None:  # the layers added in later event-loop turns
        t = time.perf_counter()
        later()
        now = time.perf_counter()
        shown["all"] = max(shown.get("all", now), now)
        split["show"] = split.get("show", 0.0) + now - t

    widget._later._timer.timeout.disconnect()
    widget._later._timer.timeout.connect(timed_later)

    ticks: list[float] = []  # times of a 5 ms timer: the longest gap is the GUI's stall

    def events(until, timeout: float = 60.0) -> None:  # noqa: ANN001
        run_events(until, timeout, 5, ticks)

    def idle() -> bool:
        return widget_idle(widget)

    def measure(action) -> tuple[float, float, dict]:  # noqa: ANN001
        # let the canvas draw the previous result first, as it has when a user moves on
        events(lambda: False, timeout=SETTLE)
        split.clear()
        shown.clear()
        t0 = time.perf_counter()
        action()
        ticks[:] = [time.perf_counter()]
        # a live update starts LIVE_DELAY_MS after the last change (debounce)
        events(lambda: not idle() or time.perf_counter() - t0 > 5)
        events(idle)
        split["stall"] = float(np.diff(ticks).max()) if len(ticks) > 1 else 0.0
        delay = 0.0 if widget.live.value is False else LIVE_DELAY_MS / 1000
        end = shown.get("all", time.perf_counter())
        return shown.get("segments", end) - t0 - delay, end - t0 - delay, dict(split)

    widget.set_params(PRESETS[args.preset].replace(n_segments=3))
    seg, total, parts = measure(widget.run_button.clicked.emit)
    rows = [("cold run (Run button)", seg, total, 1.5, parts)]
    widget.live.value = True
    events(idle)
    base = widget.params()
    changes = [
        ("n_segments", base.n_segments + 1),
        ("scale", base.scale * 1.5),
        ("refractive_index", 1.6),
        ("window", base.window + 2),
    ]
    for name, value in changes:
        seg, total, parts = measure(lambda: widget.set_params(**{name: value}))  # noqa: B023
        rows.append((f"change {name} -> {value:g}", seg, total, TARGETS[name], parts))

    # scribble mode: first strokes of every material (pixel features computed once) ...
    from napari_polarseg.engine.synthetic.scenes import scribble_strokes

    scribbles = widget.new_scribbles_layer()
    events(idle)
    first = scribble_strokes(labels, seed=0, per_material=FIRST_STROKES, length=STROKE_LENGTH)
    seg, total, parts = measure(lambda: setattr(scribbles, "data", first))
    rows.append((f"first strokes ({np.count_nonzero(first)} px)", seg, total, None, parts))
    # ... then brush strokes one at a time, each retraining on the kept features
    scribbles.brush_size = BRUSH_SIZE
    painted = 0
    for value, points in brush_strokes(labels, seed=1):
        if painted == STROKES:
            break

        def stroke(value: int = value, points: np.ndarray = points) -> None:
            for i, (r, c) in enumerate(points):
                scribbles.paint((int(r), int(c)), value, refresh=i == len(points) - 1)

        seg, total, parts = measure(stroke)
        painted += 1
        label = f"painted stroke {painted} -> segments"
        rows.append((label, seg, total, STROKE_TARGET, parts))
    if widget.status.value.startswith(("error", "scribbles:")):
        print(f"the scribble runs failed: {widget.status.value}")
    print(f"napari plugin, 720x660x19 reference stack, preset {args.preset}")
    print("seconds from the change to the segments shown / to every layer (error map too);")
    print("engine: its recomputed stages; show: adding/updating layers; stall: the longest")
    print("the Qt event loop went without running (a 5 ms timer), i.e. the GUI's freeze")
    print(f"{'change':<32}| segments |  all  | engine | show  | stall | target | result")
    for label, seg, total, target, parts in rows:
        if target is None:
            verdict = "no target"
        elif total <= target:
            verdict = "met"
        elif seg <= target:
            verdict = f"segments met; error map {total - target:.2f} s later"
        else:
            verdict = f"MISSED by {seg - target:.2f} s"
        engine, shown_s = parts.get("engine", float("nan")), parts.get("show", float("nan"))
        stall = parts.get("stall", float("nan"))
        times = f"{seg:8.3f} | {total:5.3f} | {engine:6.3f} | {shown_s:5.3f} | {stall:5.3f}"
        goal = "     —" if target is None else f"{target:6.2f}"
        print(f"{label:<32}| {times} | {goal} | {verdict}")
    strokes = [seg for label, seg, *_ in rows if label.startswith("painted stroke")]
    if strokes:
        median = float(np.median(strokes))
        verdict = "met" if median <= STROKE_TARGET else f"MISSED by {median - STROKE_TARGET:.2f} s"
        print(
            f"painted stroke -> updated segments: median {median:.3f} s of {len(strokes)} "
            f"strokes (target {STROKE_TARGET:.1f} s: {verdict})"
        )
    if args.stages:
        for label, *_, parts in rows:
            stages = ", ".join(f"{k} {v:.3f}" for k, v in parts.get("stages", {}).items())
            print(f"  {label}: {stages}")
    viewer.close()


def frame_main(path: Path, mosaic: tuple[int, ...]) -> None:
    """Issue 22's figures: the default preset on a camera frame in a fresh viewer."""
    import napari

    from napari_polarseg.io import read_stack
    from napari_polarseg.widgets.segment import LIVE_DELAY_MS

    data = read_stack(path, mosaic=mosaic)
    viewer = napari.Viewer(show=True)
    meta = {"angles_deg": [float(a) for a in data.angles_deg]}
    viewer.add_image(data.stack, name=path.stem, metadata=meta)
    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
    done: dict[str, float] = {}
    engine: dict[str, float] = {}
    show = widget._show

    def timed_show(layer, angles_deg, result, seconds, inputs=None, partial=False, *rest):  # noqa: ANN001, ANN002, ANN202
        t = time.perf_counter()
        show(layer, angles_deg, result, seconds, inputs, partial, *rest)
        done["shown"], done["show"] = time.perf_counter(), time.perf_counter() - t
        res = getattr(result, "result", None) or result
        engine.update({s: res.timings.get(s, 0.0) for s in set(res.recomputed)})

    widget._show = timed_show
    reshow = widget._reshow

    def timed_reshow(layer, snap):  # noqa: ANN001, ANN202
        t = time.perf_counter()
        again = reshow(layer, snap)
        if again:  # nothing recomputed: the re-show is the widget's whole work
            done["shown"], done["show"] = time.perf_counter(), time.perf_counter() - t
        return again

    widget._reshow = timed_reshow

    def events(until, timeout: float = 120.0) -> None:  # noqa: ANN001
        run_events(until, timeout)

    def idle() -> bool:
        return widget_idle(widget)

    def measure(action, live: bool = True):  # noqa: ANN001, ANN202
        events(lambda: False, timeout=SETTLE)
        done.clear()
        engine.clear()
        t0 = time.perf_counter()
        action()
        events(lambda: not idle() or time.perf_counter() - t0 > 5)
        events(idle)
        end = done.get("shown", time.perf_counter())
        return (
            end - t0 - (LIVE_DELAY_MS / 1000 if live else 0.0),
            dict(engine),
            done.get("show", 0.0),
        )

    rows = [("cold run (Run button)", *measure(widget.run_button.clicked.emit, live=False), None)]
    widget.live.value = True
    events(idle)
    base = widget.params()
    for name, value in (
        ("n_segments", base.n_segments + 1),
        ("refractive_index", 1.6),
        ("window", base.window + 2),
    ):
        row = measure(lambda: widget.set_params(**{name: value}))  # noqa: B023
        rows.append((f"change {name} -> {value:g}", *row, FRAME_TARGETS[name]))
    h, w = data.stack.shape[1:]
    print(f"napari plugin, {w} x {h} x {data.stack.shape[0]} frame {path.name}, preset auto")
    print("seconds from the change to the segments on screen (minus the live debounce);")
    print("engine: the stages the run computed; widget: the rest (worker, Qt, layers);")
    print("show: the widget's layers and status (or its re-show of an unchanged result);")
    print("the debounce timer may fire a few ms early: a re-show can come out below 0")
    print(f"{'change':<30}| segments | engine | widget | show  | target | result")
    for label, total, stages, shown_s, target in rows:
        eng = sum(stages.values())
        verdict = "—" if target is None else ("met" if total <= target else "MISSED")
        goal = "     —" if target is None else f"{target:6.2f}"
        print(
            f"{label:<30}| {total:8.3f} | {eng:6.3f} | {total - eng:6.3f} | {shown_s:5.3f} | "
            f"{goal} | {verdict}"
        )
        if stages:
            print("    " + ", ".join(f"{k} {v:.3f}" for k, v in stages.items()))
    print(f"status: {widget.status.value}")
    viewer.close()


#: Issue 25: the longest the GUI thread may stay busy when a first result is shown.
FREEZE_TARGET = 0.3


def first_result_main(path: Path, mosaic: tuple[int, ...]) -> None:
    """Issue 25's figures: how long the window freezes while the first result of a camera
    frame appears (presets auto and thesis, then *Polarisation image ▸ Compute*), and the
    *Polarisation plots* dock (opening it, its histograms), in a fresh viewer.

    "freeze" is the longest the Qt event loop went without running (a 2 ms timer) from
    the result's arrival on the GUI thread to 2 s after: the widget's own work (adding
    the layers) and napari drawing them. "show" is the widget's handlers (each queued
    layer too), "limits" its time in contrast limits on the GUI thread (0 when the worker computed
    them), "add" napari's add_image/add_labels.
    """
    import threading

    import napari

    import napari_polarseg.widgets._layers as layers_module
    from napari_polarseg.io import read_stack

    data = read_stack(path, mosaic=mosaic)
    viewer = napari.Viewer(show=True)
    viewer.window._qt_window.resize(1600, 1000)
    meta = {"angles_deg": [float(a) for a in data.angles_deg]}
    ticks: list[float] = []
    spent: dict[str, float] = {"limits": 0.0, "add": 0.0, "show": 0.0}
    marks: dict[str, float] = {}

    def timed(name: str, func):  # noqa: ANN001, ANN202
        """``func`` timed into ``spent[name]`` when it runs on the GUI thread."""

        def wrapper(*a, **k):  # noqa: ANN002, ANN003, ANN202
            t = time.perf_counter()
            try:
                return func(*a, **k)
            finally:
                if threading.current_thread() is threading.main_thread():
                    spent[name] += time.perf_counter() - t

        return wrapper

    layers_module.contrast_for = timed("limits", layers_module.contrast_for)
    viewer_class = type(viewer)  # a pydantic model: its instances take no new attributes
    viewer_class.add_image = timed("add", viewer_class.add_image)
    viewer_class.add_labels = timed("add", viewer_class.add_labels)

    def events(until, timeout: float = 600.0) -> None:  # noqa: ANN001
        run_events(until, timeout, 2, ticks)

    def freeze() -> float:
        """The longest gap between ticks from the first shown result on."""
        start = marks.get("shown", ticks[-1])
        times = [start] + [t for t in ticks if t > start]
        return float(np.diff(times).max()) if len(times) > 1 else 0.0

    def watch(widget, handler: str, count: bool = True) -> None:  # noqa: ANN001
        """Mark the first call of ``handler`` as the result's arrival (and time it with
        ``count``), and time every layer the widget adds in later event-loop turns."""
        original = getattr(widget, handler)

        def wrapper(*a, **k):  # noqa: ANN002, ANN003, ANN202
            marks.setdefault("shown", time.perf_counter())
            t = time.perf_counter()
            try:
                return original(*a, **k)
            finally:
                spent["show"] += (time.perf_counter() - t) if count else 0.0

        setattr(widget, handler, wrapper)
        queue = widget._later  # the layers it adds one per event-loop turn

        def queued() -> None:
            t = time.perf_counter()
            try:
                queue._next()
            finally:
                spent["show"] += time.perf_counter() - t

        queue._timer.timeout.disconnect()
        queue._timer.timeout.connect(queued)

    rows = []

    def measure(label: str, widget, start) -> None:  # noqa: ANN001
        events(lambda: False, timeout=SETTLE)
        for key in spent:
            spent[key] = 0.0
        marks.clear()
        t0 = time.perf_counter()
        start()
        events(lambda: widget_idle(widget) and "shown" in marks)
        events(lambda: False, timeout=2.0)  # napari draws the new layers
        rows.append((label, time.perf_counter() - t0 - 2.0, freeze(), dict(spent)))

    viewer.add_image(data.stack, name=path.stem, metadata=meta)
    _, seg = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
    watch(seg, "_show")
    measure("Segment, preset auto (first result)", seg, seg.run)
    seg.preset.value = "thesis"
    measure("Segment, preset thesis (error map)", seg, seg.run)
    _, pol = viewer.window.add_plugin_dock_widget("napari-polarseg", "Polarisation image")
    watch(pol, "_show_role", count=False)  # a queued layer: timed as such
    measure("Polarisation image, Compute", pol, pol.run)

    # the plots dock: opening it (matplotlib imported in the background meanwhile),
    # loading the segmentation (cached), the histograms (a worker) and drawing them
    events(lambda: False, timeout=SETTLE)
    t0 = time.perf_counter()
    _, plots = viewer.window.add_plugin_dock_widget("napari-polarseg", "Polarisation plots")
    opened = time.perf_counter() - t0
    plots.run()
    events(lambda: not plots.busy)
    ticks.clear()
    t0 = time.perf_counter()
    plots.plot.value = "histograms"
    events(lambda: not plots.busy)
    histograms = time.perf_counter() - t0
    stall = float(np.diff(ticks).max()) if len(ticks) > 1 else 0.0
    h, w = data.stack.shape[1:]
    print(f"napari plugin, {w} x {h} x {data.stack.shape[0]} frame {path.name}")
    print("seconds: total from the click to the result shown (the run included); freeze:")
    print("the longest the event loop stalled from the result's arrival on (2 ms timer);")
    print("show: the widget's handler; limits: contrast limits on the GUI thread; add:")
    print("napari's add_image/add_labels")
    print(f"{'run':<38}| total  | freeze | show  | limits | add   | target {FREEZE_TARGET}")
    for label, total, stall_s, parts in rows:
        verdict = "met" if stall_s <= FREEZE_TARGET else "MISSED"
        print(
            f"{label:<38}| {total:6.2f} | {stall_s:6.3f} | {parts['show']:5.3f} | "
            f"{parts['limits']:6.3f} | {parts['add']:5.3f} | {verdict}"
        )
    print(f"Polarisation plots: dock opened in {opened:.3f} s; histograms {histograms:.2f} s")
    print(f"  (a worker; the event loop's longest stall meanwhile {stall:.3f} s)")
    viewer.close()


if __name__ == "__main__":
    main()
