"""The result of a parameter sweep (:mod:`.sweep`): one :class:`SweepCell` per (n, w, L), the
:class:`SweepResult` grid, its best cell by a criterion (:data:`SCORES`), and its CSV and
JSON forms (the ``sweep.csv`` columns: :data:`COLUMNS`).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import PolarsegError
from ..params import SegmentParams

#: Criteria a sweep can pick its best cell by (``score`` and ``best(by=...)``).
SCORES = ("stability", "combined", "silhouette", "ncut", "ari")


#: Default criterion (see the module docstring for why).
DEFAULT_SCORE = "stability"


#: Column of each criterion, and whether larger is better.
SCORE_COLUMNS = {
    "combined": ("score", True),
    "silhouette": ("silhouette", True),
    "ncut": ("mean_ncut", False),
    "stability": ("stability", True),
    "ari": ("ari", True),
}


#: Columns of :meth:`SweepResult.to_rows` (and ``sweep.csv``) in order.
COLUMNS = (
    "refractive_index",
    "window",
    "degree",
    "n_segments",
    "n_blocks",
    "n_components",
    "mean_ncut",
    "silhouette",
    "stability",
    "ari",
    "score",
    "seconds",
    "error",
)


#: Numeric columns :meth:`SweepResult.grid` can return.
METRICS = (
    "score",
    "silhouette",
    "mean_ncut",
    "stability",
    "ari",
    "seconds",
    "n_segments",
    "n_blocks",
    "n_components",
)


_INT_COLUMNS = ("window", "degree", "n_segments", "n_blocks", "n_components")


@dataclass
class SweepCell:
    """One cell of the grid: its setting, its scores, and (in memory) its labels.

    Attributes
    ----------
    index : tuple of int
        Position (n index, w index, L index) in the grid.
    refractive_index, window, degree
        The setting: n (dimensionless), w (pixels), L.
    n_segments, n_blocks, n_components : int
        Segments reached, blocks segmented, PCA components kept (0 if the cell failed).
    mean_ncut, silhouette, stability, ari, score : float
        Scores (module docstring); NaN when undefined.
    ncut_values : list of float
        Ncut value of each cut, in order.
    seconds : float
        Seconds of the cell's pipeline run and silhouette.
    recomputed : list of str
        Pipeline stages this cell computed (the others came from the cache).
    error : str or None
        Why the cell could not run (then every score is NaN).
    labels : ndarray (H, W) or None
        Pixel labels (0 = first segment); not serialised.
    """

    index: tuple[int, int, int]
    refractive_index: float
    window: int
    degree: int
    n_segments: int = 0
    n_blocks: int = 0
    n_components: int = 0
    mean_ncut: float = math.nan
    silhouette: float = math.nan
    stability: float = math.nan
    ari: float = math.nan
    score: float = math.nan
    ncut_values: list[float] = field(default_factory=list)
    seconds: float = 0.0
    recomputed: list[str] = field(default_factory=list)
    error: str | None = None
    labels: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        """True if the cell ran."""
        return self.error is None

    def params(self, base: SegmentParams) -> SegmentParams:
        """``base`` with this cell's window, degree and refractive index."""
        return base.replace(
            window=self.window, degree=self.degree, refractive_index=self.refractive_index
        )

    def row(self) -> dict[str, Any]:
        """The cell as a table row (:data:`COLUMNS`)."""
        return {c: getattr(self, c) for c in COLUMNS}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the row plus its grid index, Ncut values and recomputed stages."""
        return {
            **self.row(),
            "index": list(self.index),
            "ncut_values": [float(v) for v in self.ncut_values],
            "recomputed": list(self.recomputed),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SweepCell:
        """Inverse of :meth:`to_dict` (no labels); None becomes NaN."""
        values: dict[str, Any] = {}
        for c in COLUMNS:
            v = data.get(c)
            if c == "error":
                values[c] = None if v in (None, "") else str(v)
            elif c in _INT_COLUMNS:
                values[c] = int(v) if v not in (None, "") else 0
            else:
                values[c] = float(v) if v not in (None, "") else math.nan
        index = tuple(int(i) for i in data.get("index", (0, 0, 0)))
        return cls(
            index=index,  # type: ignore[arg-type]
            ncut_values=[float(v) for v in data.get("ncut_values", [])],
            recomputed=[str(s) for s in data.get("recomputed", [])],
            **values,
        )


@dataclass
class SweepResult:
    """Every cell of a sweep, with the best cell and tables for heatmaps.

    Attributes
    ----------
    base : SegmentParams
        Parameters of every cell apart from w, L and n.
    windows, degrees : tuple of int
        Grid axes (ascending); ``refractive_indices`` the n axis (ascending).
    cells : list of SweepCell
        In run order: n outermost, then w, then L.
    score : str
        The criterion :meth:`best` uses by default (one of :data:`SCORES`).
    has_ground_truth : bool
        Whether the ``ari`` column was computed.
    total_seconds : float
        Wall-clock seconds of the whole sweep.
    stage_calls : dict of str to int
        How often the pipeline computed each stage over the whole sweep (the others
        came from its cache): ``polarisation`` once, ``normals`` once per n,
        ``harmonics`` and later stages once per cell that got that far.
    """

    base: SegmentParams
    windows: tuple[int, ...]
    degrees: tuple[int, ...]
    refractive_indices: tuple[float, ...]
    cells: list[SweepCell]
    score: str = DEFAULT_SCORE
    has_ground_truth: bool = False
    total_seconds: float = 0.0
    stage_calls: dict[str, int] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Grid shape (n values, windows, degrees)."""
        return (len(self.refractive_indices), len(self.windows), len(self.degrees))

    def cell(self, refractive_index: float, window: int, degree: int) -> SweepCell:
        """The cell of a setting (raises PolarsegError if it is not in the grid)."""
        for c in self.cells:
            if (
                c.window == window
                and c.degree == degree
                and math.isclose(c.refractive_index, refractive_index)
            ):
                return c
        raise PolarsegError(f"no cell w={window}, L={degree}, n={refractive_index:g} in the sweep")

    def to_rows(self) -> list[dict[str, Any]]:
        """One dict per cell (:data:`COLUMNS`), in run order."""
        return [c.row() for c in self.cells]

    def grid(self, metric: str = "score") -> np.ndarray:
        """Values of a column on the grid: array (n values, windows, degrees).

        ``grid(metric)[k]`` is the w × L table (rows w, columns L) for the k-th
        refractive index. ``metric`` is one of :data:`METRICS` (or a criterion of
        :data:`SCORES`); failed cells and undefined scores are NaN.
        """
        column = _column(metric)
        if column not in METRICS:
            raise PolarsegError(f"metric must be one of {', '.join(METRICS)}; got {metric!r}")
        out = np.full(self.shape, np.nan)
        for c in self.cells:
            if c.ok or column in ("seconds",):
                out[c.index] = float(getattr(c, column))
        return out

    def _criterion(self, by: str | None) -> tuple[str, bool]:
        by = self.score if by is None else by
        if by == "score":
            by = "combined"
        if by == "mean_ncut":
            by = "ncut"
        if by not in SCORE_COLUMNS:
            raise PolarsegError(f"best cell by must be one of {', '.join(SCORES)}; got {by!r}")
        if by == "ari" and not self.has_ground_truth:
            raise PolarsegError("the best cell by 'ari' needs a ground truth")
        return SCORE_COLUMNS[by]

    def best_cell(self, by: str | None = None) -> SweepCell:
        """The cell with the best ``by`` (default: :attr:`score`).

        Larger is better except for ``"ncut"`` (mean Ncut value, smaller is better).
        Cells that failed, reached only one segment (they segmented nothing, and their
        stability against other one-segment cells is a meaningless 1) or whose value is
        NaN are skipped; ties go to the first cell in run order. Raises
        :class:`PolarsegError` if no cell is left.
        """
        column, larger = self._criterion(by)
        best: SweepCell | None = None
        for c in self.cells:
            v = float(getattr(c, column))
            if not c.ok or c.n_segments < 2 or not math.isfinite(v):
                continue
            if best is None:
                best = c
                continue
            b = float(getattr(best, column))
            if (v > b) if larger else (v < b):
                best = c
        if best is None:
            raise PolarsegError(f"no cell of the sweep reached two segments with a finite {column}")
        return best

    def best(self, by: str | None = None) -> SegmentParams:
        """Parameters of :meth:`best_cell` (``base`` with its w, L and n)."""
        return self.best_cell(by).params(self.base)

    def labels(self, cell: SweepCell) -> np.ndarray:
        """Pixel labels of ``cell`` (raises PolarsegError if not kept or failed)."""
        if cell.labels is None:
            raise PolarsegError(
                f"no labels for w={cell.window}, L={cell.degree}: "
                + (cell.error or "not kept (a sweep read from a file)")
            )
        return cell.labels

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: axes, base parameters, cells, best cell, total seconds.

        NaN values are left as floats (``io.write_json`` writes them as null).
        """
        best: dict[str, Any] | None
        try:
            cell = self.best_cell()
            best = {
                "by": self.score,
                "cell": cell.row(),
                "params": cell.params(self.base).to_dict(),
            }
        except PolarsegError:
            best = None
        return {
            "windows": list(self.windows),
            "degrees": list(self.degrees),
            "refractive_indices": list(self.refractive_indices),
            "score": self.score,
            "has_ground_truth": self.has_ground_truth,
            "total_seconds": round(self.total_seconds, 6),
            "stage_calls": dict(self.stage_calls),
            "n_cells": len(self.cells),
            "n_failed": sum(not c.ok for c in self.cells),
            "base_params": self.base.to_dict(),
            "best": best,
            "cells": [c.to_dict() for c in self.cells],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SweepResult:
        """Inverse of :meth:`to_dict` (e.g. a ``sweep.json``; labels are not kept)."""
        try:
            return cls(
                base=SegmentParams.from_dict(data["base_params"]),
                windows=tuple(int(v) for v in data["windows"]),
                degrees=tuple(int(v) for v in data["degrees"]),
                refractive_indices=tuple(float(v) for v in data["refractive_indices"]),
                cells=[SweepCell.from_dict(c) for c in data["cells"]],
                score=str(data.get("score", DEFAULT_SCORE)),
                has_ground_truth=bool(data.get("has_ground_truth", False)),
                total_seconds=float(data.get("total_seconds", 0.0)),
                stage_calls={str(k): int(v) for k, v in data.get("stage_calls", {}).items()},
            )
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, PolarsegError):
                raise
            raise PolarsegError(f"not a sweep summary ({type(exc).__name__}: {exc})") from None

    def to_csv(self) -> str:
        """The table as CSV text (:data:`COLUMNS`; NaN and None are empty)."""
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(COLUMNS)
        for row in self.to_rows():
            writer.writerow([_csv_value(row[c]) for c in COLUMNS])
        return buf.getvalue()


def _csv_value(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if not math.isfinite(value) else repr(value)
    return str(value)


def _column(metric: str) -> str:
    if metric in SCORE_COLUMNS:
        return SCORE_COLUMNS[metric][0]
    return metric
