"""Adding a result's secondary layers one per event-loop turn.

napari takes a good part of a second of the GUI thread to add an image layer to a large
viewer (its layer list row, its controls, the texture), so a result that added its
segments and then the error map, the diagnostics, the Stokes and HSV views in one go
froze the window for the sum. A :class:`LayerQueue` runs such additions one at a time,
letting the event loop run (draw, take the mouse) between them: the window freezes for
one layer at most. The widget's ``wait()`` (and ``busy``-style checks through
``_waiting``) includes the pending additions.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Any

from qtpy.QtCore import QObject, QTimer


class LayerQueue:
    """Calls queued actions one per event-loop turn, in order, newest per key.

    :meth:`put` an action under a key (e.g. the layer's role): it replaces an action of
    the same key still pending (a newer result's layer supersedes the older one) and
    keeps that place in the queue. :meth:`clear` drops what is pending.
    """

    def __init__(self, parent: QObject) -> None:
        self._actions: OrderedDict[Any, Callable[[], Any]] = OrderedDict()
        self._timer = QTimer(parent)  # deleted with the widget: never fires after it
        self._timer.setSingleShot(True)
        self._timer.setInterval(0)
        self._timer.timeout.connect(self._next)

    @property
    def pending(self) -> bool:
        """True while an action waits."""
        return bool(self._actions)

    def put(self, key: Any, action: Callable[[], Any]) -> None:
        """Queue ``action`` under ``key`` (replacing a pending one of that key)."""
        self._actions[key] = action
        self._timer.start()

    def clear(self) -> None:
        """Drop the pending actions."""
        self._actions.clear()
        self._timer.stop()

    def flush(self) -> None:
        """Run every pending action now."""
        while self._actions:
            self._next()

    def _next(self) -> None:
        if not self._actions:
            return
        _, action = self._actions.popitem(last=False)
        try:
            action()
        except RuntimeError as exc:  # the widget or the viewer was deleted meanwhile
            if "deleted" not in str(exc):
                raise
            self._actions.clear()
            return
        if self._actions:
            self._timer.start()
