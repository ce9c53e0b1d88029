"""The *Parameter sweep* dock's sweep of a method that does not cut blocks: its own
parameters and the shared ones it reads, as ``polarseg sweep --vary`` sweeps them.

The parameters offered are the method's declaration
(:func:`~napari_polarseg.engine.analysis.param_sweep.sweepable`: the fields of its
``params_class``, then the shared fields in its ``reads``), each described by its
:class:`~napari_polarseg.engine.param_spec.ParamSpec`. :class:`MethodAxes` keeps one
field of values per parameter in the dock; :func:`method_sweep_job` runs
:func:`~napari_polarseg.engine.analysis.param_sweep.iter_param_sweep` in the worker;
:func:`param_sweep_table` is the table of its cells. The thesis method's grid of w, L and
n stays in :mod:`.sweep`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Generator
from typing import Any

import numpy as np
from magicgui.widgets import Container, LineEdit

from ..engine import PolarsegError, SegmentParams, validity_mask
from ..engine.analysis.param_sweep import (
    PARAM_SCORES,
    ParamCell,
    ParamSweepResult,
    check_axes,
    iter_param_sweep,
    sweepable,
    value_from_text,
)
from ..engine.param_spec import ParamSpec
from ..engine.params import PARAM_SPECS, method_param_specs
from ..engine.registered import computes_block_maps
from .session import relay

#: Score columns of the table of a sweep of a method's parameters: header → cell field.
PARAM_TABLE_SCORES = (
    ("segments", "n_segments"),
    ("stability", "stability"),
    ("ARI", "ari"),
    ("seconds", "seconds"),
    ("error", "error"),
)


def table_value(value: Any) -> Any:
    """A sweep value as a table shows it: "" for None and NaN, floats to 3 decimals."""
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if not math.isfinite(value) else round(value, 3)
    return value


def axis_specs(params: SegmentParams) -> dict[str, ParamSpec]:
    """The :class:`ParamSpec` of every parameter a sweep of ``params.method`` may vary
    (:func:`sweepable`), by name, in that order."""
    specs = {**PARAM_SPECS, **method_param_specs(params.method)}
    return {name: specs[name] for name in sweepable(params) if name in specs}


def axis_edit(name: str, spec: ParamSpec, value: Any) -> LineEdit:
    """The field of the values to sweep of parameter ``name`` (now ``value``)."""
    choices = spec.options()
    what = f"one or more of {', '.join(choices)}" if choices else "comma-separated"
    return LineEdit(
        name=f"vary_{name}",
        label=f"{spec.label or name.replace('_', ' ')} values",
        value="",
        tooltip=f"{spec.help}. The values to sweep, {what}; empty: not swept (the "
        f"parameters' {value!r})",
    )


def parse_axis(params: SegmentParams, name: str, text: str) -> list[Any]:
    """The values of parameter ``name`` typed as ``text`` (commas, semicolons or spaces),
    each of its type (:func:`value_from_text`; PolarsegError naming a bad one)."""
    words = [w for w in re.split(r"[,;\s]+", str(text).strip()) if w]
    return [value_from_text(params, name, w) for w in words]


class MethodAxes:
    """The fields of the values to sweep of one method's parameters, inserted into
    ``container`` before its widget ``before`` (none for a method that cuts blocks: the
    dock's w, L and n grid sweeps it)."""

    def __init__(self, container: Container, before: Any) -> None:
        self.container, self.before = container, before
        #: The method the fields are for (None: no fields)
        self.method: str | None = None
        self.edits: dict[str, LineEdit] = {}

    def show(self, params: SegmentParams | None) -> bool:
        """Show the fields of ``params.method`` (none for a method that cuts blocks, or
        without parameters); values typed for a parameter the new method also has are
        kept. Returns whether the fields changed."""
        method = None if params is None or computes_block_maps(params.method) else params.method
        if method == self.method:
            return False
        typed = {name: edit.value for name, edit in self.edits.items()}
        for edit in self.edits.values():
            self.container.remove(edit)
        self.edits, self.method = {}, method
        if params is not None and method is not None:
            for name, spec in axis_specs(params).items():
                edit = axis_edit(name, spec, getattr(params, name))
                edit.value = typed.get(name, "")
                self.container.insert(self.container.index(self.before), edit)
                self.edits[name] = edit
        return True

    def axes(self, params: SegmentParams) -> dict[str, tuple]:
        """Parameter name → the values typed, for every field filled in, checked with
        ``params`` (:func:`check_axes`); PolarsegError when none is filled in or a value
        is wrong."""
        given = {n: parse_axis(params, n, e.value) for n, e in self.edits.items() if e.value}
        given = {name: values for name, values in given.items() if values}
        if not given:
            names = ", ".join(self.edits) or "none"
            raise PolarsegError(
                f"type the values of at least one parameter of method {params.method} to "
                f"sweep (its parameters: {names})"
            )
        return check_axes(params, given)


def param_score(score: str) -> str:
    """The criterion of the best cell of a sweep of a method's parameters: ``score`` if
    it is one (:data:`PARAM_SCORES`), else PolarsegError."""
    if score not in PARAM_SCORES:
        raise PolarsegError(
            f"a sweep of a method's parameters picks its best cell by "
            f"{' or '.join(PARAM_SCORES)}, not {score}"
        )
    return score


def method_sweep_job(
    data: Any,
    angles_rad: np.ndarray,
    base: SegmentParams,
    axes: dict[str, tuple],
    truth: np.ndarray | None,
    score: str,
) -> Generator[tuple[str, int, int], None, ParamSweepResult]:
    """Worker job: the sweep of ``base.method``'s ``axes``, yielding ``("object_size=20",
    done, total)`` after each cell. Saturated and black samples are left out as in the
    Segment widget; stopping the worker between two yields stops the sweep."""
    stack = np.asarray(data)
    mask = validity_mask(stack, saturation="auto", dark_level=0)
    gen = iter_param_sweep(
        stack, angles_rad, base, axes, truth, mask, keep_labels=False, score=score
    )
    try:
        return (yield from relay(gen, param_cell_stage))
    finally:
        gen.close()


def cell_text(cell: ParamCell) -> str:
    """``"object_size = 20, n_segments = 3"``: a cell's values."""
    return ", ".join(f"{name} = {value}" for name, value in cell.values.items())


def param_cell_stage(item: tuple[int, int, ParamCell]) -> tuple[str, int, int]:
    """``("object_size = 20", done, total)`` of a sweep's ``(done, total, cell)``."""
    done, total, cell = item
    return cell_text(cell), done, total


def param_sweep_table(result: ParamSweepResult) -> dict[str, list[Any]]:
    """Table data (header → values) of a sweep of a method's parameters: the best cell
    marked ★, the swept values, then :data:`PARAM_TABLE_SCORES`."""
    try:
        best = result.best_cell()
    except PolarsegError:
        best = None
    out: dict[str, list[Any]] = {"best": ["★" if c is best else "" for c in result.cells]}
    for name in result.axes:
        out[name] = [table_value(c.values[name]) for c in result.cells]
    for head, column in PARAM_TABLE_SCORES:
        out[head] = [table_value(getattr(c, column)) for c in result.cells]
    return out
