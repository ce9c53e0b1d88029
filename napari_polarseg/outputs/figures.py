"""Matplotlib figures of the analyst's plots, and :func:`save_plots` writing them as PNGs.

:func:`render_plots` gives the same PNGs as bytes in memory (for writers that compute
everything first); :func:`sweep_heatmap_figure` draws a sweep of the thesis block grid
(:mod:`napari_polarseg.engine.analysis.sweep`) as heatmaps, :func:`param_sweep_figure` a
sweep of another method's parameters (:mod:`napari_polarseg.engine.analysis.param_sweep`)
as one bar per cell.

Every ``*_figure`` function draws the data of :mod:`napari_polarseg.engine.analysis.plots` into a
:class:`matplotlib.figure.Figure` (a new one, or ``fig`` cleared first, e.g. the figure
of a Qt canvas) with the object-oriented API only: no pyplot, so no global state.
matplotlib is imported lazily, when a figure is drawn.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import io as pio
from ..engine.analysis import plots
from ..engine.errors import PolarsegError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..engine import SegmentationResult
    from ..engine.analysis.param_sweep import ParamSweepResult
    from ..engine.analysis.sweep_result import SweepCell, SweepResult
    from ..engine.materials import Materials

#: Colours of the light default theme: figure background, text/axes, accent.
LIGHT = {"background": "#ffffff", "foreground": "#000000", "accent": "#1f77b4"}
#: A dark theme like napari's default one.
DARK = {"background": "#262930", "foreground": "#f0f1f2", "accent": "#50a0ff"}


def _figure(fig: Figure | None, size: tuple[float, float], theme: dict[str, str]) -> Figure:
    if fig is None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=size, layout="constrained")
    else:
        fig.clear()
    fig.set_facecolor(theme["background"])
    return fig


def _single_axes(
    fig: Figure | None, size: tuple[float, float], theme: dict[str, str]
) -> tuple[Figure, Any]:
    """A figure as :func:`_figure` makes it, with one axes filling it."""
    fig = _figure(fig, size, theme)
    return fig, fig.add_subplot(1, 1, 1)


def _style(ax: Any, theme: dict[str, str]) -> None:
    fg = theme["foreground"]
    ax.set_facecolor(theme["background"])
    ax.tick_params(colors=fg, which="both")
    for spine in ax.spines.values():
        spine.set_color(fg)
    ax.xaxis.label.set_color(fg)
    ax.yaxis.label.set_color(fg)
    ax.title.set_color(fg)


def _legend(ax: Any, theme: dict[str, str], **kwargs: Any) -> None:
    leg = ax.legend(fontsize="small", **kwargs)
    leg.get_frame().set_facecolor(theme["background"])
    leg.get_frame().set_edgecolor(theme["foreground"])
    for text in leg.get_texts():
        text.set_color(theme["foreground"])


def scatter_figure(
    data: plots.ScatterData,
    against: str = "dop",
    fig: Figure | None = None,
    theme: dict[str, str] = LIGHT,
    first_label: int = 0,
    materials: Materials | None = None,
) -> Figure:
    """Î against ρ (``against="dop"``), φ (``"phase"``, degrees) or both (``"both"``),
    coloured by segment (thesis figure 4.1). One point collection per axes.

    Each segment has the colour the viewer draws it in
    (:func:`napari_polarseg.palette.label_rgba` of its shown value). The legend names
    segment label v as ``v + first_label``: 0 numbers them as ``labels.tif`` does, 1 as
    the plugin's ``segments`` layer (where 0 is no label); with ``materials`` (a scribble
    classifier's) by its scribble value and material name, as both do."""
    from ..engine.materials import display_values
    from ..palette import label_rgba

    kinds = ["dop", "phase"] if against == "both" else [against]
    if any(k not in ("dop", "phase") for k in kinds):
        raise ValueError(f"against must be 'dop', 'phase' or 'both', got {against!r}")
    fig = _figure(fig, (5.0 * len(kinds), 4.0), theme)
    labels = np.asarray(data.labels)
    values = np.unique(labels)
    n = int(labels.max(initial=0)) + 1
    if materials is not None and len(materials.values) < n:
        materials = None  # labels the materials do not describe: numbered only
    palette = label_rgba(display_values(n, materials))
    colours = palette[labels]
    if materials is None:
        names = [f"segment {v + first_label}" for v in range(n)]
    else:
        names = [f"{v} {name}" for v, name in zip(materials.values, materials.names, strict=True)]
    for i, kind in enumerate(kinds):
        ax = fig.add_subplot(1, len(kinds), i + 1)
        x = data.dop if kind == "dop" else np.rad2deg(data.phase)
        ax.scatter(x, data.intensity, c=colours, s=2, linewidths=0, rasterized=True)
        for v in values:  # legend entries only (no points)
            ax.scatter([], [], color=palette[v], s=12, label=names[v])
        ax.set_xlabel("ρ degree of polarisation" if kind == "dop" else "φ phase (degrees)")
        ax.set_ylabel("Î intensity")
        ax.set_title(f"Î against {'ρ' if kind == 'dop' else 'φ'} ({len(data)} pixels)")
        _style(ax, theme)
        if values.size <= 12:
            _legend(ax, theme, markerscale=1.5)
    return fig


