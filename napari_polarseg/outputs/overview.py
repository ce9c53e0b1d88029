"""The ``overview.png`` of a result folder: every map of a segmentation, on a grid.

:func:`overview_figure` draws the input, Î, ρ, φ, the AoLP/DoLP HSV composite, the
segments (in the colours the viewer draws them in, :func:`napari_polarseg.palette.label_rgba`;
their colour bar is the legend: each label's ``labels.tif`` value and, from a scribble
classifier, its material's name), the ground truth (when known, in the colours of the
segments it is matched to, :func:`segment_colours_for`) and the reconstruction error;
:func:`render_overview` turns it into pixels. matplotlib is imported lazily, with its
object-oriented API on an Agg canvas only (no pyplot, no window, safe in a worker thread).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..engine.analysis.views import CompositeParams, aolp_dolp_composite, auto_dolp_max

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..engine import SegmentationResult

#: One panel of the overview: (title, image, colour map or "rgb" or a label-panel key of
#: the ticks or :data:`NOT_COMPUTED`, vmin, vmax).
Panel = tuple[str, Any, str, Any, Any]
#: The colour-map slot of a panel whose map the method did not compute: its "image" is
#: the text shown in the panel (no image, no colour bar).
NOT_COMPUTED = "not computed"
#: The label panels by their key: (label values, tick labels, RGBA of each value).
Ticks = dict[str, tuple[Any, list[str], np.ndarray]]
#: Columns of the overview's grid (2 rows of 4 for the 7 or 8 panels).
COLUMNS = 4


def segment_colours_for(truth: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Colour indices of the true materials and of the segments, matched by overlap.

    The true labels are numbered 0, 1, … in increasing order; each segment gets the index
    of the true material it is matched to (the largest total overlap, a linear
    assignment on the contingency table), so a material and its segment share a colour.
    Unmatched segments get the indices after the true materials'. Returns ``(truth
    index (H, W), segment index by label value (n_labels,))``.
    """
    from scipy.optimize import linear_sum_assignment

    true_values, true_index = np.unique(np.asarray(truth), return_inverse=True)
    true_index = true_index.reshape(np.shape(truth))
    n_labels = int(np.max(labels, initial=0)) + 1
    table = np.zeros((true_values.size, n_labels))
    np.add.at(table, (true_index.ravel(), np.asarray(labels).ravel()), 1.0)
    rows, cols = linear_sum_assignment(table, maximize=True)
    colour = np.full(n_labels, -1)
    colour[cols] = rows
    spare = iter(range(true_values.size, true_values.size + n_labels))
    for j in np.flatnonzero(colour < 0):
        colour[j] = next(spare)
    return true_index, colour


def _truth_rgba(segment_rgba: np.ndarray, colour: np.ndarray, n_true: int) -> np.ndarray:
    """RGBA of the true materials 0..m−1: the colour of the segment matched to each, and
    for an unmatched one a palette colour no segment has (grey when none is left)."""
    from ..palette import segment_rgba as palette

    rgba = np.tile([0.6, 0.6, 0.6, 1.0], (n_true, 1))
    for j, i in enumerate(colour):
        if i < n_true:
            rgba[i] = segment_rgba[j]
    used = {tuple(c) for c in np.round(segment_rgba, 6)}
    spare = iter(c for c in palette() if tuple(np.round(c, 6)) not in used)
    matched = set(int(i) for i in colour if i < n_true)
    for i in range(n_true):
        if i not in matched:
            rgba[i] = next(spare, rgba[i])
    return rgba


def _segment_ticks(result: SegmentationResult, n: int) -> tuple[Any, list[str], np.ndarray]:
    """The segments' colour-bar ticks (label 0..n−1 named by its ``labels.tif`` value,
    and by its material with a scribble classifier: the legend) and their RGBA, the
    colours the viewer draws them in (:func:`~napari_polarseg.palette.label_rgba`)."""
    from ..engine.materials import display_values, file_values
    from ..palette import label_rgba

    materials = result.materials if result.materials is not None else None
    if materials is not None and len(materials.values) < n:
        materials = None  # labels the materials do not describe: numbered only
    values = file_values(n, materials)
    if materials is None:
        names = [str(v) for v in values]
    else:
        names = [f"{v} {name}" for v, name in zip(values, materials.names, strict=False)]
    return np.arange(n), names[:n], label_rgba(display_values(n, materials)[:n])


