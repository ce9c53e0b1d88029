"""Issue 25, plugin items: what a user met in the docks."""

from __future__ import annotations

import numpy as np
from _gui_helpers import PLUGIN_DOCKS as DOCKS
from _gui_helpers import run_and_wait
from napari.layers import Labels

from napari_polarseg.engine.params import AUTO
from napari_polarseg.widgets._layers import layer_tag
from napari_polarseg.widgets.polarisation import polarisation_status


def test_derived_maps_sit_below_segments_and_scribbles(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    segment = add_widget("Segment by material")
    run_and_wait(qtbot, segment)
    scribbles = viewer.add_labels(np.zeros(stack.data.shape[1:], dtype=np.int32), name="strokes")
    polarisation = add_widget("Polarisation image")
    run_and_wait(qtbot, polarisation)
    names = [layer.name for layer in viewer.layers]
    segments = names.index(f"segments ({stack.name})")
    lowest_labels = min(segments, names.index(scribbles.name))
    derived = [
        i
        for i, layer in enumerate(viewer.layers)
        if layer_tag(layer) is not None and not isinstance(layer, Labels)
    ]
    assert len(derived) >= 8  # Î, ρ, φ, θ, S0-S2, the HSV view (and the error map)
    assert max(derived) < lowest_labels, names
    assert names.index(stack.name) < min(derived)  # still above the stack
    assert "90°" in polarisation.status.value or "ρ is above" not in polarisation.status.value


def test_polarisation_status_speaks_to_a_user():
    text = polarisation_status("leaves", 115409, "diffuse")
    assert "115,409 pixels" in text and "zenith is set to 90°" in text
    assert "ceiling" not in text
    assert "ρ is above" not in polarisation_status("leaves", 0, "diffuse")
    assert "ρ is above" not in polarisation_status("leaves", 12, "specular")


def _in_view(widget, dock) -> bool:
    """True when ``widget`` shows on screen, wholly inside ``dock``."""
    if not widget.isVisible() or widget.visibleRegion().isEmpty():
        return False
    top_left = widget.mapTo(dock, widget.rect().topLeft())
    bottom_right = widget.mapTo(dock, widget.rect().bottomRight())
    return dock.rect().contains(top_left) and dock.rect().contains(bottom_right)


def test_run_and_status_stay_in_view_with_every_dock_open(viewer, open_sample, add_widget, qtbot):
    from napari_polarseg.widgets._base import _dock_of

    open_sample("leaves")
    widgets = []
    for name in DOCKS:  # one by one, as from the Plugins menu: each opens as a tab
        widgets.append(add_widget(name))
        qtbot.wait(10)
    window = viewer.window._qt_window
    window.resize(1600, 1000)
    window.show()
    qtbot.wait(50)
    for name, widget in zip(DOCKS, widgets, strict=True):
        widget.status.value = "a status a user reads"
        dock = _dock_of(widget.native)
        dock.raise_()
        qtbot.wait(20)
        for control in (widget.run_button, widget.status):
            assert _in_view(control.native, dock), f"{name}: {control!r} out of view"
    # however short a dock gets, the footer does not scroll away
    segment = widgets[0]
    _dock_of(segment.native).raise_()
    segment.show_advanced.value = True
    window.resize(1600, 600)
    qtbot.wait(50)
    assert segment.scroll_area.verticalScrollBar().maximum() > 0
    assert _in_view(segment.run_button.native, _dock_of(segment.native))


def test_use_best_shows_the_swept_preset_and_values(viewer, open_sample, add_widget, qtbot):
    from _gui_helpers import wait_idle

    open_sample("leaves")
    segment = add_widget("Segment by material", preset=None)
    assert segment.preset.value == "auto" and segment.method.value == AUTO.method
    sweep = add_widget("Parameter sweep")
    assert sweep.source.value == "recommended"
    assert "auto" in sweep.source.native.toolTip()  # says why it is not the default
    sweep.windows.value = "8"
    sweep.degrees.value = "4, 6"
    run_and_wait(qtbot, sweep)
    best = sweep.result.best()
    assert sweep.use_best() is segment
    wait_idle(qtbot, segment)
    assert segment.preset.value == "recommended"
    assert segment.method.value == best.method == "thesis"
    assert (segment.window.value, segment.degree.value) == (8, best.degree)
    assert segment.params() == best


#: Opens every dock, segments (live update on), leaves a live rerun pending and two runs
#: going, closes the viewer, then waits for the worker threads.
EXIT_SCRIPT = """
import time

import napari
from qtpy.QtWidgets import QApplication
from superqt.utils._qthreading import WorkerBase

viewer = napari.Viewer(show=False)
viewer.open_sample("napari-polarseg", "leaves")
widgets = {}
for name in DOCKS:
    _, widgets[name] = viewer.window.add_plugin_dock_widget("napari-polarseg", name)
    QApplication.processEvents()
segment = widgets["Segment by material"]
segment.live.value = True
segment.run()
assert segment.wait(120), "the segmentation did not end"
assert segment.output("segments") is not None
segment.n_segments.value = segment.n_segments.value + 1  # a live rerun on the timer
widgets["Polarisation image"].run()
segment.window.value = 8
segment.run()  # still running when the viewer closes
viewer.close()
deadline = time.monotonic() + 60
while any(getattr(w, "busy", False) for w in widgets.values()):
    assert time.monotonic() < deadline, "a run outlived the viewer"
    QApplication.processEvents()
    time.sleep(0.05)
WorkerBase.await_workers(msecs=30_000)  # raises if a thread still runs
print("closed cleanly")
"""


def test_every_dock_open_then_close_exits_cleanly():
    import os
    import subprocess
    import sys

    script = f"DOCKS = {DOCKS!r}\n{EXIT_SCRIPT}"
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "closed cleanly" in done.stdout
    for bad in ("Traceback", "QThread: Destroyed", "RuntimeError", "Segmentation fault"):
        assert bad not in done.stderr, done.stderr[-3000:]
