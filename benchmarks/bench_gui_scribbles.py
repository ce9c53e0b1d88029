"""Issue 23's figures: the scribble loop on a real camera frame in a fresh napari viewer.

Run by ``bench_gui.py --frame PATH --scribbles [--crop 768x1024]`` under Xvfb. The
frame must have a bundled truth file (``napari_polarseg/sample_data/truth``): the
strokes are a robot user's (``robot_user.py``): one disc per material at the deepest
point of its truth, then each correction one disc of the true class at the deepest
point of the largest wrong region of the labels on screen.

Timed, each from the action to the layers on screen, minus the live-update debounce
(``STROKE_DELAY_MS``, printed; 0 since issue 40) for the painted corrections:

- background features: from *New scribbles layer* (clicked 0.5 s after the dock opened
  on the frame: the polarisation image, computed once the stack is chosen, is ready) to
  the stack's pixel features ready (the worker computes them while the first strokes
  are painted);
- first strokes → labels: the discs of every material set at once (training, then the
  preview: every pixel's labels from the region walk on the 8 px grid's prediction;
  then the final labels: the walk on the 4 px grid and the border cells);
- each correction → labels: the preview's labels and the final ones.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from bench_gui import run_events, widget_idle

#: Issue 23's targets (seconds).
FIRST_TARGET, STROKE_TARGET = 2.0, 0.3
#: Corrections painted one after the other.
CORRECTIONS = 7
#: Idle event loop before each action (the previous result gets drawn).
SETTLE = 0.5


def frame_truth(path: Path, crop: tuple[int, int] | None) -> tuple[np.ndarray, list]:
    """The truth labels of the frame ``path`` (its bundled truth file), cropped, and
    the frame's mosaic layout (degrees) the file names."""
    from napari_polarseg.truth import read_truth_file, truth_files

    for file in truth_files():
        truth = read_truth_file(file)
        if truth.frame == path.name:
            labels = np.asarray(truth.truth)
            labels = labels if crop is None else labels[: crop[0], : crop[1]]
            return labels, list(truth.mosaic)
    raise SystemExit(f"no bundled truth file for {path.name}")


def scribble_frame_main(path: Path, mosaic: tuple[int, ...], crop=None) -> None:  # noqa: ANN001
    """Print the scribble loop's figures on ``path`` (optionally its top-left ``crop``);
    the frame is read with its truth file's mosaic layout (``mosaic`` is not used)."""
    import napari
    from robot_user import deepest_point, disc_radius, initial_scribbles, largest_wrong_region

    from napari_polarseg.io import read_stack
    from napari_polarseg.widgets.segment import STROKE_DELAY_MS

    truth, layout = frame_truth(path, crop)  # the truth file's layout, not ``mosaic``
    data = read_stack(path, mosaic=layout)
    stack = data.stack if crop is None else data.stack[:, : crop[0], : crop[1]]
    viewer = napari.Viewer(show=True)
    viewer.add_image(stack, name=path.stem, metadata={"angles_deg": list(data.angles_deg)})
    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
    shown: dict[str, float] = {}
    show = widget._show

    def timed_show(layer, angles_deg, result, seconds, inputs=None, partial=False, *rest):  # noqa: ANN001, ANN002, ANN202
        t = time.perf_counter()
        show(layer, angles_deg, result, seconds, inputs, partial, *rest)
        now = time.perf_counter()
        shown.setdefault("show", now - t)  # the widget's layers of the first result
        shown.setdefault("first", now)
        if not partial:
            shown["all"] = now
        seg = getattr(result, "segmentation", None)
        if seg is not None:
            shown["engine"] = dict(seg.seconds)

    widget._show = timed_show

    def events(until, timeout: float = 300.0) -> None:  # noqa: ANN001
        run_events(until, timeout)

    def idle() -> bool:
        return widget_idle(widget)

    def measure(action, delay: float) -> tuple[float, float, dict]:  # noqa: ANN001
        events(lambda: False, timeout=SETTLE)
        shown.clear()
        t0 = time.perf_counter()
        action()
        events(lambda: not idle() or time.perf_counter() - t0 > 5)
        events(idle)
        end = shown.get("all", time.perf_counter())
        engine = {**shown.get("engine", {}), "show": shown.get("show", 0.0)}
        return shown.get("first", end) - t0 - delay, end - t0 - delay, engine

    # the user's first look at the frame (SETTLE) before *New scribbles layer*: the
    # polarisation image, computed in the background once the stack is chosen, is ready
    events(lambda: False, timeout=SETTLE)
    t0 = time.perf_counter()
    layer = widget.new_scribbles_layer()
    events(idle)
    features = time.perf_counter() - t0
    widget.live.value = True
    radius = disc_radius(truth.shape)
    first, _ = initial_scribbles(truth, radius)
    rows = [("first strokes -> labels", *measure(lambda: setattr(layer, "data", first), 0))]
    layer.brush_size = 2 * radius + 1
    delay = STROKE_DELAY_MS / 1000
    for n in range(1, CORRECTIONS + 1):
        region = largest_wrong_region(np.asarray(widget.output("segments").data), truth)
        if region is None:
            break
        centre = deepest_point(region)
        value = int(truth[centre])
        row = measure(lambda c=centre, v=value: layer.paint(c, v, refresh=True), delay)
        rows.append((f"correction {n} -> labels", *row))
    h, w = stack.shape[1:]
    print(f"napari plugin, scribble loop on {w} x {h} x {stack.shape[0]} frame {path.name}")
    print(f"pixel features in the background after 'New scribbles layer': {features:.2f} s")
    print("seconds from the action to the labels on screen: 'preview' = every pixel's labels")
    print("from the walk on the 8 px grid, 'all' = the final ones (4 px grid and border")
    print(f"cells); corrections minus the stroke debounce ({STROKE_DELAY_MS} ms)")
    print(f"{'action':<28}| preview |  all   | engine train, preview, predict | show preview")
    for label, first_s, all_s, eng in rows:
        parts = ", ".join(f"{eng.get(k, 0.0):.3f}" for k in ("train", "preview", "predict", "show"))
        print(f"{label:<28}| {first_s:7.3f} | {all_s:6.3f} | {parts}")
    strokes = [r for r in rows if r[0].startswith("correction")]
    if strokes:
        median = float(np.median([r[1] for r in strokes]))
        median_all = float(np.median([r[2] for r in strokes]))
        verdict = "met" if median <= STROKE_TARGET else "MISSED"
        print(
            f"correction -> labels of every pixel on screen: median {median:.3f} s preview, "
            f"{median_all:.3f} s final, of {len(strokes)} (target {STROKE_TARGET} s: "
            f"{verdict})"
        )
    opened = features + rows[0][1]
    verdict = "met" if opened <= FIRST_TARGET else "MISSED"
    print(
        f"first training -> labels on screen: {rows[0][1]:.3f} s preview, {rows[0][2]:.3f} s "
        f"final once the features are computed; {opened:.3f} s from 'New scribbles layer' "
        f"(features + preview; target {FIRST_TARGET} s: {verdict})"
    )
    print(f"status: {widget.status.value}")
    viewer.close()
