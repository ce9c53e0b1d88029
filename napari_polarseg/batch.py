"""Batch runs: many scenes, the same parameters, in parallel on a Dask cluster.

Every input (a stack file, a folder of frames, a raw mosaic frame; globs are expanded) is
one *scene*, segmented exactly as ``polarseg segment`` would (the task parses a
``segment`` command line and runs it, so the result folder follows the ``segment``
contract) into ``OUT/<scene>/``. Then ``OUT/batch_summary.csv`` and
``OUT/batch_summary.json`` list per scene its status, timings, segment statistics and,
where the input carries ground truth (an ``.npz`` with ``labels``), the adjusted Rand
index.

Guarantees
----------
- **Atomic scenes**: a task writes into a hidden temporary folder beside the final one
  (``OUT/.<scene>.tmp-<id>``), adds the completion marker
  ``.polarseg-complete.json`` (input, parameters, every file and its size), and renames
  the folder into place. A result folder is *complete* when it holds every contract file
  plus the marker and the sizes match; an interrupted task leaves only a hidden
  temporary folder, removed by the next run.
- **Failures stay local**: a scene whose input is bad, whose task raises or whose worker
  dies is recorded with its error; the others go on.
- **Resume**: a rerun skips the scenes whose folder is complete *for the same input and
  parameters*, and redoes the failed, missing and incomplete ones (``resume=False``
  redoes everything).
- **Bounded memory**: the local cluster runs one single-threaded worker process per
  core (at most one per scene), each with a memory limit (default: the machine's memory
  shared out); only as many scenes are in flight as the cluster has threads, so a
  worker holds one scene at a time (and a worker that dies takes no queued scene down
  with it); every scene is refused up front (by the engine's memory estimate) if it
  would need more than 80 % of the smallest worker limit, instead of getting the worker
  killed. A scene whose worker dies anyway (killed, out of memory) is retried once on
  another worker, then recorded as failed.
- One batch at a time per output folder (a lock file ``OUT/.polarseg-batch.lock``).

With ``scheduler=ADDRESS`` the scenes run on an existing ``dask.distributed`` cluster;
its workers must see the inputs and the output folder under the same paths (a shared
file system) and have napari-polarseg installed. ``scheduler="inline"`` runs the scenes
one after the other in this process, without Dask (debugging, small jobs).

This module never imports napari or Qt.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import glob
import io as _io
import json
import logging
import os
import re
import shutil
import socket
import time
import traceback
import uuid
import warnings
from collections.abc import Callable, Generator, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import __version__
from . import io as pio
from .engine.errors import Cancelled, PolarsegError
from .engine.params import SegmentParams
from .jobs import OutputOptions, ReadOptions, segment_args, segment_to_folder
from .outputs import FLOAT_OUTPUTS, OutputError

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

_TMP_RE = re.compile(r"^\..+\.(tmp|old)-[0-9a-f]{12}$")
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
_GLOB_CHARS = re.compile(r"[*?\[]")


def contract_files() -> tuple[str, ...]:
    """Files every complete scene folder must hold (the ``segment`` contract)."""
    return ("labels.tif", *FLOAT_OUTPUTS, "params.json", "summary.json")


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
    """The scenes in a folder: stack files and sub-folders (raw frames with ``mosaic``).

    Hidden entries are left out; natural sort order.
    """
    root = Path(folder)
    if not root.is_dir():
        raise PolarsegError(f"{root}: not a folder")
    suffixes = pio.FRAME_SUFFIXES if mosaic else pio.STACK_SUFFIXES
    entries = [
        p
        for p in root.iterdir()
        if not p.name.startswith(".")
        and (p.is_dir() or (p.is_file() and p.suffix.lower() in suffixes))
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


def _marker_expect(scene: Scene, params: dict[str, Any], args: list[str]) -> dict[str, Any]:
    return {"input": scene.input, "params": params, "segment_args": args}


# -- the task (runs on a worker) ------------------------------------------------------------


def _worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _remove_tree(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)


def _commit(tmp: Path, final: Path) -> None:
    """Move a finished temporary folder into place (replacing an incomplete old one)."""
    old = None
    if final.exists() or final.is_symlink():
        old = final.with_name(f".{final.name}.old-{uuid.uuid4().hex[:12]}")
        os.replace(final, old)
    os.replace(tmp, final)
    if old is not None:
        _remove_tree(old)


def _stats(summary: dict[str, Any]) -> dict[str, Any]:
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


def _read_summary(folder: Path) -> dict[str, Any]:
    try:
        data = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _blank(scene: Scene | dict[str, Any], status: str, error: str | None = None) -> dict[str, Any]:
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
        a dict), ``read`` (:class:`~napari_polarseg.jobs.ReadOptions`, with the memory
        cap), ``outputs`` (:class:`~napari_polarseg.jobs.OutputOptions`) and
        ``segment_args`` (the same options as ``segment`` flags, for the marker).

    Returns
    -------
    dict
        The scene's row (keys :data:`COLUMNS`), plus ``log`` (the job's messages),
        ``warnings`` and, for an unexpected error, ``traceback``.
    """
    t0 = time.perf_counter()
    final = Path(job["output"])
    record = _blank(job, "failed")
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
        record.update(_stats(_read_summary(final)), status="done")
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
            _remove_tree(tmp)
    record["log"] = "".join(f"{line}\n" for line in log)
    record["task_seconds"] = round(time.perf_counter() - t0, 6)
    return record


