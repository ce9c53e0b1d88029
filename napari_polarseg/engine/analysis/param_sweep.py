"""Sweep of a method's parameters: segment one stack for every combination of the values
given for the chosen method's parameters and score every cell.

The parameters a sweep may vary (:func:`sweepable`) are read from the method's own
declaration: the fields of its ``params_class`` and the shared
:class:`~napari_polarseg.engine.params.SegmentParams` fields it reads (its ``reads``, e.g.
``n_segments``, ``object_size``). Every cell runs the method on one
:class:`~napari_polarseg.engine.methods.Scene` (the polarisation image is computed
once; the method's cache key holds its own parameters, so no cell is served another's
labels). Scores, without ground truth and with it:

``stability``
    Mean pixel-level adjusted Rand index between this cell's labels and those of the
    cells one step away along any axis: 1 = the segmentation does not depend on the
    exact setting; NaN without a neighbour that ran.
``ari``
    Pixel-level adjusted Rand index against the ground truth (when given).

The block-grid sweep of the thesis method (window, degree, refractive index, with its
block scores) is :mod:`.sweep`.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import time
import typing
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..errors import Cancelled, PolarsegError
from ..method_params import params_class
from ..param_spec import types_of
from ..params import SegmentParams
from .evaluation import adjusted_rand_index

#: Criteria a parameter sweep picks its best cell by.
PARAM_SCORES = ("stability", "ari")


def sweepable(params: SegmentParams) -> tuple[str, ...]:
    """The parameters a sweep of ``params.method`` may vary: its own (its
    ``params_class``), then the shared fields it reads."""
    from ..methods import get_method  # the registry, at run time

    method = get_method(params.method)
    cls = params_class(params.method)
    own = () if cls is None else tuple(f.name for f in fields(cls))
    shared = tuple(n for n in method.reads if n in SegmentParams.__dataclass_fields__)
    return (*own, *(n for n in shared if n not in own))


def value_from_text(params: SegmentParams, name: str, text: str) -> Any:
    """The value of parameter ``name`` of ``params.method`` written as ``text`` (a
    number, a word, ``none``), converted to the field's type (PolarsegError else)."""
    cls = params_class(params.method)
    owner = cls if cls is not None and name in types_of(cls) else SegmentParams
    kind = types_of(owner).get(name, str)
    kinds = typing.get_args(kind) or (kind,)
    word = text.strip()
    if word.lower() == "none" and type(None) in kinds:
        return None
    for k in (int, float):
        if k in kinds:
            try:
                return k(word)
            except ValueError:
                continue
    if str in kinds:
        return word
    raise PolarsegError(f"{name}: {word!r} is not a value of {kind}")


def check_axes(base: SegmentParams, axes: Mapping[str, Sequence[Any]]) -> dict[str, tuple]:
    """The axes of a sweep of ``base.method``, validated: each a parameter it may vary
    (:func:`sweepable`), each value valid with ``base`` (PolarsegError naming the bad
    one); duplicates dropped, order kept."""
    if not axes:
        raise PolarsegError("a sweep needs at least one parameter to vary")
    allowed = sweepable(base)
    out: dict[str, tuple] = {}
    for name, values in axes.items():
        if name not in allowed:
            raise PolarsegError(
                f"method {base.method} has no parameter {name!r} to sweep; its parameters: "
                + (", ".join(allowed) or "none")
            )
        out[name] = tuple(dict.fromkeys(values))
        if not out[name]:
            raise PolarsegError(f"give at least one value of {name}")
        for value in out[name]:
            base.replace(**{name: value})
    return out


@dataclass
class ParamCell:
    """One cell of a parameter sweep: its values, scores and (in memory) labels.

    Attributes
    ----------
    index : tuple of int
        Position in the grid (one index per axis).
    values : dict
        The value of every swept parameter.
    n_segments : int
        Segments in the labels (0 if the cell failed).
    stability, ari : float
        Scores (module docstring); NaN when undefined.
    seconds : float
        Seconds of the cell's run.
    error : str or None
        Why the cell could not run.
    labels : ndarray (H, W) or None
        Pixel labels; not serialised.
    """

    index: tuple[int, ...]
    values: dict[str, Any]
    n_segments: int = 0
    stability: float = math.nan
    ari: float = math.nan
    seconds: float = 0.0
    error: str | None = None
    labels: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        """True if the cell ran."""
        return self.error is None

    def params(self, base: SegmentParams) -> SegmentParams:
        """``base`` with this cell's values."""
        return base.replace(**self.values)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None)."""

        def plain(v: float) -> float | None:
            return None if not math.isfinite(v) else float(v)

        return {
            "index": list(self.index),
            "values": dict(self.values),
            "n_segments": self.n_segments,
            "stability": plain(self.stability),
            "ari": plain(self.ari),
            "seconds": round(self.seconds, 6),
            "error": self.error,
        }


@dataclass
class ParamSweepResult:
    """A parameter sweep: its base parameters, axes, cells and criterion."""

    base: SegmentParams
    axes: dict[str, tuple]
    cells: list[ParamCell]
    score: str = "stability"
    has_ground_truth: bool = False
    total_seconds: float = 0.0

    def best_cell(self, by: str | None = None) -> ParamCell:
        """The cell that scores best by ``by`` (default :attr:`score`) among those that
        reached two segments (PolarsegError if none did or the score is undefined)."""
        by = by or self.score
        if by not in PARAM_SCORES:
            raise PolarsegError(f"score must be one of {', '.join(PARAM_SCORES)}; got {by!r}")
        scored = [c for c in self.cells if c.ok and c.n_segments > 1]
        scored = [c for c in scored if math.isfinite(getattr(c, by))]
        if not scored:
            raise PolarsegError(f"no cell of the sweep has a {by} score (two segments or more)")
        return max(scored, key=lambda c: getattr(c, by))

    def best(self, by: str | None = None) -> SegmentParams:
        """The parameters of :meth:`best_cell`."""
        return self.best_cell(by).params(self.base)

    def to_csv(self) -> str:
        """One row per cell: the swept values, then the scores."""
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        columns = ["n_segments", "stability", "ari", "seconds", "error"]
        writer.writerow([*self.axes, *columns])
        for c in self.cells:
            row = c.to_dict()
            writer.writerow(
                [c.values[a] for a in self.axes]
                + ["" if row[k] is None else row[k] for k in columns]
            )
        return buf.getvalue()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: base parameters, axes, criterion, cells."""
        return {
            "method": self.base.method,
            "base_params": self.base.to_dict(),
            "axes": {k: list(v) for k, v in self.axes.items()},
            "score": self.score,
            "has_ground_truth": self.has_ground_truth,
            "total_seconds": round(self.total_seconds, 6),
            "cells": [c.to_dict() for c in self.cells],
        }


