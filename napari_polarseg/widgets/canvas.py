"""The matplotlib canvas of the plot widgets (*Polarisation plots*, *Parameter sweep*),
themed like napari."""

from __future__ import annotations

import sys
import threading
from typing import TYPE_CHECKING, Any

from ..outputs import figures

if TYPE_CHECKING:
    import napari
    from matplotlib.figure import Figure


def napari_theme(viewer: napari.viewer.Viewer) -> dict[str, str]:
    """Figure colours from the viewer's napari theme (a dark grey if unavailable)."""
    try:
        from napari.utils.theme import get_theme

        theme = get_theme(viewer.theme)
        return {
            "background": theme.background.as_hex(),
            "foreground": theme.text.as_hex(),
            "accent": theme.highlight.as_hex() if theme.highlight else figures.DARK["accent"],
        }
    except Exception:  # noqa: BLE001 - any theme problem: fall back to dark grey
        return dict(figures.DARK)


#: The thread importing matplotlib ahead of the first plot (:func:`warm_plotting`).
_warming: list[threading.Thread] = []


def warm_plotting() -> None:
    """Import matplotlib's figure and Agg backend in a background thread, once.

    That import is most of the time the first *Polarisation plots* or *Parameter sweep*
    dock took to open (the GUI froze meanwhile); a plugin dock calls this when it opens,
    so the plot docks opened after it find matplotlib imported. The thread only imports
    modules (no figure, no Qt object) and ends by itself.
    """
    if _warming or "matplotlib.backends.backend_agg" in sys.modules:
        return

    def _import() -> None:
        import matplotlib.backends.backend_agg  # noqa: F401
        import matplotlib.figure  # noqa: F401

    thread = threading.Thread(target=_import, name="napari-polarseg matplotlib import")
    _warming.append(thread)
    thread.start()


def figure_canvas(size: tuple[float, float], min_height: int) -> tuple[Figure, Any]:
    """A constrained-layout figure of ``size`` inches on a Qt canvas at least
    ``min_height`` pixels high (``FigureCanvasQTAgg``)."""
    from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=size, layout="constrained")
    canvas = FigureCanvasQTAgg(figure)
    canvas.setMinimumHeight(min_height)
    return figure, canvas


def show_message(figure: Figure, theme: dict[str, str], text: str) -> None:
    """Clear ``figure`` and write ``text`` in its middle (a hint in place of a plot)."""
    figure.clear()
    figure.set_facecolor(theme["background"])
    figure.text(0.5, 0.5, text, ha="center", va="center", wrap=True, color=theme["foreground"])
