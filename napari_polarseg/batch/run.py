"""Running a batch: :func:`iter_batch` and :func:`run_batch`, the summary tables.

A run takes the output folder's lock (:data:`~napari_polarseg.batch.plan.LOCK_FILE`),
removes what an interrupted run left, skips the scenes already complete, runs the others
(:mod:`napari_polarseg.batch.runners`, each scene :func:`~napari_polarseg.batch.scene.run_scene`)
and writes ``batch_summary.csv`` and ``batch_summary.json`` (:func:`write_summary`) at the
end, also when it is cancelled or interrupted.
"""

from __future__ import annotations

import contextlib
import csv
import io as _io
import json
import os
import re
import shutil
import socket
import time
from collections.abc import Callable, Generator, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import __version__
from .. import io as pio
from ..engine.errors import Cancelled, PolarsegError
from ..engine.params import SegmentParams
from ..io.read_options import ReadOptions
from ..job_options import OutputOptions, segment_args
from .cluster import parse_scheduler
from .plan import (
    COLUMNS,
    LOCK_FILE,
    PARAMS_FILE,
    STATUSES,
    SUMMARY_CSV,
    SUMMARY_JSON,
    Scene,
    is_complete,
    marker_expect,
    plan,
    plan_total,
    read_marker,
)
from .runners import DaskRunner, InlineRunner, error_text, memory_capped
from .scene import blank_row, read_scene_summary, run_scene, scene_stats

#: Temporary and replaced scene folders (``.<scene>.tmp-<id>``, ``.<scene>.old-<id>``).
_TMP_RE = re.compile(r"^\..+\.(tmp|old)-[0-9a-f]{12}$")


@dataclass
class BatchResult:
    """What a batch did: one row per scene, and how it ran."""

    out: Path
    records: list[dict[str, Any]]
    scheduler: str
    n_workers: int
    wall_seconds: float
    run_seconds: float
    params: dict[str, Any] = field(default_factory=dict)
    segment_args: list[str] = field(default_factory=list)

    def count(self, status: str) -> int:
        """Number of scenes with ``status`` (one of :data:`STATUSES`)."""
        return sum(r["status"] == status for r in self.records)

    @property
    def ok(self) -> bool:
        """True if every scene is complete (done now or skipped as done before)."""
        return all(r["status"] in ("done", "skipped") for r in self.records)

    @property
    def scenes_per_second(self) -> float | None:
        """Scenes segmented per second of the run (cluster start-up excluded)."""
        done = self.count("done")
        return round(done / self.run_seconds, 6) if done and self.run_seconds > 0 else None

    def rate_text(self) -> str:
        """``", 6.14 scenes/s over the 1.3 s after the cluster started"``: the rate and
        the time it is counted over (the wall time also counts the cluster's start-up);
        ``""`` when no scene was segmented."""
        rate = self.scenes_per_second
        if rate is None:
            return ""
        return f", {rate:.3g} scenes/s over the {self.run_seconds:.1f} s after the cluster started"

    def to_dict(self) -> dict[str, Any]:
        """The JSON summary."""
        return {
            "polarseg_version": __version__,
            "command": "batch",
            "out": str(self.out),
            "params": self.params,
            "segment_args": self.segment_args,
            "scheduler": self.scheduler,
            "n_workers": self.n_workers,
            "wall_seconds": round(self.wall_seconds, 6),
            "run_seconds": round(self.run_seconds, 6),
            "scenes_per_second": self.scenes_per_second,
            "counts": {s: self.count(s) for s in STATUSES},
            "scenes": [
                {k: r.get(k) for k in (*COLUMNS, "warnings", "traceback")} for r in self.records
            ],
        }


def write_summary(result: BatchResult) -> tuple[Path, Path]:
    """Write ``batch_summary.json`` and ``batch_summary.csv`` (atomically) into the output."""
    json_path = result.out / SUMMARY_JSON
    csv_path = result.out / SUMMARY_CSV
    pio.write_json(json_path, result.to_dict())
    buffer = _io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    for r in result.records:
        row = []
        for key in COLUMNS:
            value = r.get(key)
            if isinstance(value, (list, tuple)):
                value = ";".join(str(v) for v in value)
            row.append("" if value is None else value)
        writer.writerow(row)
    with pio.atomic_output(csv_path) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    return csv_path, json_path


def read_summary(out: str | os.PathLike[str]) -> dict[str, Any]:
    """The JSON summary of a batch output folder (raises PolarsegError if missing)."""
    path = Path(out) / SUMMARY_JSON
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise PolarsegError(f"{path}: cannot read the batch summary ({exc})") from None


@contextlib.contextmanager
def _lock(out: Path) -> Generator[None, None, None]:
    path = out / LOCK_FILE
    me = {"pid": os.getpid(), "host": socket.gethostname()}
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                other = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                other = {}
            if other.get("host") == me["host"] and _alive(other.get("pid")):
                raise PolarsegError(
                    f"{out}: another polarseg batch (process {other.get('pid')}) is writing "
                    "into this folder"
                ) from None
            with contextlib.suppress(OSError):
                path.unlink()  # stale: its process is gone
            continue
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            json.dump(me, handle)
        break
    else:  # pragma: no cover - lost a race twice
        raise PolarsegError(f"{out}: cannot take the batch lock {path}")
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            path.unlink()