def explained_variance_figure(
    data: plots.ExplainedVariance, fig: Figure | None = None, theme: dict[str, str] = LIGHT
) -> Figure:
    """Bars of each principal component's share and a line of the cumulative share."""
    fig, ax = _single_axes(fig, (5.0, 3.5), theme)
    k = np.arange(1, data.ratio.size + 1)
    ax.bar(k, data.ratio, color=theme["accent"], label="component")
    ax.plot(k, data.cumulative, "o-", color=theme["foreground"], ms=3, label="cumulative")
    ax.set_xlabel("principal component")
    ax.set_ylabel("share of the variance")
    ax.set_ylim(0, 1.02)
    ax.set_xticks(k if k.size <= 20 else k[:: int(np.ceil(k.size / 20))])
    ax.set_title("explained variance")
    _style(ax, theme)
    _legend(ax, theme, loc="center right")
    return fig


def importances_figure(
    data: plots.FeatureImportances, fig: Figure | None = None, theme: dict[str, str] = LIGHT
) -> Figure:
    """Horizontal bars of a pixel classifier's largest feature importances, largest on top."""
    fig, ax = _single_axes(fig, (5.0, 4.0), theme)
    y = np.arange(len(data.names))
    ax.barh(y, data.values, color=theme["accent"])
    ax.set_yticks(y, data.names, fontsize="small")
    ax.invert_yaxis()
    ax.tick_params(axis="x", labelsize="small")
    # the title and the x label centred on the figure, not on the axes the long feature
    # names push right: in a narrow dock they ran off the canvas
    fg = theme["foreground"]
    fig.suptitle(
        f"top {len(data.names)} of {data.n_features} features\n"
        f"({data.shown_share:.0%} of the importance)",
        fontsize="medium",
        color=fg,
    )
    fig.supxlabel("importance (mean impurity decrease)", fontsize="small", color=fg)
    _style(ax, theme)
    return fig


def _map_grid(
    maps: np.ndarray,
    titles: Sequence[str],
    fig: Figure | None,
    theme: dict[str, str],
    cmap: str,
) -> Figure:
    n = maps.shape[0]
    ncols = min(3, n)
    nrows = int(np.ceil(n / ncols))
    fig = _figure(fig, (3.2 * ncols, 2.8 * nrows), theme)
    for i in range(n):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        im = ax.imshow(maps[i], cmap=cmap, interpolation="nearest")
        ax.set_title(titles[i])
        ax.set_xticks([])
        ax.set_yticks([])
        _style(ax, theme)
        bar = fig.colorbar(im, ax=ax, shrink=0.8)
        bar.ax.tick_params(colors=theme["foreground"], labelsize="small")
    return fig


