"""The "Parameter sweep" widget: score a grid of parameters on the chosen angle stack.

For the thesis method (a method that cuts blocks) the grid is w, L and n: thin, the sweep
is :func:`napari_polarseg.engine.analysis.sweep.iter_sweep` run in a napari worker
(progress bar per cell, *Cancel* stops after the running cell), the heatmaps are
:func:`napari_polarseg.outputs.figures.sweep_heatmap_figure` on a matplotlib canvas themed
like napari, the table is the sweep's rows. For another method (the parameters' method,
e.g. preset auto's) the grid is the values typed for its own parameters and the shared
ones it reads (:mod:`.method_sweep`, as ``polarseg sweep --vary``): the cells are
:func:`~napari_polarseg.engine.analysis.param_sweep.iter_param_sweep`'s, drawn by
:func:`~napari_polarseg.outputs.figures.param_sweep_figure`. *Use best* hands the best
cell's parameters to the *Segment by material* widget (docking it if needed) and runs it;
*Save best…* writes them as a SegmentParams JSON file (the format of ``polarseg segment
--params``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Generator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import ComboBox, Container, LineEdit, PushButton, SpinBox, Table

from ..engine import PolarsegError, SegmentParams, validity_mask
from ..engine.analysis.param_sweep import ParamCell, ParamSweepResult
from ..engine.analysis.sweep import check_grid, iter_sweep
from ..engine.analysis.sweep_result import DEFAULT_SCORE, SCORES, SweepResult
from ..engine.params import PRESETS
from ..engine.registered import computes_block_maps
from ..outputs import figures
from ._base import StackWidget, ask_file
from .canvas import figure_canvas, napari_theme, show_message
from .docks import segment_dock
from .method_sweep import (
    MethodAxes,
    cell_text,
    method_sweep_job,
    param_score,
    param_sweep_table,
    table_value,
)
from .param_sources import params_from
from .session import relay, write_params_json

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

    from .segment import SegmentWidget

#: Where the sweep's other parameters come from (the first is the default); their method
#: decides what is swept (the thesis method: w, L, n; another: its own parameters).
PARAM_SOURCES = ("recommended", "thesis", "auto", "Segment by material widget")
#: Heatmap menu: text shown → column of the sweep.
HEATMAPS = (
    ("stability", "stability"),
    ("combined score", "score"),
    ("silhouette", "silhouette"),
    ("mean Ncut", "mean_ncut"),
    ("ARI (ground truth)", "ari"),
    ("seconds", "seconds"),
)
#: Table columns: header → sweep column.
TABLE_COLUMNS = (
    ("best", None),
    ("n", "refractive_index"),
    ("w", "window"),
    ("L", "degree"),
    ("segments", "n_segments"),
    ("stability", "stability"),
    ("silhouette", "silhouette"),
    ("mean Ncut", "mean_ncut"),
    ("score", "score"),
    ("ARI", "ari"),
    ("seconds", "seconds"),
    ("error", "error"),
)
#: Display name of the Segment widget in the manifest.
SEGMENT_WIDGET = "Segment by material"


def parse_numbers(text: str, kind: type, what: str) -> list:
    """Numbers from ``"8, 10, 12"`` (commas, semicolons or spaces); raises PolarsegError."""
    parts = [p for p in re.split(r"[,;\s]+", str(text).strip()) if p]
    if not parts:
        raise PolarsegError(f"give the {what}, e.g. {'8,10,12' if kind is int else '1.45,1.6'}")
    out = []
    for p in parts:
        try:
            out.append(kind(p))
        except ValueError:
            raise PolarsegError(
                f"{what} must be {'whole ' if kind is int else ''}numbers, got {p!r}"
            ) from None
    return out


def sweep_table(result: SweepResult | None) -> dict[str, list[Any]]:
    """Table data (header → values) of a sweep's cells; the best cell is marked ★."""
    if result is None:
        return {head: [] for head, _ in TABLE_COLUMNS}
    try:
        best = result.best_cell()
    except PolarsegError:
        best = None
    out: dict[str, list[Any]] = {}
    for head, column in TABLE_COLUMNS:
        if column is None:
            out[head] = ["★" if c is best else "" for c in result.cells]
        elif column == "refractive_index":
            out[head] = [f"{c.refractive_index:g}" for c in result.cells]
        else:
            out[head] = [table_value(getattr(c, column)) for c in result.cells]
    return out