def neighbour_stability(cells: list[ParamCell]) -> None:
    """Set every cell's stability: the mean pixel ARI with the cells one step away along
    one axis (NaN without such a neighbour that ran)."""
    by_index = {c.index: c for c in cells if c.ok and c.labels is not None}
    pairs: dict[tuple, float] = {}
    for idx, cell in by_index.items():
        scores = []
        for axis, step in itertools.product(range(len(idx)), (-1, 1)):
            nb = idx[:axis] + (idx[axis] + step,) + idx[axis + 1 :]
            other = by_index.get(nb)
            if other is None:
                continue
            key = (min(idx, nb), max(idx, nb))
            if key not in pairs:
                pairs[key] = adjusted_rand_index(cell.labels, other.labels)
            scores.append(pairs[key])
        cell.stability = float(np.mean(scores)) if scores else math.nan


def iter_param_sweep(
    stack: np.ndarray,
    angles: np.ndarray,
    base: SegmentParams,
    axes: Mapping[str, Sequence[Any]],
    ground_truth: np.ndarray | None = None,
    mask: Any = None,
    cancel: Callable[[], bool] | None = None,
    keep_labels: bool = True,
    score: str | None = None,
) -> Iterator[tuple[int, int, ParamCell]]:
    """Segment ``stack`` (angles in radians) with ``base.method`` for every combination
    of the ``axes`` values (parameter name → values), yielding ``(done, total, cell)``
    after each cell; returns (``StopIteration.value``) the :class:`ParamSweepResult`.

    A cell whose values cannot run on this stack records its error; ``cancel()`` is
    checked before every cell and within it (raises :class:`Cancelled`). ``score``:
    the criterion of the best cell, ``ari`` with a ground truth, else ``stability``.
    """
    from ..methods import Scene  # the methods, at run time

    t0 = time.perf_counter()
    grid = check_axes(base, axes)
    truth = None if ground_truth is None else np.asarray(ground_truth)
    score = score or ("ari" if truth is not None else "stability")
    if score == "ari" and truth is None:
        raise PolarsegError("score 'ari' needs a ground truth")
    scene = Scene(stack, angles, mask)
    names = list(grid)
    combos = list(itertools.product(*(range(len(grid[n])) for n in names)))
    cells: list[ParamCell] = []
    for done, index in enumerate(combos, start=1):
        if cancel is not None and cancel():
            raise Cancelled(f"sweep cancelled after {done - 1} of {len(combos)} cells")
        values = {n: grid[n][i] for n, i in zip(names, index, strict=True)}
        cell = ParamCell(index=index, values=values)
        t1 = time.perf_counter()
        try:
            result = scene.segment(
                cell.params(base), maps=False, reconstruction=False, cancel=cancel
            )
            cell.labels, cell.n_segments = result.labels, int(np.unique(result.labels).size)
            if truth is not None:
                cell.ari = adjusted_rand_index(truth, result.labels)
        except (PolarsegError, MemoryError) as exc:
            cell.error = str(exc) or type(exc).__name__
        cell.seconds = time.perf_counter() - t1
        cells.append(cell)
        yield done, len(combos), cell
    neighbour_stability(cells)
    if not keep_labels:
        for c in cells:
            c.labels = None
    return ParamSweepResult(base, grid, cells, score, truth is not None, time.perf_counter() - t0)


def param_sweep(
    stack: np.ndarray,
    angles: np.ndarray,
    base: SegmentParams,
    axes: Mapping[str, Sequence[Any]],
    ground_truth: np.ndarray | None = None,
    mask: Any = None,
    progress: Callable[[int, int], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    keep_labels: bool = True,
    score: str | None = None,
) -> ParamSweepResult:
    """:func:`iter_param_sweep` run to its end (``progress(done, total)`` after every
    cell).

    Examples
    --------
    >>> axes = {"object_size": [20, 40]}                               # doctest: +SKIP
    >>> param_sweep(stack, angles, PRESETS["auto"], axes).best()       # doctest: +SKIP
    """
    gen = iter_param_sweep(
        stack, angles, base, axes, ground_truth, mask, cancel, keep_labels, score
    )
    while True:
        try:
            done, total, _ = next(gen)
        except StopIteration as stop:
            return stop.value
        if progress is not None:
            progress(done, total)