def coefficients_figure(
    data: plots.CoefficientMaps, fig: Figure | None = None, theme: dict[str, str] = LIGHT
) -> Figure:
    """Block-grid maps of the chosen a_lm (thesis figures 5.2/5.11)."""
    titles = [f"a(l={l}, m={m})" for l, m in data.pairs]  # noqa: E741
    return _map_grid(data.maps, titles, fig, theme, "viridis")


def components_figure(
    data: plots.ComponentMaps, fig: Figure | None = None, theme: dict[str, str] = LIGHT
) -> Figure:
    """Block-grid maps of the first principal components (thesis figures 5.4/5.13)."""
    titles = [f"component {i + 1} ({r:.0%})" for i, r in enumerate(data.explained)]
    return _map_grid(data.blocks, titles, fig, theme, "RdBu_r")


#: Colours of the reconstructions in :func:`histograms_figure` (matplotlib's tab10
#: orange, green, red, purple, …: none is the original's grey or the theme's colours).
RECONSTRUCTION_COLOURS = ("#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#17becf", "#bcbd22")


def histograms_figure(
    data: plots.ReconstructionHistograms, fig: Figure | None = None, theme: dict[str, str] = LIGHT
) -> Figure:
    """Histogram of Î and of its reconstructions on shared bins (thesis figure 5.17), as
    small multiples: one panel per degree L, each with the original Î (grey, filled)
    behind that reconstruction (a coloured step line, its own colour), on one x-axis (the
    robust range of :func:`~napari_polarseg.engine.analysis.plots.reconstruction_histograms`).
    Heights are shares of the counted pixels, so a sample of blocks reads as the whole."""
    n = max(1, len(data.reconstructed))
    fig = _figure(fig, (5.5, 1.6 + 1.3 * n), theme)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    total = max(1, data.n_pixels or int(data.original.sum()))
    share = 100.0 / total
    for i, (ax, (d, counts)) in enumerate(zip(axes, data.reconstructed.items(), strict=False)):
        ax.stairs(data.original * share, data.edges, fill=True, color="0.6", alpha=0.5, label="Î")
        colour = RECONSTRUCTION_COLOURS[i % len(RECONSTRUCTION_COLOURS)]
        error = data.mean_error.get(d)
        label = f"L = {d}" + ("" if error is None else f" (mean |error| {error:.3g})")
        ax.stairs(counts * share, data.edges, color=colour, lw=1.4, label=label)
        ax.set_ylabel("% of pixels")
        _style(ax, theme)
        _legend(ax, theme, loc="best")
    outside = max([data.outside_original, *data.outside.values()])
    share_out = 100.0 * outside / total
    beyond = f" (≤ {share_out:.1f} % of pixels beyond)" if outside else ""
    axes[-1].set_xlabel(f"Î intensity{beyond}")
    axes[-1].set_xlim(float(data.edges[0]), float(data.edges[-1]))
    what = f", {data.sampled_blocks} random blocks" if data.sampled_blocks else ""
    axes[0].set_title(f"Î and its reconstructions (w = {data.window}{what})", fontsize="medium")
    axes[0].title.set_color(theme["foreground"])
    return fig


def error_table_figure(
    data: plots.ErrorTable, fig: Figure | None = None, theme: dict[str, str] = LIGHT
) -> Figure:
    """Mean reconstruction error per window and degree as a table (thesis table 5.1)."""
    size = (1.5 + 0.9 * len(data.degrees), 0.8 + 0.35 * len(data.windows))
    fig, ax = _single_axes(fig, size, theme)
    ax.axis("off")
    cells = [[f"{v:.4g}" for v in row] for row in data.errors]
    table = ax.table(
        cellText=cells,
        rowLabels=[f"w = {w}" for w in data.windows],
        colLabels=[f"L = {d}" for d in data.degrees],
        bbox=[0.15, 0.0, 0.85, 0.9],  # axes fraction: row labels stay inside the figure
    )
    for cell in table.get_celld().values():
        cell.set_facecolor(theme["background"])
        cell.set_edgecolor(theme["foreground"])
        cell.get_text().set_color(theme["foreground"])
    ax.set_title("mean |reconstruction error|", color=theme["foreground"])
    return fig