def sweep_job(
    data: Any,
    angles_rad: np.ndarray,
    base: SegmentParams,
    windows: list[int],
    degrees: list[int],
    refractive_indices: list[float] | None,
    truth: np.ndarray | None,
    score: str,
) -> Generator[tuple[str, int, int], None, SweepResult]:
    """Worker job: the sweep, yielding ``("w=… L=… n=…", done, total)`` after each cell.

    Saturated and black samples are left out as in the Segment widget. Stopping the
    worker between two yields stops the sweep.
    """
    stack = np.asarray(data)
    mask = validity_mask(stack, saturation="auto", dark_level=0)
    gen = iter_sweep(
        stack, angles_rad, base, windows, degrees, refractive_indices, truth, score, mask=mask
    )
    try:
        return (yield from relay(gen, cell_stage))
    finally:
        gen.close()


def cell_stage(item: tuple[int, int, Any]) -> tuple[str, int, int]:
    """``("w=… L=… n=…", done, total)`` of a sweep's ``(done, total, cell)``."""
    done, total, cell = item
    return f"w={cell.window} L={cell.degree} n={cell.refractive_index:g}", done, total


def best_buttons() -> tuple[PushButton, PushButton]:
    """*Use best* and *Save best…* (enabled once a sweep has a best cell)."""
    use_button = PushButton(
        text="Use best",
        enabled=False,
        tooltip="Set the Segment by material widget (docked if needed) to the preset "
        "and the best cell's swept parameters, and segment the swept stack",
    )
    save_button = PushButton(
        text="Save best…",
        enabled=False,
        tooltip="Write the best cell's parameters as JSON (what polarseg segment "
        "--params and the batch widget read)",
    )
    return use_button, save_button


