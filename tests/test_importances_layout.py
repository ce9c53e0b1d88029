"""Issue 25: the feature-importance chart fits a narrow plots dock (title and x label
were cut off by the long feature names)."""

from __future__ import annotations

import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from napari_polarseg.engine.analysis import plots
from napari_polarseg.outputs import figures

NAMES = (
    "intensity_contrast@16",
    "dop_vs_log_intensity_corr@16",
    "region:dop_vs_log_intensity_corr@1",
    "dolp@8",
    "dop_spread_over_dop@16",
)


@pytest.mark.parametrize("width_px", [330, 600])
def test_every_text_of_the_importance_chart_lies_inside_the_canvas(width_px):
    importances = {f"{name}#{i}": 0.05 - 0.002 * i for i, name in enumerate(NAMES * 3)}
    data = plots.feature_importances(importances, 15)
    fig = Figure(figsize=(width_px / 100, 3.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    figures.importances_figure(data, fig, figures.DARK)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    (ax,) = fig.axes
    assert "top 15 of 15 features" in fig._suptitle.get_text()
    assert "importance" in fig._supxlabel.get_text()
    # the title, the x label and the axes with its drawn tick labels (the feature names)
    for what, extent in (
        ("title", fig._suptitle.get_window_extent(renderer)),
        ("x label", fig._supxlabel.get_window_extent(renderer)),
        ("axes", ax.get_tightbbox(renderer)),
    ):
        assert box.x0 - 1 <= extent.x0 and extent.x1 <= box.x1 + 1, what
        assert box.y0 - 1 <= extent.y0 and extent.y1 <= box.y1 + 1, what