def _plot_makers(
    result: SegmentationResult,
    *,
    degrees: Sequence[int],
    windows: Sequence[int] | None,
    table_degrees: Sequence[int] | None,
    pairs: Sequence[tuple[int, int]] | None,
    n_components: int,
    max_points: int,
    seed: int,
    theme: dict[str, str],
) -> dict[str, Any]:
    """File name → function drawing that plot of ``result``
    (:data:`~napari_polarseg.outputs.contract.PLOT_FILES`)."""
    degree = result.params.degree
    if pairs is None:
        pairs = [(l, m) for l, m in plots.DEFAULT_PAIRS if l <= degree]  # noqa: E741
    return {
        "scatter.png": lambda: scatter_figure(
            plots.scatter_data(result, max_points, seed),
            "both",
            theme=theme,
            materials=result.materials,
        ),
        "explained_variance.png": lambda: explained_variance_figure(
            plots.explained_variance(result), theme=theme
        ),
        "coefficients.png": lambda: coefficients_figure(
            plots.coefficient_maps(result, pairs), theme=theme
        ),
        "components.png": lambda: components_figure(
            plots.component_maps(result, n_components), theme=theme
        ),
        "histograms.png": lambda: histograms_figure(
            plots.result_histograms(result, degrees), theme=theme
        ),
        "error_table.png": lambda: error_table_figure(
            plots.result_error_table(
                result,
                windows or [result.params.window],
                table_degrees or (4, 8, 12, 16, 20),
            ),
            theme=theme,
        ),
    }


def save_plots(result: SegmentationResult, out_dir: str | Path, **options: Any) -> dict[str, Path]:
    """Write the six plots of ``result`` as PNGs into ``out_dir`` (created if missing).

    ``options`` are those of :func:`render_plots` (degrees, windows and table degrees of
    the error table, coefficient pairs, components, points, seed, dpi, theme). Returns
    the path of each file by its name (:data:`~napari_polarseg.outputs.contract.PLOT_FILES`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, content in render_plots(result, **options).items():
        with pio.atomic_output(out / name) as tmp:
            tmp.write_bytes(content)
        paths[name] = out / name
    return paths


def png_bytes(fig: Figure, dpi: int = 100) -> bytes:
    """The figure as PNG file content (drawn on an Agg canvas; nothing is written)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, facecolor=fig.get_facecolor())
    return buf.getvalue()


def render_plots(
    result: SegmentationResult,
    *,
    degrees: Sequence[int] = (4, 12, 20),
    windows: Sequence[int] | None = None,
    table_degrees: Sequence[int] | None = None,
    pairs: Sequence[tuple[int, int]] | None = None,
    n_components: int = 3,
    max_points: int = 20000,
    seed: int = 0,
    dpi: int = 100,
    theme: dict[str, str] = LIGHT,
) -> dict[str, bytes]:
    """The six plots of ``result`` as PNG file contents by name, in memory.

    For callers that compute everything before writing anything (``polarseg segment
    --plots``); :func:`save_plots` writes them. ``windows`` and ``table_degrees`` of the
    error table default to the result's window and (4, 8, 12, 16, 20); ``pairs`` (l, m)
    of the coefficient maps to :data:`~napari_polarseg.engine.analysis.plots.DEFAULT_PAIRS` up to
    the result's degree. Each figure is drawn and turned into bytes before the next
    (bounded memory).
    """
    makers = _plot_makers(
        result,
        degrees=degrees,
        windows=windows,
        table_degrees=table_degrees,
        pairs=pairs,
        n_components=n_components,
        max_points=max_points,
        seed=seed,
        theme=theme,
    )
    return {name: png_bytes(make(), dpi) for name, make in makers.items()}


