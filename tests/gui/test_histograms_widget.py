"""The plots dock's reconstruction histograms are readable (issue 14, item 6): the x-axis
is the data's robust range, not every value of a degree-20 fit that overshoots, and each
reconstruction has its own panel and colour over the original Î."""

from __future__ import annotations

import numpy as np
from _gui_helpers import run_and_wait, wait_idle
from matplotlib.colors import to_rgba

from napari_polarseg.engine.analysis import plots
from napari_polarseg.engine.features.harmonics import reconstruct_intensity
from napari_polarseg.widgets.plots import HISTOGRAM_BLOCKS, HISTOGRAM_DEGREES


def test_histograms_span_the_robust_range_one_colour_per_degree(
    viewer, open_sample, add_widget, qtbot
):
    open_sample("fruits_camera")
    segment = add_widget("Segment by material")
    run_and_wait(qtbot, segment)
    widget = add_widget("Polarisation plots")
    run_and_wait(qtbot, widget)  # Load segmentation
    widget.plot.value = "histograms"
    wait_idle(qtbot, widget)
    hist = widget.histograms
    assert hist is not None and set(hist.reconstructed) == set(HISTOGRAM_DEGREES)
    # the axis: within the union of the curves' 0.5-99.5 percentiles, which is far
    # narrower than the span of every value (the degree-20 fit overshoots)
    result = widget.result
    (I, zen, azi, _), k = plots.sample_blocks(
        [result.intensity, result.zenith, result.azimuth, None],
        result.params.window,
        HISTOGRAM_BLOCKS,
    )
    assert k is None or k == hist.sampled_blocks
    curves = [I] + [
        reconstruct_intensity(I, zen, azi, result.params.window, d, ridge=result.params.ridge)
        for d in HISTOGRAM_DEGREES
    ]
    ranges = np.array([plots.robust_range(c) for c in curves])
    lo, hi = ranges[:, 0].min(), ranges[:, 1].max()
    axes = widget.figure.axes
    assert len(axes) == len(HISTOGRAM_DEGREES)  # small multiples, one per degree
    for ax in axes:
        x0, x1 = ax.get_xlim()
        assert lo - 1e-9 <= x0 < x1 <= hi + 1e-9
    span = max(float(np.nanmax(c)) for c in curves) - min(float(np.nanmin(c)) for c in curves)
    assert hi - lo < span
    # every count is in the histogram or counted beyond it
    for d, counts in hist.reconstructed.items():
        assert counts.sum() + hist.outside[d] == hist.n_pixels
    # each panel: the original in grey and its own degree in its own colour, whose
    # heights are that degree's counts
    colours = set()
    for ax, (d, counts) in zip(axes, hist.reconstructed.items(), strict=True):
        original, rec = ax.patches[0], ax.patches[1]
        assert f"L = {d}" in rec.get_label()
        heights = np.asarray(rec.get_data().values)
        np.testing.assert_allclose(heights, 100.0 * counts / hist.n_pixels)
        np.testing.assert_allclose(
            original.get_data().values, 100.0 * hist.original / hist.n_pixels
        )
        colours.add(tuple(np.round(to_rgba(rec.get_edgecolor()), 3)))
    assert len(colours) == len(HISTOGRAM_DEGREES)
