"""Importing the libraries a plugin dock will need, in the background, ahead of time.

matplotlib (the plot docks' canvas), and the parts of scikit-image and pandas napari
imports with the first Labels layer, took the GUI thread one to two seconds the first
time they were needed: the *Polarisation plots* dock opened slowly, and the first
segments froze the window longer than the next ones. A plugin dock calls
:func:`warm_imports` when it opens; a thread imports them while the user sets up the
run.
"""

from __future__ import annotations

import importlib
import sys
import threading

#: Modules imported ahead (only modules: no figure, no Qt object is made). pandas:
#: napari's Labels layer imports it for its features table when the first one is made
#: (the first segments), on the GUI thread (docs/performance.md).
WARM_MODULES = (
    "matplotlib.figure",
    "matplotlib.backends.backend_agg",
    "skimage.color.colorconv",
    "pandas",
)

#: The thread importing :data:`WARM_MODULES` (started once).
_warming: list[threading.Thread] = []


def warm_imports() -> None:
    """Import :data:`WARM_MODULES` in a background thread, once per process."""
    if _warming or all(name in sys.modules for name in WARM_MODULES):
        return

    def _import() -> None:
        for name in WARM_MODULES:
            importlib.import_module(name)

    thread = threading.Thread(target=_import, name="napari-polarseg imports")
    _warming.append(thread)
    thread.start()


def warmed(timeout: float | None = None) -> bool:
    """Wait for the importing thread (at most ``timeout`` seconds); True once it ended
    (or never started)."""
    for thread in _warming:
        thread.join(timeout)
    return not any(thread.is_alive() for thread in _warming)