# -- parameter sweep ------------------------------------------------------------------------

#: Columns of a sweep drawn by :func:`sweep_heatmap_figure` by default (``ari`` only with
#: a ground truth), and their titles.
SWEEP_METRICS = {
    "stability": "stability",
    "score": "combined score",
    "silhouette": "silhouette",
    "mean_ncut": "mean Ncut (lower is better)",
    "ari": "ARI (ground truth)",
    "seconds": "seconds",
}


def sweep_heatmap_figure(
    result: SweepResult,
    metrics: str | Sequence[str] | None = None,
    fig: Figure | None = None,
    theme: dict[str, str] = LIGHT,
    annotate: bool = True,
) -> Figure:
    """Heatmaps of a parameter sweep: one row per metric, one column per refractive index.

    Each panel is the w × L grid (rows: window size w, columns: degree L) of one metric
    for one n (:meth:`~napari_polarseg.engine.analysis.sweep_result.SweepResult.grid`), on one
    colour
    scale per metric, brighter = better (reversed for the mean Ncut), with the values
    written in the cells; failed cells are blank and marked ×. The best cell by the
    sweep's criterion (``result.score``) is outlined in every row.

    Parameters
    ----------
    result : SweepResult
    metrics : str or sequence of str, optional
        Columns of the sweep to draw (default: :data:`SWEEP_METRICS` without
        ``seconds``, and without ``ari`` when there is no ground truth).
    fig, theme
        As the other figures of this module.
    annotate : bool
        Write each cell's value into it.
    """
    if metrics is None:
        metrics = [
            m for m in SWEEP_METRICS if m != "seconds" and (m != "ari" or result.has_ground_truth)
        ]
    elif isinstance(metrics, str):
        metrics = [metrics]
    metrics = list(metrics)
    n_rows, n_cols = len(metrics), len(result.refractive_indices)
    nw, nl = len(result.windows), len(result.degrees)
    panel = (1.2 + 0.55 * nl, 0.9 + 0.42 * nw)
    fig = _figure(fig, (panel[0] * n_cols + 0.8, panel[1] * n_rows + 0.4), theme)
    try:
        best = result.best_cell()
    except PolarsegError:
        best = None
    for r, metric in enumerate(metrics):
        _sweep_row(fig, result, metric, (r, n_rows), best, theme, annotate)
    if best is not None:
        fig.suptitle(
            f"best by {result.score}: w = {best.window}, L = {best.degree}, "
            f"n = {best.refractive_index:g}",
            color=theme["foreground"],
        )
    return fig


def _sweep_row(
    fig: Figure,
    result: SweepResult,
    metric: str,
    row: tuple[int, int],
    best: SweepCell | None,
    theme: dict[str, str],
    annotate: bool,
) -> None:
    """Row ``row = (r, n_rows)`` of :func:`sweep_heatmap_figure`: ``metric``'s panel for
    every refractive index, on one colour scale with one colour bar."""
    from matplotlib import colormaps
    from matplotlib.patches import Rectangle

    r, n_rows = row
    n_cols = len(result.refractive_indices)
    values = result.grid(metric)
    finite = values[np.isfinite(values)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if not hi > lo:
        lo, hi = lo - 0.5, hi + 0.5
    cmap = colormaps["viridis_r" if metric in ("mean_ncut", "seconds") else "viridis"]
    cmap = cmap.with_extremes(bad=theme["background"])
    axes = []
    for k, n in enumerate(result.refractive_indices):
        ax = fig.add_subplot(n_rows, n_cols, r * n_cols + k + 1)
        axes.append(ax)
        grid = np.ma.masked_invalid(values[k])
        im = ax.imshow(grid, cmap=cmap, vmin=lo, vmax=hi, aspect="auto")
        ax.set_xticks(range(len(result.degrees)), [str(d) for d in result.degrees])
        ax.set_yticks(range(len(result.windows)), [str(w) for w in result.windows])
        ax.set_xlabel("degree L")
        ax.set_ylabel("window w")
        title = SWEEP_METRICS.get(metric, metric)
        ax.set_title(f"{title}\nn = {n:g}" if n_cols > 1 else title, fontsize="medium")
        _style(ax, theme)
        _sweep_cells(ax, values[k], metric, (lo, hi), theme, annotate)
        if best is not None and best.index[0] == k:
            _, i, j = best.index
            ax.add_patch(
                Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor="#ff3b30", linewidth=2.5)
            )
    bar = fig.colorbar(im, ax=axes, shrink=0.9)
    bar.ax.tick_params(colors=theme["foreground"], labelsize="small")


