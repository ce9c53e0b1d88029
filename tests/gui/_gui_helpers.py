"""Helpers shared by the GUI tests (clicking, waiting, engine reference results)."""

from __future__ import annotations

from typing import Any

import numpy as np
from napari.utils.notifications import notification_manager
from qtpy.QtCore import Qt

from napari_polarseg.engine import Scene, SegmentParams

PLUGIN = "napari-polarseg"
#: Sample keys of the plugin's manifest and the shape of their stacks.
SAMPLES = {
    "leaves": (7, 120, 130),
    "camouflage": (7, 120, 130),
    "fruit": (7, 120, 130),
    "fruits_camera": (4, 256, 256),
}
#: Worker timeout for waits (milliseconds).
TIMEOUT_MS = 120_000


#: Every dock widget of the plugin's manifest, by the name the Plugins menu shows, the
#: Segment dock first.
PLUGIN_DOCKS = (
    "Segment by material",
    "Polarisation image",
    "Polarisation plots",
    "Parameter sweep",
    "Batch over a folder",
    "Time series change map",
)


def click(qtbot: Any, button: Any) -> None:
    """Click a magicgui push button with the mouse."""
    qtbot.mouseClick(button.native, Qt.MouseButton.LeftButton)


def run_and_wait(qtbot: Any, widget: Any, timeout: int = TIMEOUT_MS) -> None:
    """Click the widget's Run button and wait until its worker has ended."""
    click(qtbot, widget.run_button)
    wait_idle(qtbot, widget, timeout)


def wait_idle(qtbot: Any, widget: Any, timeout: int = TIMEOUT_MS) -> None:
    """Wait until the widget has no worker running or queued."""
    qtbot.waitUntil(lambda: not widget.busy and not widget._waiting(), timeout=timeout)


def engine_result(layer: Any, params: SegmentParams) -> Any:
    """The engine's result for the same input, computed without the plugin."""
    angles = np.deg2rad(layer.metadata["angles_deg"])
    return Scene(np.asarray(layer.data), angles).segment(params)


def error_messages() -> list[str]:
    """Messages of the error notifications dispatched so far in this test."""
    return [str(n.message) for n in notification_manager.records if n.severity == "error"]


class Gate:
    """Makes ``module.name`` wait for ``release`` (deterministic mid-run actions).

    ``entered`` is set when a call starts waiting; ``state`` counts the calls running at
    once (``max_active`` shows whether two ever overlapped).
    """

    def __init__(self, monkeypatch: Any, module: Any, name: str) -> None:
        import threading

        self.entered, self.release = threading.Event(), threading.Event()
        self.state = {"active": 0, "max_active": 0}
        original = getattr(module, name)
        entered, release, state = self.entered, self.release, self.state

        def blocking(*args: Any, **kwargs: Any) -> Any:
            state["active"] += 1
            state["max_active"] = max(state["max_active"], state["active"])
            entered.set()
            try:
                assert release.wait(30), f"test never released {name}"
                return original(*args, **kwargs)
            finally:
                state["active"] -= 1

        monkeypatch.setattr(module, name, blocking)

    def arm(self) -> None:
        """Block the next call (again)."""
        self.entered.clear()
        self.release.clear()
