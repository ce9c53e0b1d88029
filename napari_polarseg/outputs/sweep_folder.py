"""The folder ``polarseg sweep`` writes: ``sweep.csv``, ``sweep_heatmap.png``,
``best_params.json`` and ``sweep.json`` (with ``--vary``: no heatmap)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import io as pio
from . import figures
from .contract import OutputError

if TYPE_CHECKING:
    from ..engine.analysis.param_sweep import ParamSweepResult
    from ..engine.analysis.sweep_result import SweepResult
    from ..engine.params import SegmentParams


def write_sweep_folder(
    folder: str | Path, result: SweepResult, best: SegmentParams, summary: dict[str, Any]
) -> None:
    """Write a sweep's files into ``folder`` (created if needed), each atomically.

    The heatmap is drawn before the first file is written.

    Parameters
    ----------
    folder
        The output folder.
    result
        The sweep: ``sweep.csv`` (one row per cell) and ``sweep_heatmap.png``.
    best
        The best cell's parameters: ``best_params.json`` (for ``segment --params``).
    summary
        The content of ``sweep.json``.

    Raises
    ------
    OutputError
        If a file could not be written (its name in the message).
    """
    heatmap = figures.png_bytes(figures.sweep_heatmap_figure(result))
    out = Path(folder)
    name = str(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        name = str(out / "sweep.csv")
        with pio.atomic_output(out / "sweep.csv") as tmp:
            tmp.write_text(result.to_csv(), encoding="utf-8")
        name = str(out / "sweep_heatmap.png")
        with pio.atomic_output(out / "sweep_heatmap.png") as tmp:
            tmp.write_bytes(heatmap)
        name = str(out / "best_params.json")
        with pio.atomic_output(out / "best_params.json") as tmp:
            tmp.write_text(best.to_json() + "\n", encoding="utf-8")
        name = str(out / "sweep.json")
        pio.write_json(out / "sweep.json", summary)
    except OSError as exc:
        raise OutputError(f"cannot write {name}: {exc.strerror or exc}") from exc


def write_param_sweep_folder(
    folder: str | Path, result: ParamSweepResult, best: SegmentParams, summary: dict[str, Any]
) -> None:
    """Write a sweep of a method's parameters into ``folder`` (created if needed), each
    file atomically: ``sweep.csv`` (one row per cell), ``best_params.json`` (for
    ``segment --params``) and ``sweep.json`` (``summary``); OutputError naming a file
    that could not be written."""
    out = Path(folder)
    name = str(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, text in (("sweep.csv", result.to_csv()), ("best_params.json", best.to_json())):
            with pio.atomic_output(out / name) as tmp:
                tmp.write_text(text if name.endswith(".csv") else text + "\n", encoding="utf-8")
        name = "sweep.json"
        pio.write_json(out / "sweep.json", summary)
    except OSError as exc:
        raise OutputError(f"cannot write {out / name}: {exc.strerror or exc}") from exc
