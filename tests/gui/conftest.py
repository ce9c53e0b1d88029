"""Fixtures for the GUI tests: a real napari viewer (Qt + GL under Xvfb), the plugin's
samples and widgets, and helpers that click buttons and wait for the worker threads.

Run with ``xvfb-run -a .venv/bin/pytest tests/gui``.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from collections.abc import Callable, Iterator
from typing import Any

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
if HERE not in sys.path:  # the tests import ``_gui_helpers`` from this folder
    sys.path.insert(0, HERE)
HAVE_GUI_STACK = all(
    importlib.util.find_spec(name) is not None for name in ("napari", "pytestqt", "qtpy", "npe2")
)
if not HAVE_GUI_STACK:  # the test modules import napari: do not even collect them
    collect_ignore_glob = ["test_*.py"]
NO_DISPLAY = sys.platform.startswith("linux") and not (
    os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark this folder's tests ``gui``; skip them without a display (use ``xvfb-run -a``)."""
    skip = pytest.mark.skip(reason="GUI tests need a display: run `xvfb-run -a pytest tests/gui`")
    for item in items:
        if str(item.fspath).startswith(HERE):
            item.add_marker(pytest.mark.gui)
            if NO_DISPLAY:
                item.add_marker(skip)


@pytest.fixture(autouse=True)
def _wait_for_workers_and_clear_notifications() -> Iterator[None]:
    """Start each test with no notifications; end it with no worker thread running."""
    from napari.utils.notifications import notification_manager

    notification_manager.records.clear()
    yield
    from superqt.utils._qthreading import WorkerBase

    WorkerBase.await_workers(msecs=30_000)


@pytest.fixture
def viewer(make_napari_viewer: Callable[..., Any]) -> Any:
    """A napari viewer (not shown; Qt and GL are real)."""
    return make_napari_viewer()


@pytest.fixture
def open_sample(viewer: Any) -> Callable[[str], Any]:
    """Open one of the plugin's samples in ``viewer``; returns its angle-stack layer."""

    def _open(key: str) -> Any:
        layers = viewer.open_sample("napari-polarseg", key)
        return layers[0]

    return _open


@pytest.fixture
def add_widget(viewer: Any) -> Callable[..., Any]:
    """Dock one of the plugin's widgets by its display name, as a user would.

    *Segment by material* is switched to the ``thesis`` preset unless ``preset`` says
    otherwise (None keeps the widget's own default, ``auto``): most GUI tests compare the
    widget with the thesis pipeline run by the engine; test_auto_default.py checks the
    default a user gets.
    """

    def _add(name: str, preset: str | None = "thesis") -> Any:
        _, widget = viewer.window.add_plugin_dock_widget("napari-polarseg", name)
        if name == "Segment by material" and preset is not None:
            widget.preset.value = preset
        return widget

    return _add


@pytest.fixture
def gate(monkeypatch: Any) -> Callable[[str], Any]:
    """``gate("block_coefficients")`` makes that function of the pipeline's harmonics
    module wait for ``release`` (deterministic mid-run actions; see ``_gui_helpers.Gate``)."""
    from _gui_helpers import Gate

    import napari_polarseg.engine.pipeline as pipeline_module

    return lambda name: Gate(monkeypatch, pipeline_module.harmonics, name)