class SweepWidget(StackWidget):
    """Sweep the parameters of the chosen method on an angle stack.

    The parameters come from a preset (recommended, thesis, auto) or from the docked
    *Segment by material* widget; *segments* (0: from those parameters) sets the number
    of segments. Their method decides the grid: for the thesis method (a method that
    cuts blocks) window size w, harmonic degree L and refractive index n, typed as lists
    (``8,10,12``); for another method one list of values per parameter it declares
    (its own, then the shared ones it reads, e.g. object size and segments; an empty
    field is not swept), as ``polarseg sweep --vary``. With a *ground truth* Labels
    layer (any label ids; the stack's height × width) every cell also gets its adjusted
    Rand index. *best by* chooses the criterion of the best cell (the default, stability,
    is the label-free one that tracked the ground truth best on the synthetic scenes;
    docs/cli.md, "Parameter sweep"). *Run sweep* runs in a worker with a progress bar;
    *Cancel* stops after the running cell. The canvas shows one metric as heatmaps (rows
    w, columns L, one per n; the best cell outlined), or for another method's sweep as
    one bar per cell (stability, ARI or seconds; the best by stability or ARI), and the
    table every cell.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers the widget reads.
    """

    run_text = "Run sweep"
    run_tooltip = "Segment the chosen stack for every cell of the grid and score each"
    dock_title = "Sweep"
    progress_desc = "Parameter sweep"

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(viewer)
        self.result: SweepResult | ParamSweepResult | None = None
        self._source: Layer | None = None
        self.source = ComboBox(
            label="parameters",
            choices=list(PARAM_SOURCES),
            value=PARAM_SOURCES[0],
            tooltip="The parameters of every cell apart from the swept ones; their method "
            "decides what is swept: the thesis method's block window w, degree L and "
            "refractive index n, or another method's own parameters and the shared ones "
            "it reads (preset auto: object size, segments, fit). "
            "'Use best' sets the Segment widget to this preset and the best cell",
        )
        self.windows = LineEdit(
            label="windows w", value="8,10,12", tooltip="Window sizes in pixels, comma-separated"
        )
        self.degrees = LineEdit(
            label="degrees L", value="4,8,12", tooltip="Harmonic degrees, comma-separated"
        )
        self.refractive_indices = LineEdit(
            label="refractive indices n",
            value="",
            tooltip="Refractive indices, comma-separated; empty: the parameters' n",
        )
        self.n_segments = SpinBox(
            label="segments", value=0, min=0, max=256, tooltip="0: from the parameters"
        )
        self.ground_truth = self._labels_box(
            "ground truth",
            "none",
            "A Labels layer of the true materials (the stack's height x width): adds "
            "the adjusted Rand index of every cell",
        )
        self.score = ComboBox(
            label="best by",
            choices=list(SCORES),
            value=DEFAULT_SCORE,
            tooltip="What picks the best cell: stability (mean ARI with the neighbouring "
            "cells), the combined label-free score, silhouette, the smallest mean Ncut, or "
            "the ARI against the ground truth",
        )
        self.metric = ComboBox(
            label="heatmap", choices=list(HEATMAPS), value="stability", tooltip="Metric shown"
        )
        self.use_button, self.save_button = best_buttons()
        self._add_parameters(
            [
                self.source,
                self.windows,
                self.degrees,
                self.refractive_indices,
                self.n_segments,
                self.ground_truth,
                self.score,
            ]
        )
        self.theme = napari_theme(viewer)
        self.figure, self.canvas = figure_canvas((4.0, 3.0), min_height=260)
        self.table = Table(value=sweep_table(None))
        self.table.native.setMinimumHeight(160)
        buttons = Container(layout="horizontal", widgets=[self.use_button, self.save_button])
        buttons.margins = (0, 0, 0, 0)
        self.append(self.metric)
        # below the labelled controls: heatmaps, the two buttons, the table
        self.add_native(self.canvas, expand=True)
        self.add_native(buttons.native)
        self.add_native(self.table.native)
        self._buttons = buttons
        self.metric.changed.connect(self.draw)
        self.use_button.changed.connect(self.use_best)
        self.save_button.changed.connect(self._save_clicked)
        self.stack_layer.changed.connect(self.ground_truth.reset_choices)
        self.method_axes = MethodAxes(self, self.n_segments)
        self.source.changed.connect(self.show_axes)
        self.show_axes()
        self.draw()

    # -- inputs -----------------------------------------------------------------------
    def _refresh_stacks(self) -> None:
        super()._refresh_stacks()
        truth = getattr(self, "ground_truth", None)  # None while the base class initialises
        if truth is not None:
            truth.reset_choices()

    def base_params(self) -> SegmentParams:
        """The parameters of every cell apart from w, L, n (raises PolarsegError)."""
        params = params_from(self._viewer, self.source.value)
        if int(self.n_segments.value) > 0:
            params = params.replace(n_segments=int(self.n_segments.value))
        return params

    def show_axes(self, *_: Any) -> SegmentParams | None:
        """Show the fields of what the parameters' method sweeps: w, L and n for a
        method that cuts blocks, else one field of values per parameter of the method
        (:class:`~.method_sweep.MethodAxes`). Returns the parameters (None when they
        cannot be read now, e.g. no Segment widget: the fields stay)."""
        try:
            base = self.base_params()
        except PolarsegError:
            return None
        blocks = computes_block_maps(base.method)
        for box in (self.windows, self.degrees, self.refractive_indices):
            box.visible = blocks
        self.method_axes.show(base)
        return base

    def grid(self) -> tuple[list[int], list[int], list[float] | None]:
        """The windows, degrees and refractive indices typed (raises PolarsegError)."""
        windows = parse_numbers(self.windows.value, int, "window sizes")
        degrees = parse_numbers(self.degrees.value, int, "harmonic degrees")
        text = self.refractive_indices.value.strip()
        ns = parse_numbers(text, float, "refractive indices") if text else None
        return windows, degrees, ns

    # -- running ----------------------------------------------------------------------
    def grid_job(self, base: SegmentParams) -> tuple[Any, tuple[Any, ...], int]:
        """(job, its grid arguments, cells) of a sweep of the thesis block grid."""
        windows, degrees, ns = self.grid()
        ws, ls, nn = check_grid(base, windows, degrees, ns)
        return sweep_job, (windows, degrees, ns), len(ws) * len(ls) * len(nn)

    def method_job(self, base: SegmentParams, score: str) -> tuple[Any, tuple[Any, ...], int]:
        """(job, its axes argument, cells) of a sweep of ``base.method``'s parameters."""
        param_score(score)
        axes = self.method_axes.axes(base)
        return method_sweep_job, (axes,), math.prod(len(v) for v in axes.values())

    def run(self, *_: Any) -> None:
        """Start the sweep in a worker; returns at once."""
        try:
            layer, angles_deg = self.current_stack()
            base = self.show_axes() or self.base_params()
            truth_layer = self.ground_truth.value
            truth = None if truth_layer is None else np.asarray(truth_layer.data)
            score = self.score.value
            if computes_block_maps(base.method):
                job, grid, total = self.grid_job(base)
            else:
                job, grid, total = self.method_job(base, score)
            if score == "ari" and truth is None:
                raise PolarsegError("'best by ari' needs a ground-truth Labels layer")
        except PolarsegError as exc:
            self._fail(exc)
            return

        def on_result(run_id: int, result: SweepResult | ParamSweepResult) -> None:
            if layer in self._viewer.layers:
                self.set_result(layer, result)

        args = (layer.data, np.deg2rad(angles_deg), base, *grid, truth, score)
        self._set_status(f"running {total} cells…")
        self._submit(job, args, total, on_result)

    def set_result(self, layer: Layer, result: SweepResult | ParamSweepResult) -> None:
        """Show ``result`` (a sweep of ``layer``): heatmap or bars, table, status."""
        self.result, self._source = result, layer
        by_method = isinstance(result, ParamSweepResult)
        self.table.value = param_sweep_table(result) if by_method else sweep_table(result)
        self.table.native.resizeColumnsToContents()
        failed = sum(not c.ok for c in result.cells)
        try:
            text = f"best by {result.score}: {self.best_text()}"
            self.use_button.enabled = self.save_button.enabled = True
        except PolarsegError as exc:
            text = str(exc)
            self.use_button.enabled = self.save_button.enabled = False
        self._done(
            f"{text} · {len(result.cells)} cells ({failed} failed) in {result.total_seconds:.2f} s"
        )
        self.draw()

    # -- drawing ----------------------------------------------------------------------
    def draw(self, *_: Any) -> None:
        """Draw the chosen metric's heatmaps (a hint before the first sweep)."""
        result, theme = self.result, self.theme
        if result is None:
            show_message(self.figure, theme, "press 'Run sweep' to score the grid")
        elif isinstance(result, ParamSweepResult):
            metric = self.metric.value
            if metric not in figures.PARAM_SWEEP_METRICS or (
                metric == "ari" and not result.has_ground_truth
            ):
                metric = "stability"
            figures.param_sweep_figure(result, metric, fig=self.figure, theme=theme)
        else:
            metric = self.metric.value
            if metric == "ari" and not result.has_ground_truth:
                metric = "stability"
            figures.sweep_heatmap_figure(result, metric, fig=self.figure, theme=theme)
        self.canvas.draw_idle()

    # -- the best cell ----------------------------------------------------------------
    def best_params(self) -> SegmentParams:
        """The best cell's parameters (raises PolarsegError before a sweep)."""
        if self.result is None:
            raise PolarsegError("run a sweep first")
        return self.result.best()

    def best_text(self) -> str:
        """The best cell's swept values: ``"w = 8, L = 4, n = 1.45"`` for the thesis
        grid, ``"object_size = 20"`` for another method's (PolarsegError without one)."""
        if self.result is None:
            raise PolarsegError("run a sweep first")
        best = self.result.best_cell()
        if isinstance(best, ParamCell):
            return cell_text(best)
        return f"w = {best.window}, L = {best.degree}, n = {best.refractive_index:g}"

    def segment_widget(self) -> SegmentWidget:
        """The docked *Segment by material* widget, docked now if it is not."""
        widget = segment_dock(self._viewer)
        if widget is not None:
            return widget
        _, widget = self._viewer.window.add_plugin_dock_widget("napari-polarseg", SEGMENT_WIDGET)
        return widget

    def use_best(self, *_: Any) -> SegmentWidget | None:
        """Set the Segment widget to the best cell's parameters on this stack and run it.

        Its preset menu shows the preset the sweep started from (when one was chosen as
        the *parameters*), its controls the best cell's method and swept values."""
        try:
            params = self.best_params()
            chosen = self.best_text()
            source = self._source
            if source is None or source not in self._viewer.layers:
                raise PolarsegError("the swept stack layer is no longer in the viewer")
        except PolarsegError as exc:
            self._fail(exc)
            return None
        widget = self.segment_widget()
        widget.stack_layer.value = source
        if not widget.angles.value:
            widget.angles.value = self.angles.value
        if self.source.value in PRESETS:  # the preset the cells started from (not auto)
            widget.preset.value = self.source.value
        widget.set_params(params)
        widget.run()
        self._done(f"'{SEGMENT_WIDGET}' runs {chosen}")
        return widget

    def save_best(self, path: str | Path | None = None) -> Path | None:
        """Write the best parameters as SegmentParams JSON (asks for a file if no ``path``).

        The file is what ``polarseg segment --params`` and the batch widget read.
        """
        try:
            params = self.best_params()
        except PolarsegError as exc:
            self._fail(exc)
            return None
        if path is None:
            path = ask_file(
                self.native, "Save the best parameters", "best_params.json", "JSON (*.json)", True
            )
            if path is None:
                return None
        path = Path(path)
        try:
            write_params_json(path, params)
        except OSError as exc:
            self._fail(PolarsegError(f"cannot write {path}: {exc.strerror or exc}"))
            return None
        self._done(f"saved the best parameters to {path}")
        return path

    def _save_clicked(self, *_: Any) -> None:
        self.save_best()