def _label_panels(
    result: SegmentationResult, truth: np.ndarray | None
) -> tuple[list[Panel], Ticks]:
    """The segments' panel and, with ``truth``, the ground truth's, matched in colour;
    their colour-bar ticks (and colours)."""
    from ..engine.analysis.evaluation import adjusted_rand_index

    labels = np.asarray(result.labels)
    n = max(result.n_segments, int(labels.max(initial=0)) + 1, 1)
    seg_title = f"segments ({result.n_segments})"
    # each label panel shows its values 0, 1, ... in order, in the viewer's colours;
    # with the truth, a material is drawn in the colour of the segment matched to it
    ticks: Ticks = {"segments": _segment_ticks(result, n)}
    if truth is None:
        return [(seg_title, labels, "segments", -0.5, n - 0.5)], ticks
    true_index, colour = segment_colours_for(truth, labels)
    true_values = np.unique(np.asarray(truth))
    m = true_values.size
    seg_rgba = ticks["segments"][2]
    ticks["truth"] = (np.arange(m), [str(v) for v in true_values], _truth_rgba(seg_rgba, colour, m))
    seg_title += f", ARI {adjusted_rand_index(truth, result.labels):.3f}"
    return (
        [
            (seg_title, labels, "segments", -0.5, n - 0.5),
            (f"ground truth ({m})", true_index, "truth", -0.5, m - 0.5),
        ],
        ticks,
    )


def _panels(
    first_frame: np.ndarray,
    result: SegmentationResult,
    truth: np.ndarray | None,
    composite: np.ndarray | None,
    dolp_max: float | None,
) -> tuple[list[Panel], Ticks]:
    """Every panel of the overview in order, the label panels' ticks and colours."""
    if composite is None:
        if dolp_max is None:
            dolp_max = auto_dolp_max(result.dop)
        composite = aolp_dolp_composite(
            result.intensity, result.dop, result.phase, CompositeParams(dolp_max=dolp_max)
        )
    hsv_title = "AoLP hue, DoLP saturation"
    if dolp_max is not None:
        hsv_title += f"\n(full at ρ = {dolp_max:g})"
    label_panels, ticks = _label_panels(result, truth)
    error = result.reconstruction_error
    if error is None:
        note = f"not computed by\nthe {result.method}\nmethod\n\n(--thesis-maps\ncomputes it)"
        error_panel: Panel = ("reconstruction error", note, NOT_COMPUTED, None, None)
    else:
        finite_err = error[np.isfinite(error)]
        err_max = float(np.percentile(finite_err, 99)) if finite_err.size else 1.0
        error_panel = ("reconstruction error", error, "magma", 0.0, err_max or None)
    panels: list[Panel] = [
        ("input (first frame)", first_frame, "gray", None, None),
        ("Î mean intensity", result.intensity, "gray", None, None),
        ("ρ degree of polarisation", result.dop, "viridis", 0.0, None),
        ("φ phase (rad)", result.phase, "twilight", 0.0, np.pi),
        (hsv_title, composite, "rgb", None, None),
        *label_panels,
        error_panel,
    ]
    return panels, ticks


