"""The matplotlib canvas of the plot widgets (*Polarisation plots*, *Parameter sweep*),
themed like napari."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..outputs import figures
from .warm import warmed

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


def figure_canvas(size: tuple[float, float], min_height: int) -> tuple[Figure, Any]:
    """A constrained-layout figure of ``size`` inches on a Qt canvas at least
    ``min_height`` pixels high (``FigureCanvasQTAgg``)."""
    # matplotlib imported by the background thread of warm.py, if that still runs: wait
    # for it rather than import the same modules from two threads at once
    warmed()
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
