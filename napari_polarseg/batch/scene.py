"""The task of a batch: one scene segmented into its result folder, atomically.

:func:`run_scene` runs on a Dask worker (or in this process with ``scheduler="inline"``);
Dask pickles it by reference, so it stays importable as
``napari_polarseg.batch.scene.run_scene`` (also as ``napari_polarseg.batch.run_scene``).
The helpers make the scene's table row (:func:`blank_row`, :func:`scene_stats`).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import time
import traceback
import uuid
import warnings
from pathlib import Path
from typing import Any

from .. import __version__
from .. import io as pio
from ..engine.errors import PolarsegError
from ..engine.params import SegmentParams
from ..jobs import segment_to_folder
from ..outputs import OutputError
from .plan import COLUMNS, MARKER, Scene, contract_files


def _worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _commit(tmp: Path, final: Path) -> None:
    """Move a finished temporary folder into place (replacing an incomplete old one)."""
    old = None
    if final.exists() or final.is_symlink():
        old = final.with_name(f".{final.name}.old-{uuid.uuid4().hex[:12]}")
        os.replace(final, old)
    os.replace(tmp, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def scene_stats(summary: dict[str, Any]) -> dict[str, Any]:
    """Per-scene statistics for the table, from a scene's summary.json."""
    io_s = summary.get("io_seconds") or {}
    pixels = summary.get("segment_pixels") or []
    total = sum(pixels)
    shape = summary.get("output_shape") or [None, None]
    return {
        "read_seconds": io_s.get("read"),
        "register_seconds": io_s.get("register"),
        "segment_seconds": summary.get("segment_seconds"),
        "write_seconds": io_s.get("write"),
        "height": shape[0],
        "width": shape[1],
        "n_segments": summary.get("n_segments"),
        "segment_pixels": pixels,
        "largest_segment_share": round(max(pixels) / total, 6) if total else None,
        # one segment holds (nearly) everything (SegmentationResult.degenerate)
        "degenerate": summary.get("degenerate"),
        "degenerate_reason": summary.get("degenerate_reason"),
        "n_blocks": summary.get("n_blocks"),
        "n_components": summary.get("n_components"),
        "explained_variance": summary.get("explained_variance"),
        "mean_reconstruction_error": summary.get("mean_reconstruction_error"),
        "clamped_pixels": summary.get("clamped_pixels"),
        "adjusted_rand_index": summary.get("adjusted_rand_index"),
    }


def read_scene_summary(folder: Path) -> dict[str, Any]:
    """A scene folder's ``summary.json``, or an empty dict if missing or unreadable."""
    try:
        data = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def blank_row(
    scene: Scene | dict[str, Any], status: str, error: str | None = None
) -> dict[str, Any]:
    """A scene's table row (keys :data:`~napari_polarseg.batch.plan.COLUMNS`) with only its
    name, input, output, status and error; ``scene`` is a :class:`Scene` or a job dict."""
    get = scene.get if isinstance(scene, dict) else lambda k: getattr(scene, k)
    record: dict[str, Any] = dict.fromkeys(COLUMNS)
    record.update(
        scene=get("name"),
        input=get("input"),
        output=str(get("output")),
        status=status,
        error=error,
        segment_pixels=[],
    )
    return record


def run_scene(job: dict[str, Any]) -> dict[str, Any]:
    """Segment one scene into its result folder, atomically; return its table row.

    The Dask task of a batch (also called directly by ``scheduler="inline"``). Runs the
    job of ``polarseg segment`` (:func:`napari_polarseg.jobs.segment_to_folder`) with the
    output set to a temporary folder beside the final one, then writes the completion
    marker and renames the folder into place. Bad input, unwritable output and errors of
    the engine are returned as a ``"failed"`` row with the error's message; nothing is
    left behind but the old state of the final folder.

    Parameters
    ----------
    job : dict
        ``name``, ``input``, ``output`` (the final folder), ``params`` (SegmentParams as
        a dict), ``read`` (:class:`~napari_polarseg.io.read_options.ReadOptions`, with the memory
        cap), ``outputs`` (:class:`~napari_polarseg.job_options.OutputOptions`) and
        ``segment_args`` (the same options as ``segment`` flags, for the marker).

    Returns
    -------
    dict
        The scene's row (keys :data:`COLUMNS`), plus ``log`` (the job's messages),
        ``warnings`` and, for an unexpected error, ``traceback``.
    """
    t0 = time.perf_counter()
    final = Path(job["output"])
    record = blank_row(job, "failed")
    record["worker"] = _worker_id()
    tmp = final.with_name(f".{final.name}.tmp-{uuid.uuid4().hex[:12]}")
    log: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            params = SegmentParams.from_dict(job["params"])
            done = segment_to_folder(
                str(job["input"]), tmp, params, job.get("read"), job.get("outputs")
            )
            # what segment says (e.g. its warning of a degenerate result) goes into the
            # row's log; the batch reports per scene itself
            log = [message.text for message in done.messages]
        missing = [f for f in contract_files() if not (tmp / f).is_file()]
        if missing:
            raise OutputError(f"segment did not write {', '.join(missing)}")
        files = {p.name: p.stat().st_size for p in sorted(tmp.iterdir()) if p.is_file()}
        marker = {
            "polarseg_version": __version__,
            "input": job["input"],
            "params": job["params"],
            "segment_args": list(job.get("segment_args", ())),
            "files": files,
            "worker": record["worker"],
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        pio.write_json(tmp / MARKER, marker)
        _commit(tmp, final)
        record.update(scene_stats(read_scene_summary(final)), status="done")
        record["warnings"] = list(
            dict.fromkeys((str(w.message).splitlines() or [""])[0] for w in caught)
        )
    except (PolarsegError, OutputError, OSError) as exc:
        record["error"] = " ".join(str(exc).split()) or type(exc).__name__
    except Exception as exc:  # an engine bug must not stop the batch
        record["error"] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        record["traceback"] = traceback.format_exc()
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    record["log"] = "".join(f"{line}\n" for line in log)
    record["task_seconds"] = round(time.perf_counter() - t0, 6)
    return record
