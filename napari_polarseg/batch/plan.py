"""Planning a batch: its scenes, the layout of its output folder, the completion marker.

The names of the files a batch writes (:data:`MARKER`, :data:`PARAMS_FILE`, the summary
tables, :data:`LOCK_FILE`) and the columns of its table (:data:`COLUMNS`); one
:class:`Scene` per input (:func:`plan`: globs expanded, unique folder names); and when a
scene folder counts as complete (:func:`is_complete`: the ``segment`` contract files and
the marker, sizes as recorded, same input and parameters).
"""

from __future__ import annotations

import glob
import json
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import io as pio
from ..engine.errors import PolarsegError
from ..outputs import FLOAT_OUTPUTS

#: Name of the completion marker inside a finished scene folder.
MARKER = ".polarseg-complete.json"
#: Parameters file the driver writes into the output folder and every task reads.
PARAMS_FILE = "batch_params.json"
#: Summary tables.
SUMMARY_CSV = "batch_summary.csv"
SUMMARY_JSON = "batch_summary.json"
#: Lock file: one batch at a time per output folder.
LOCK_FILE = ".polarseg-batch.lock"
#: Scene statuses.
STATUSES = ("done", "skipped", "failed", "cancelled")
#: Columns of the CSV summary, in order.
COLUMNS = (
    "scene",
    "status",
    "error",
    "input",
    "output",
    "worker",
    "task_seconds",
    "read_seconds",
    "register_seconds",
    "segment_seconds",
    "write_seconds",
    "height",
    "width",
    "n_segments",
    "segment_pixels",
    "largest_segment_share",
    "degenerate",
    "n_blocks",
    "n_components",
    "explained_variance",
    "mean_reconstruction_error",
    "clamped_pixels",
    "adjusted_rand_index",
)
#: Fraction of a worker's memory limit a scene may be estimated to need.
MEMORY_SHARE = 0.8

_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
_GLOB_CHARS = re.compile(r"[*?\[]")


def contract_files() -> tuple[str, ...]:
    """Files every complete scene folder must hold (the ``segment`` contract).

    The reconstruction-error map is written with the thesis maps only (the thesis
    method, ``--thesis-maps``): a scene of another method or of a classifier is complete
    without it."""
    always = (f for f in FLOAT_OUTPUTS if f != "reconstruction_error.tif")
    return ("labels.tif", *always, "params.json", "summary.json")


# -- planning -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scene:
    """One input of a batch and its result folder."""

    name: str
    input: str
    output: Path


def expand_inputs(inputs: Iterable[str | os.PathLike[str]]) -> list[Path]:
    """Inputs as paths: glob patterns expanded (sorted), duplicates dropped, order kept.

    Raises :class:`PolarsegError` for a pattern that matches nothing. Paths that do not
    exist are kept (their scene fails with the reader's message).
    """
    out: list[Path] = []
    seen: set[str] = set()
    for item in inputs:
        text = os.fspath(item)
        if _GLOB_CHARS.search(text) and not Path(text).exists():
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise PolarsegError(f"{text}: no file or folder matches this pattern")
        else:
            matches = [text]
        for m in matches:
            key = os.path.abspath(m)
            if key not in seen:
                seen.add(key)
                out.append(Path(m))
    return out


def folder_inputs(folder: str | os.PathLike[str], mosaic: bool = False) -> list[Path]:
    """The scenes in a folder: stack files, sub-folders and the raw frames of a
    polarisation camera named after its sensor (``…_IMX250MZR.png``: read as mosaics,
    :func:`~napari_polarseg.io.sensor_from_name`); with ``mosaic``, every image file
    (each a raw frame of the given layout).

    Hidden entries are left out; natural sort order.
    """
    root = Path(folder)
    if not root.is_dir():
        raise PolarsegError(f"{root}: not a folder")
    suffixes = pio.FRAME_SUFFIXES if mosaic else pio.STACK_SUFFIXES

    def is_scene_file(p: Path) -> bool:
        suffix = p.suffix.lower()
        raw = suffix in pio.FRAME_SUFFIXES and pio.sensor_from_name(p) is not None
        return suffix in suffixes or raw

    entries = [
        p
        for p in root.iterdir()
        if not p.name.startswith(".")
        and (p.is_dir() or (p.is_file() and is_scene_file(p)))
        and not (p.is_file() and p.name in (SUMMARY_CSV, SUMMARY_JSON, PARAMS_FILE))
    ]
    return sorted(entries, key=lambda p: pio.natural_key(p.name))


def scene_name(path: str | os.PathLike[str]) -> str:
    """Folder name of a scene: the file's stem (a folder's name), made file-system safe."""
    p = Path(path)
    base = p.name if p.is_dir() or not p.suffix else p.stem
    name = _UNSAFE.sub("_", base).strip("_") or "scene"
    return "_" + name if name.startswith(".") else name


def plan(inputs: Iterable[str | os.PathLike[str]], out: str | os.PathLike[str]) -> list[Scene]:
    """Scenes of a batch: one per input, unique folder names under ``out``.

    Inputs inside ``out`` (earlier results) are left out. A name used twice gets
    ``-2``, ``-3``, … in input order.
    """
    out_dir = Path(out).resolve()
    scenes: list[Scene] = []
    used: dict[str, int] = {}
    for path in expand_inputs(inputs):
        resolved = path.resolve()
        if resolved == out_dir or out_dir in resolved.parents:
            continue
        name = scene_name(path)
        count = used.get(name.lower(), 0) + 1
        used[name.lower()] = count
        if count > 1:
            name = f"{name}-{count}"
        scenes.append(Scene(name, str(resolved), out_dir / name))
    return scenes


# -- completeness ---------------------------------------------------------------------------


def read_marker(folder: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The completion marker of a scene folder, or None if absent or unreadable."""
    try:
        data = json.loads((Path(folder) / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def is_complete(folder: str | os.PathLike[str], expect: dict[str, Any] | None = None) -> bool:
    """True if ``folder`` holds a finished scene: marker, contract files, sizes as recorded.

    Parameters
    ----------
    folder : path
        A scene's result folder.
    expect : dict, optional
        Items the marker must have with equal values (e.g. ``input``, ``params``,
        ``segment_args``): a folder finished for other inputs or parameters is not
        complete for this run.
    """
    folder = Path(folder)
    marker = read_marker(folder)
    if marker is None or not isinstance(marker.get("files"), dict):
        return False
    files: dict[str, Any] = marker["files"]
    if not set(contract_files()) <= set(files):
        return False
    for name, size in files.items():
        try:
            if (folder / name).stat().st_size != size:
                return False
        except OSError:
            return False
    return all(marker.get(key) == value for key, value in (expect or {}).items())


def marker_expect(scene: Scene, params: dict[str, Any], args: list[str]) -> dict[str, Any]:
    """The marker items a folder complete for this run has (:func:`is_complete`'s
    ``expect``): the scene's input, the parameters and the ``segment`` options."""
    return {"input": scene.input, "params": params, "segment_args": args}


def plan_total(inputs: Any, out: Any) -> list[Scene]:
    """The scenes a batch would run (for progress totals)."""
    items = list(inputs)
    return items if items and all(isinstance(s, Scene) for s in items) else plan(items, out)