def _draw_panel(fig: Figure, ax: Any, panel: Panel, ticks: Ticks) -> None:
    """One panel and its colour bar (hue degrees for the composite, label ticks); a map
    the method did not compute is a framed note, with no colour bar."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, Normalize
    from matplotlib.patches import Rectangle

    title, image, cmap, vmin, vmax = panel
    ax.set_title(title, fontsize=10)
    ax.set_axis_off()
    if cmap == NOT_COMPUTED:
        ax.text(0.5, 0.5, image, ha="center", va="center", fontsize=9, transform=ax.transAxes)
        ax.add_patch(
            Rectangle((0, 0), 1, 1, transform=ax.transAxes, fill=False, ls="--", clip_on=False)
        )
        return
    if cmap == "rgb":
        ax.imshow(image, interpolation="nearest")
        hue = ScalarMappable(Normalize(0.0, 180.0), colormaps["hsv"])
        bar = fig.colorbar(hue, ax=ax, fraction=0.046, pad=0.02)
        bar.set_ticks([0, 45, 90, 135, 180])
        bar.ax.set_title("AoLP °", fontsize=8)  # above the bar: a side label met the next panel
        return
    is_labels = cmap in ticks
    if is_labels:
        values, names, colours = ticks[cmap]
        panel_cmap: Any = ListedColormap(np.asarray(colours, dtype=float))
    else:
        panel_cmap = cmap
    shown = ax.imshow(
        np.asarray(image, dtype=float),
        cmap=panel_cmap,
        vmin=vmin,
        vmax=vmax,
        interpolation="nearest",
    )
    bar = fig.colorbar(shown, ax=ax, fraction=0.046, pad=0.02)
    if is_labels:
        if len(names) <= 12:
            bar.set_ticks(np.asarray(values, dtype=float), labels=names)
        else:
            bar.set_ticks(np.linspace(0, len(names) - 1, 5).round())


def overview_figure(
    first_frame: np.ndarray,
    result: SegmentationResult,
    *,
    truth: np.ndarray | None = None,
    composite: np.ndarray | None = None,
    dolp_max: float | None = None,
) -> Figure:
    """The figure of ``overview.png``: one panel per map, in rows of :data:`COLUMNS`.

    Input, Î, ρ, φ, the AoLP/DoLP HSV composite, the segments, the ground truth (when
    given) and the reconstruction error. Uses matplotlib's object-oriented API on an Agg
    canvas (no pyplot, so no global backend is switched and no window opens; safe in a
    worker thread); :func:`render_overview` draws it into pixels.

    Parameters
    ----------
    first_frame : array (H, W)
        First frame of the angle stack.
    result : SegmentationResult
        The pipeline's result.
    truth : array (H, W) of int, optional
        The true materials: drawn beside the segments, in the colours of the segments
        they are matched to, and the segments' title gives the adjusted Rand index.
    composite : array (H, W, 3) uint8, optional
        The AoLP/DoLP HSV composite
        (:func:`napari_polarseg.engine.analysis.views.aolp_dolp_composite`);
        computed with ρ_max = ``dolp_max`` (default
        :func:`~napari_polarseg.engine.analysis.views.auto_dolp_max`) when not given.
    dolp_max : float, optional
        The composite's ρ_max, for its title.

    Returns
    -------
    matplotlib.figure.Figure
        On an Agg canvas, laid out; ``fig.axes[:n]`` are the n panels in order, their
        colour bars follow.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels, ticks = _panels(first_frame, result, truth, composite, dolp_max)
    h, w = result.labels.shape
    rows = -(-len(panels) // COLUMNS)
    panel_w = 3.4  # inches per panel, its colour bar included
    panel_h = (panel_w - 0.6) * h / w + 0.5  # the image, the title
    fig = Figure(figsize=(panel_w * COLUMNS, panel_h * rows), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, COLUMNS, squeeze=False).ravel()
    for ax, panel in zip(axes, panels, strict=False):
        _draw_panel(fig, ax, panel, ticks)
    for ax in axes[len(panels) :]:
        fig.delaxes(ax)
    for ax, panel in zip(axes, panels, strict=False):
        if panel[2] == NOT_COMPUTED:
            ax.set_box_aspect(h / w)  # a note the shape of the image panels
    return fig


def render_overview(
    first_frame: np.ndarray,
    result: SegmentationResult,
    *,
    truth: np.ndarray | None = None,
    composite: np.ndarray | None = None,
    dolp_max: float | None = None,
) -> np.ndarray:
    """Draw :func:`overview_figure` (same arguments) into pixels.

    Returns
    -------
    ndarray (rows, columns, 4) uint8
        The RGBA figure, ready for :func:`napari_polarseg.io.write_png`.
    """
    fig = overview_figure(first_frame, result, truth=truth, composite=composite, dolp_max=dolp_max)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba()).copy()