def _alive(pid: Any) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _clean_leftovers(out: Path) -> None:
    """Remove temporary and replaced folders that an interrupted run left behind."""
    for entry in out.iterdir():
        if entry.is_dir() and _TMP_RE.match(entry.name):
            shutil.rmtree(entry, ignore_errors=True)


def _checked_scenes(
    inputs: Iterable[str | os.PathLike[str]] | Sequence[Scene],
    out: str | os.PathLike[str],
    params: SegmentParams,
    n_workers: int | None,
) -> tuple[list[Scene], Path]:
    """The scenes of a batch and its output folder (created), after checking the
    arguments; raises :class:`PolarsegError`."""
    if not isinstance(params, SegmentParams):
        raise PolarsegError("params must be a SegmentParams")
    if n_workers is not None and n_workers < 1:
        raise PolarsegError(f"the number of workers must be at least 1, got {n_workers}")
    out_dir = Path(out).resolve()
    items = list(inputs)
    scenes = items if items and all(isinstance(s, Scene) for s in items) else plan(items, out_dir)
    if not scenes:
        raise PolarsegError("no input scenes given")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise PolarsegError(f"{out_dir}: cannot create the output folder ({reason})") from None
    return scenes, out_dir


class _Run:
    """One run of :func:`iter_batch`: its scenes, rows, runner and timings."""

    def __init__(
        self,
        scenes: list[Scene],
        out_dir: Path,
        params: SegmentParams,
        read: ReadOptions,
        outputs: OutputOptions,
        scheduler: str | None,
    ) -> None:
        self.scenes = scenes
        self.params = params.to_dict()
        self.read = read
        self.outputs = outputs
        self.scheduler = scheduler
        self.args = segment_args(read, outputs)
        self.result = BatchResult(
            out_dir, [], scheduler or "local", 0, 0.0, 0.0, self.params, self.args
        )
        self.records: dict[str, dict[str, Any]] = {}
        self.todo: list[Scene] = []
        self.skipped: list[dict[str, Any]] = []
        self.runner: InlineRunner | DaskRunner | None = None
        self.t_run = time.perf_counter()

    def sort(self, resume: bool) -> None:
        """Scenes to run (``todo``) and rows of those complete already (``skipped``)."""
        for scene in self.scenes:
            expect = marker_expect(scene, self.params, self.args)
            if resume and is_complete(scene.output, expect):
                row = blank_row(scene, "skipped")
                row.update(scene_stats(read_scene_summary(scene.output)))
                row["worker"] = (read_marker(scene.output) or {}).get("worker")
                self.skipped.append(row)
            else:
                self.todo.append(scene)

    def start(
        self,
        task: Callable[[dict[str, Any]], dict[str, Any]],
        n_workers: int | None,
        memory_limit: str | float | int | None,
        allowed_failures: int,
        timeout: float,
    ) -> str:
        """Start the runner the scenes to run need; returns its label."""
        if not self.todo:
            label = "nothing to run"
        elif self.scheduler == "inline":
            self.runner = InlineRunner(task)
            self.result.n_workers, label = 1, "inline (this process)"
        else:
            address, count = parse_scheduler(self.scheduler or "local")
            n = count or n_workers or max(1, min(os.cpu_count() or 1, len(self.todo)))
            self.runner = DaskRunner(task, address, n, memory_limit, allowed_failures, timeout)
            self.result.n_workers, label = self.runner.n_workers, self.runner.label
            self.read = memory_capped(self.read, self.runner.memory_limits)
        self.result.scheduler = self.scheduler or ("local" if self.todo else "none")
        return label

    def job(self, scene: Scene) -> dict[str, Any]:
        """The task's argument for ``scene`` (:func:`~napari_polarseg.batch.scene.run_scene`)."""
        return {
            "name": scene.name,
            "input": scene.input,
            "output": str(scene.output),
            "params": self.params,
            "read": self.read,  # with the derived memory cap
            "outputs": self.outputs,
            "segment_args": list(self.args),  # as recorded in the marker
        }

    def rows(self, cancel: Callable[[], bool]) -> Generator[dict[str, Any], None, None]:
        """The skipped scenes' rows, then each run scene's as it completes."""
        for row in self.skipped:
            self.records[row["scene"]] = row
            yield row
        self.t_run = time.perf_counter()
        jobs = [self.job(s) for s in self.todo]
        if self.runner is None:
            return
        for job, value in self.runner.run(jobs, cancel):
            if isinstance(value, BaseException):
                status = "cancelled" if isinstance(value, Cancelled) else "failed"
                row = blank_row(job, status, error_text(value))
            else:
                row = value
            if row["status"] != "done":
                row["output"] = None  # no result folder was made
            self.records[row["scene"]] = row
            yield row

    def finish(self, t_start: float) -> None:
        """Stop the cluster, mark the scenes not run, write the summary tables."""
        self.result.run_seconds = time.perf_counter() - self.t_run
        if self.runner is not None and isinstance(self.runner, DaskRunner):
            self.runner.close()
        for scene in self.scenes:
            if scene.name not in self.records:
                row = blank_row(scene, "cancelled", "not run: the batch was stopped")
                row["output"] = None
                self.records[scene.name] = row
        self.result.records = [self.records[s.name] for s in self.scenes]
        self.result.wall_seconds = time.perf_counter() - t_start
        if self.runner is not None or not self.todo:  # not when the scheduler was never reached
            write_summary(self.result)


