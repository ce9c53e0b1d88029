"""Issue 25, the Polarisation plots dock: the status line says what the canvas shows,
progress reads done after a cached result, component maps go below the segments and
scribbles, and matplotlib is imported before the dock opens."""

from __future__ import annotations

import numpy as np
from _gui_helpers import click, run_and_wait, wait_idle
from napari.layers import Labels

FAST = {"window": 10, "degree": 5, "n_segments": 3}


def test_status_follows_the_plot_and_progress_reads_done(viewer, open_sample, add_widget, qtbot):
    open_sample("leaves")
    segment = add_widget("Segment by material")
    segment.set_params(**FAST)
    run_and_wait(qtbot, segment)
    plots = add_widget("Polarisation plots")
    assert plots.progress.value == 0
    click(qtbot, plots.run_button)
    assert not plots.busy  # the Segment widget's result: no worker ran
    assert plots.progress.value == plots.progress.max > 0  # done, not 0 %
    summary = plots.status.value
    assert summary.startswith("3 segments")
    plots.plot.value = "histograms"
    wait_idle(qtbot, plots)
    assert "histograms of Î and L = 4, 12, 20" in plots.status.value
    assert plots.progress.value == plots.progress.max
    plots.plot.value = "importances"  # no classifier behind these segments
    assert "histograms" not in plots.status.value
    assert plots.status.value == "no pixel classifier behind the segments"
    plots.plot.value = "scatter_dop"
    assert plots.status.value == summary
    plots.plot.value = "histograms"  # kept: drawn at once, no worker
    assert not plots.busy and "histograms of Î" in plots.status.value
    # another plot chosen while the histograms compute: its status stays when they end
    plots.histograms = None
    plots.plot.value = "scatter_phase"
    plots.plot.value = "histograms"
    assert plots.busy
    plots.plot.value = "importances"
    wait_idle(qtbot, plots)
    assert plots.histograms is not None
    assert plots.status.value == "no pixel classifier behind the segments"


def test_component_maps_go_below_the_segments_and_scribbles(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    segment = add_widget("Segment by material")
    segment.set_params(**FAST)
    run_and_wait(qtbot, segment)
    scribbles = viewer.add_labels(np.zeros(stack.data.shape[1:], dtype=np.int32), name="strokes")
    plots = add_widget("Polarisation plots")
    click(qtbot, plots.run_button)
    layers = plots.add_component_maps()
    assert len(layers) == 3
    names = [layer.name for layer in viewer.layers]
    lowest_labels = min(names.index(f"segments ({stack.name})"), names.index(scribbles.name))
    for layer in layers:
        assert names.index(stack.name) < names.index(layer.name) < lowest_labels, names
    # the layers above the stack: maps first, Labels last
    above = list(viewer.layers)[names.index(stack.name) + 1 :]
    kinds = [isinstance(layer, Labels) for layer in above]
    assert kinds == sorted(kinds), names


WARM_SCRIPT = """
import sys
import napari
from qtpy.QtWidgets import QApplication

viewer = napari.Viewer(show=False)
assert "matplotlib.figure" not in sys.modules, "imported before any plugin dock"
viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
QApplication.processEvents()
from napari_polarseg.widgets.warm import WARM_MODULES, warmed

assert warmed(60)
assert all(name in sys.modules for name in WARM_MODULES)
assert "matplotlib.pyplot" not in sys.modules
viewer.close()
print("warmed")
"""


def test_the_first_plugin_dock_imports_matplotlib_in_the_background():
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    done = subprocess.run(
        [sys.executable, "-c", WARM_SCRIPT], capture_output=True, text=True, timeout=300, env=env
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "warmed" in done.stdout