def _sweep_cells(
    ax: Any,
    values: np.ndarray,
    metric: str,
    scale: tuple[float, float],
    theme: dict[str, str],
    annotate: bool,
) -> None:
    """Mark the failed cells of one w × L panel with ×; with ``annotate``, write every
    other cell's value, black on bright cells, white on dark ones."""
    lo, hi = scale
    for i in range(values.shape[0]):
        for j in range(values.shape[1]):
            v = values[i, j]
            if not np.isfinite(v):
                ax.text(j, i, "×", ha="center", va="center", color=theme["foreground"])
            elif annotate:
                shade = (v - lo) / (hi - lo)
                if metric in ("mean_ncut", "seconds"):
                    shade = 1.0 - shade
                colour = "black" if shade > 0.55 else "white"
                ax.text(j, i, f"{v:.2f}", ha="center", va="center", color=colour, fontsize="small")


#: Scores of a sweep of a method's parameters that :func:`param_sweep_figure` draws.
PARAM_SWEEP_METRICS = {
    "stability": "stability",
    "ari": "ARI (ground truth)",
    "seconds": "seconds (lower is better)",
}


def param_sweep_figure(
    result: ParamSweepResult,
    metric: str = "stability",
    fig: Figure | None = None,
    theme: dict[str, str] = LIGHT,
) -> Figure:
    """A sweep of a method's parameters
    (:class:`~napari_polarseg.engine.analysis.param_sweep.ParamSweepResult`): one bar per
    cell of ``metric`` (:data:`PARAM_SWEEP_METRICS`), labelled by the cell's values; a
    failed cell or one without the score is marked ×, the best cell (by the sweep's
    criterion) is outlined."""
    if metric not in PARAM_SWEEP_METRICS:
        raise PolarsegError(f"metric must be one of {', '.join(PARAM_SWEEP_METRICS)}")
    cells = result.cells
    fig, ax = _single_axes(fig, (1.5 + 0.6 * len(cells), 3.0), theme)
    try:
        best = result.best_cell()
    except PolarsegError:
        best = None
    values = np.array([getattr(c, metric) if c.ok else np.nan for c in cells], dtype=float)
    shown = np.nan_to_num(values, nan=0.0)
    edges = ["#ff3b30" if c is best else theme["accent"] for c in cells]
    ax.bar(range(len(cells)), shown, color=theme["accent"], edgecolor=edges, linewidth=2.5)
    for i, v in enumerate(values):
        text = "×" if not np.isfinite(v) else f"{v:.2f}"
        ax.text(i, shown[i], text, ha="center", va="bottom", color=theme["foreground"])
    names = [", ".join(f"{k}={v}" for k, v in c.values.items()) for c in cells]
    ax.set_xticks(range(len(cells)), names, rotation=30 if len(cells) > 4 else 0, ha="right")
    ax.set_ylabel(PARAM_SWEEP_METRICS[metric])
    title = f"{result.base.method}: {PARAM_SWEEP_METRICS[metric]} per cell"
    if best is not None:
        chosen = ", ".join(f"{k} = {v}" for k, v in best.values.items())
        title += f"\nbest by {result.score}: {chosen}"
    ax.set_title(title, fontsize="medium")
    _style(ax, theme)
    return fig