# -- running --------------------------------------------------------------------------------


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
            _remove_tree(entry)


def _memory_capped(read: ReadOptions, worker_limits: list[float]) -> ReadOptions:
    """``read`` with the memory limit of the smallest worker (share :data:`MEMORY_SHARE`,
    GiB to 3 decimals) unless it has its own."""
    if read.max_memory_gib is not None:
        return read
    limits = [v for v in worker_limits if v and v > 0]
    if not limits:
        return read
    gib = MEMORY_SHARE * min(limits) / 2**30
    return dataclasses.replace(read, max_memory_gib=float(f"{gib:.3f}"))


class _Inline:
    """Runs tasks in this process, one after the other (``scheduler="inline"``)."""

    def __init__(self, task: Callable[[dict[str, Any]], dict[str, Any]]) -> None:
        self.task = task

    def run(
        self, jobs: list[dict[str, Any]], cancel: Callable[[], bool]
    ) -> Generator[tuple[dict[str, Any], dict[str, Any] | BaseException], None, None]:
        for job in jobs:
            if cancel():
                return
            try:
                yield job, self.task(job)
            except Exception as exc:  # a task that raises: record it, go on
                yield job, exc


class _Dask:
    """Runs tasks on a Dask cluster: a new local one, or an existing scheduler."""

    def __init__(
        self,
        task: Callable[[dict[str, Any]], dict[str, Any]],
        address: str | None,
        n_workers: int,
        memory_limit: str | float | int | None,
        allowed_failures: int,
        timeout: float,
    ) -> None:
        import dask
        from distributed import Client, LocalCluster

        self.task = task
        self.cluster = None
        if address is None:
            config = {
                "distributed.scheduler.allowed-failures": allowed_failures,
            }
            with dask.config.set(config):
                self.cluster = LocalCluster(
                    n_workers=n_workers,
                    threads_per_worker=1,
                    processes=True,
                    memory_limit="auto" if memory_limit is None else memory_limit,
                    host="127.0.0.1",
                    dashboard_address=None,
                    silence_logs=logging.ERROR,
                )
            self.client = Client(self.cluster, timeout=timeout)
            self.label = f"local cluster ({n_workers} worker process(es), 1 thread each)"
        else:
            try:
                self.client = Client(address, timeout=timeout)
            except (OSError, TimeoutError, ValueError) as exc:
                raise PolarsegError(
                    f"cannot reach the Dask scheduler at {address} within {timeout:g} s "
                    f"({type(exc).__name__}: {exc})"
                ) from None
            self.label = f"scheduler {address}"
        try:
            self.client.wait_for_workers(1, timeout=timeout)
        except Exception as exc:
            self.close()
            raise PolarsegError(
                f"no Dask worker joined {self.label} within {timeout:g} s ({exc})"
            ) from None
        with contextlib.suppress(Exception):  # imports once per worker, before the clock
            self.client.run(_warm_up)
        workers = self.client.scheduler_info(n_workers=-1)["workers"]
        self.n_workers = len(workers)
        self.memory_limits = [float(w.get("memory_limit") or 0) for w in workers.values()]

    def run(
        self, jobs: list[dict[str, Any]], cancel: Callable[[], bool]
    ) -> Generator[tuple[dict[str, Any], dict[str, Any] | BaseException], None, None]:
        from distributed import wait

        queue = list(jobs)
        futures: dict[Any, dict[str, Any]] = {}

        def refill() -> None:
            # as many scenes in flight as worker threads: each worker holds one scene at a
            # time (memory), and a worker that dies takes no queued scene down with it
            try:
                capacity = max(1, sum(self.client.nthreads().values()))
            except Exception:  # pragma: no cover - scheduler gone; wait() will tell
                capacity = 1
            while queue and len(futures) < capacity:
                job = queue.pop(0)
                key = f"polarseg-scene-{job['name']}-{uuid.uuid4().hex[:8]}"
                futures[self.client.submit(self.task, job, key=key, pure=False)] = job

        refill()
        try:
            while futures:
                if cancel():
                    return
                try:
                    done, _ = wait(list(futures), timeout=0.2, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    continue
                for fut in done:
                    job = futures.pop(fut)
                    if fut.status == "finished":
                        try:
                            value: dict[str, Any] | BaseException = fut.result()
                        except Exception as exc:  # pragma: no cover - lost result
                            value = exc
                    elif fut.status == "cancelled":
                        value = Cancelled("cancelled")
                    else:
                        value = fut.exception()
                    refill()
                    yield job, value
        finally:
            if futures:
                self.client.cancel(list(futures), force=True)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.close(timeout=10)
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close(timeout=10)


def _warm_up() -> None:
    """Import what a scene needs (about a second), on each worker before the first scene."""
    from sklearn.decomposition import PCA  # noqa: F401

    from . import jobs  # noqa: F401


def _error_text(exc: BaseException) -> str:
    name = type(exc).__name__
    text = " ".join(str(exc).split())
    if name == "KilledWorker":
        return f"KilledWorker: the worker process died while segmenting this scene ({text})"
    return f"{name}: {text}" if text else name


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
    inputs : paths or glob patterns, or a list of :class:`Scene`
        One scene per entry (see :func:`plan`).
    out : path
        Output folder (created); one sub-folder per scene.
    params : SegmentParams
        Parameters for every scene.
    read : ReadOptions, optional
        How every scene is read (angles, mosaic, channel, registration, memory limit,
        classifier, …; default: as ``polarseg segment`` without options).
    outputs : OutputOptions, optional
        The optional files of every scene folder (``overview.png``, …).
    scheduler : str, optional
        None: start a local cluster of worker processes; ``"inline"``: no Dask, one
        scene after the other here; otherwise the address of a running
        ``dask.distributed`` scheduler (``tcp://host:port``).
    n_workers : int, optional
        Local cluster size (default: the number of cores, at most one per scene).
    memory_limit : str or number, optional
        Memory limit of each local worker (``"4GiB"``, bytes; default ``"auto"``: the
        machine's memory divided among the workers).
    resume : bool
        Skip scenes whose folder is complete for the same input and parameters.
    allowed_failures : int
        Local cluster: how many times a scene whose worker died is retried elsewhere.
    timeout : float
        Seconds to wait for the scheduler and a first worker.
    cancel : callable() -> bool, optional
        Polled while waiting; True stops the batch (running scenes are abandoned, their
        temporary folders removed by the next run).
    task : callable(job) -> dict, optional
        Replaces :func:`run_scene` (tests, instrumentation); must be picklable.
    on_start : callable(n_to_run, n_skipped, scheduler_label), optional
        Called once the scenes are planned and the scheduler is ready.

    Yields
    ------
    dict
        One row per scene (keys :data:`COLUMNS`), in completion order.

    Returns
    -------
    BatchResult
    """
    t_start = time.perf_counter()
    cancel = cancel or (lambda: False)
    task = task or run_scene
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
    params_dict = params.to_dict()
    read = read or ReadOptions()
    outputs = outputs or OutputOptions()
    user_args = segment_args(read, outputs)
    records: dict[str, dict[str, Any]] = {}
    result = BatchResult(out_dir, [], scheduler or "local", 0, 0.0, 0.0, params_dict, user_args)

    with _lock(out_dir):
        _clean_leftovers(out_dir)
        pio.write_json(out_dir / PARAMS_FILE, params_dict)
        todo: list[Scene] = []
        skipped: list[dict[str, Any]] = []
        for scene in scenes:
            if resume and is_complete(scene.output, _marker_expect(scene, params_dict, user_args)):
                row = _blank(scene, "skipped")
                row.update(_stats(_read_summary(scene.output)))
                row["worker"] = (read_marker(scene.output) or {}).get("worker")
                skipped.append(row)
            else:
                todo.append(scene)
        runner: _Inline | _Dask | None = None
        t_run = time.perf_counter()
        try:
            if todo:
                if scheduler == "inline":
                    runner = _Inline(task)
                    result.n_workers, label = 1, "inline (this process)"
                else:
                    n = n_workers or max(1, min(os.cpu_count() or 1, len(todo)))
                    runner = _Dask(task, scheduler, n, memory_limit, allowed_failures, timeout)
                    result.n_workers, label = runner.n_workers, runner.label
                    read = _memory_capped(read, runner.memory_limits)
            else:
                label = "nothing to run"
            result.scheduler = scheduler or ("local" if todo else "none")
            if on_start is not None:
                on_start(len(todo), len(skipped), label)
            for row in skipped:
                records[row["scene"]] = row
                yield row
            t_run = time.perf_counter()
            jobs = [
                {
                    "name": s.name,
                    "input": s.input,
                    "output": str(s.output),
                    "params": params_dict,
                    "read": read,  # with the derived memory cap
                    "outputs": outputs,
                    "segment_args": list(user_args),  # as recorded in the marker
                }
                for s in todo
            ]
            if runner is not None:
                for job, value in runner.run(jobs, cancel):
                    if isinstance(value, BaseException):
                        status = "cancelled" if isinstance(value, Cancelled) else "failed"
                        row = _blank(job, status, _error_text(value))
                    else:
                        row = value
                    if row["status"] != "done":
                        row["output"] = None  # no result folder was made
                    records[row["scene"]] = row
                    yield row
        finally:
            result.run_seconds = time.perf_counter() - t_run
            if runner is not None and isinstance(runner, _Dask):
                runner.close()
            for scene in scenes:
                if scene.name not in records:
                    row = _blank(scene, "cancelled", "not run: the batch was stopped")
                    row["output"] = None
                    records[scene.name] = row
            result.records = [records[s.name] for s in scenes]
            result.wall_seconds = time.perf_counter() - t_start
            if runner is not None or not todo:  # not when the scheduler was never reached
                write_summary(result)
    return result


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


def plan_total(inputs: Any, out: Any) -> list[Scene]:
    """The scenes a batch would run (for progress totals)."""
    items = list(inputs)
    return items if items and all(isinstance(s, Scene) for s in items) else plan(items, out)