def iter_batch(
    inputs: Iterable[str | os.PathLike[str]] | Sequence[Scene],
    out: str | os.PathLike[str],
    params: SegmentParams,
    *,
    read: ReadOptions | None = None,
    outputs: OutputOptions | None = None,
    scheduler: str | None = None,
    n_workers: int | None = None,
    memory_limit: str | float | int | None = None,
    resume: bool = True,
    allowed_failures: int = 1,
    timeout: float = 60.0,
    cancel: Callable[[], bool] | None = None,
    task: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
    on_start: Callable[[int, int, str], None] | None = None,
) -> Generator[dict[str, Any], None, BatchResult]:
    """Run a batch, yielding each scene's row as it completes; return the :class:`BatchResult`.

    Skipped scenes are yielded first. The summary tables are written at the end, also
    when the batch is cancelled or interrupted (unfinished scenes are then
    ``"cancelled"``).

    Parameters
    ----------
    inputs : paths or glob patterns, or a list of :class:`~napari_polarseg.batch.plan.Scene`
        One scene per entry (see :func:`~napari_polarseg.batch.plan.plan`).
    out : path
        Output folder (created); one sub-folder per scene.
    params : SegmentParams
        Parameters for every scene.
    read, outputs : ReadOptions, OutputOptions, optional
        How every scene is read (angles, mosaic, channel, registration, memory limit,
        classifier, …; default: as ``polarseg segment`` without options), and the
        optional files of every scene folder (``overview.png``, …).
    scheduler : str, optional
        None or ``"local"``: a new local cluster of worker processes (``"local:N"``: of
        N); ``"inline"``: no Dask, one scene after the other here; else the address of
        a running scheduler (``tcp://host:port``; :func:`~.cluster.parse_scheduler`).
    n_workers, memory_limit, allowed_failures : optional
        Local cluster: its size (default: the number of cores, at most one per scene),
        each worker's memory limit (``"4GiB"``, bytes; default ``"auto"``: the machine's
        memory divided among the workers), how many times a scene whose worker died is
        retried elsewhere (default 1).
    resume : bool
        Skip scenes whose folder is complete for the same input and parameters.
    timeout : float
        Seconds to wait for the scheduler and a first worker.
    cancel : callable() -> bool, optional
        Polled while waiting; True stops the batch (running scenes are abandoned, their
        temporary folders removed by the next run).
    task, on_start : callable, optional
        ``task(job) -> dict`` replaces :func:`~napari_polarseg.batch.scene.run_scene`
        (tests, instrumentation; must be picklable); ``on_start(n_to_run, n_skipped,
        scheduler_label)`` is called once the scenes are planned and the scheduler is ready.

    Yields
    ------
    dict
        One row per scene (keys :data:`~napari_polarseg.batch.plan.COLUMNS`), in
        completion order. The generator returns the :class:`BatchResult`.
    """
    t_start = time.perf_counter()
    scenes, out_dir = _checked_scenes(inputs, out, params, n_workers)
    run = _Run(
        scenes, out_dir, params, read or ReadOptions(), outputs or OutputOptions(), scheduler
    )
    with _lock(out_dir):
        _clean_leftovers(out_dir)
        pio.write_json(out_dir / PARAMS_FILE, run.params)
        run.sort(resume)
        run.t_run = time.perf_counter()
        try:
            label = run.start(task or run_scene, n_workers, memory_limit, allowed_failures, timeout)
            if on_start is not None:
                on_start(len(run.todo), len(run.skipped), label)
            yield from run.rows(cancel or (lambda: False))
        finally:
            run.finish(t_start)
    return run.result


def run_batch(
    inputs: Iterable[str | os.PathLike[str]] | Sequence[Scene],
    out: str | os.PathLike[str],
    params: SegmentParams,
    *,
    progress: Callable[[int, int, dict[str, Any]], None] | None = None,
    **options: Any,
) -> BatchResult:
    """Run a batch to the end (see :func:`iter_batch` for the options).

    Parameters
    ----------
    progress : callable(index, total, row), optional
        Called after each scene (skipped ones first).

    Examples
    --------
    >>> from napari_polarseg.engine.params import RECOMMENDED
    >>> res = run_batch(["data/*.npz"], "results", RECOMMENDED)   # doctest: +SKIP
    >>> res.count("done"), res.count("failed")                      # doctest: +SKIP
    (12, 0)
    """
    scenes = plan_total(inputs, out)
    gen = iter_batch(scenes, out, params, **options)
    index = 0
    while True:
        try:
            row = next(gen)
        except StopIteration as stop:
            return stop.value
        index += 1
        if progress is not None:
            progress(index, len(scenes), row)
