"""Deleting the angle stack after a Run must not kill the session (issue 40, point 8).

napari 0.9.2 crashes (SIGSEGV) drawing 2-D layers after the last 3-D layer is removed
(:mod:`napari_polarseg.widgets.dims_guard`). A crash would take pytest with it, so the
scene runs in a child process with a *shown* viewer (a hidden canvas never draws) and
the test reads its exit code.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import numpy as np, napari
    from qtpy.QtWidgets import QApplication

    def pump(n):
        for _ in range(n):
            QApplication.processEvents()

    viewer = napari.Viewer()  # shown: the canvas draws, as for a user
    stack = viewer.open_sample("napari-polarseg", "leaves")[0]
    _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", "Segment by material")
    widget.stack_layer.value = stack
    widget.run_button.native.click()
    assert widget.wait(timeout=120), "the run did not end"
    pump(30)
    names = [layer.name for layer in viewer.layers]
    assert any(layer.ndim == 2 for layer in viewer.layers), names
    viewer.layers.remove(stack)
    pump(60)
    left = [layer for layer in viewer.layers]
    assert left and all(layer.ndim == 2 for layer in left), [l.name for l in left]
    print("survived", len(left), flush=True)
    viewer.close()
    """
)


def _run(script: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300
    )


def test_deleting_the_stack_after_a_run_keeps_the_viewer_alive():
    done = _run(SCRIPT)
    assert done.returncode == 0, (done.returncode, done.stdout[-2000:], done.stderr[-3000:])
    assert "survived" in done.stdout
