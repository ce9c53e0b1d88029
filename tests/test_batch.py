"""``polarseg batch``: many scenes on a Dask cluster, failures, resume, external scheduler."""

from __future__ import annotations

import contextlib
import csv
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
import tifffile

from napari_polarseg import batch, cli
from napari_polarseg.engine import PolarsegError
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.engine.synthetic.scenes import make_scene

# tasks defined here travel to the workers by value (the workers cannot import tests/)
cloudpickle.register_pickle_by_value(sys.modules[__name__])

SHAPE = (64, 72)
PARAMS = RECOMMENDED.replace(window=8, n_segments=2)
FLAGS = ["--preset", "recommended", "--window", "8", "--segments", "2"]
DASK = Path(sys.executable).with_name("dask")


def write_scene(path: Path, name: str = "fruit", seed: int = 0) -> Path:
    """A small synthetic scene as .npz with stack, angles (degrees) and labels."""
    scene = make_scene(name, shape=SHAPE, seed=seed)
    np.savez(path, stack=scene.stack, angles=scene.angles_deg, labels=scene.labels)
    return path


@pytest.fixture
def scenes(tmp_path: Path) -> Path:
    folder = tmp_path / "scenes"
    folder.mkdir()
    for seed, name in enumerate(("leaves", "camouflage", "fruit")):
        write_scene(folder / f"{name}.npz", name, seed)
    return folder


def check_scene_folder(folder: Path) -> None:
    """Every contract file, the marker, and labels over the input's full size."""
    names = {p.name for p in folder.iterdir()}
    assert set(batch.contract_files()) <= names and batch.MARKER in names
    assert batch.is_complete(folder)
    labels = tifffile.imread(folder / "labels.tif")
    assert labels.shape == SHAPE and labels.min() == 0
    for name in ("intensity.tif", "dop.tif", "phase.tif", "zenith.tif"):
        image = tifffile.imread(folder / name)
        assert image.shape == SHAPE and image.dtype == np.float32


def no_leftovers(out: Path) -> bool:
    return not any(p.name.startswith(".") and p.is_dir() for p in out.iterdir())


# -- planning and completeness (no cluster) -------------------------------------------------


def test_plan_names_globs_and_outputs(tmp_path: Path, scenes: Path) -> None:
    (scenes / "sub").mkdir()
    write_scene(scenes / "sub" / "fruit.npz")
    out = tmp_path / "out"
    plan = batch.plan([str(scenes / "*.npz"), scenes / "sub" / "fruit.npz", out], out)
    assert [s.name for s in plan] == ["camouflage", "fruit", "leaves", "fruit-2"]
    assert all(s.output.parent == out.resolve() for s in plan)
    assert batch.scene_name(".hidden.npz") == "_.hidden"
    assert batch.scene_name("a b/c d.tif") == "c_d"
    with pytest.raises(PolarsegError, match="no file or folder matches"):
        batch.plan([str(scenes / "*.nothing")], out)
    assert [p.name for p in batch.folder_inputs(scenes)] == [
        "camouflage.npz",
        "fruit.npz",
        "leaves.npz",
        "sub",
    ]


def test_a_folder_of_raw_camera_frames_is_a_folder_of_scenes(tmp_path: Path) -> None:
    """Raw frames named after their sensor are scenes of a folder, read as mosaics, as
    the Batch dock and ``polarseg batch DIR`` find them; another picture is not."""
    import shutil

    raw = Path(__file__).resolve().parents[1] / "napari_polarseg" / "sample_data"
    frame = raw / "fruits_IMX250MZR_crop.png"
    folder = tmp_path / "raw"
    folder.mkdir()
    for name in ("day1_IMX250MZR.png", "day2_imx250mzr.png", "holiday.png"):
        shutil.copy(frame, folder / name)
    found = [p.name for p in batch.folder_inputs(folder)]
    assert found == ["day1_IMX250MZR.png", "day2_imx250mzr.png"]
    assert [p.name for p in batch.folder_inputs(folder, mosaic=True)] == [
        "day1_IMX250MZR.png",
        "day2_imx250mzr.png",
        "holiday.png",
    ]
    out = tmp_path / "out"
    result = batch.run_batch(batch.folder_inputs(folder), out, PARAMS, scheduler="inline")
    assert result.ok and result.count("done") == 2
    labels = tifffile.imread(out / "day1_IMX250MZR" / "labels.tif")
    assert labels.shape == tuple(s // 2 for s in iio_shape(frame))  # demosaiced: half size


def iio_shape(path: Path) -> tuple[int, int]:
    """Height and width of a picture file."""
    from napari_polarseg.io import read_frame

    return read_frame(path).shape


def test_inline_batch_resume_and_parameter_change(tmp_path: Path, scenes: Path) -> None:
    out = tmp_path / "out"
    first = batch.run_batch([scenes / "fruit.npz"], out, PARAMS, scheduler="inline")
    assert first.ok and first.count("done") == 1
    folder = out / "fruit"
    check_scene_folder(folder)
    mtime = (folder / "labels.tif").stat().st_mtime_ns
    again = batch.run_batch([scenes / "fruit.npz"], out, PARAMS, scheduler="inline")
    assert again.count("skipped") == 1 and (folder / "labels.tif").stat().st_mtime_ns == mtime
    assert again.records[0]["n_segments"] == first.records[0]["n_segments"]
    # other parameters: the folder is not complete for this run and is redone in place
    changed = batch.run_batch(
        [scenes / "fruit.npz"], out, PARAMS.replace(n_segments=3), scheduler="inline"
    )
    assert changed.count("done") == 1
    assert batch.read_marker(folder)["params"]["n_segments"] == 3
    assert no_leftovers(out)
    # a file of the contract missing or cut short: not complete
    (folder / "dop.tif").write_bytes(b"")
    assert not batch.is_complete(folder)
    (folder / "dop.tif").unlink()
    assert not batch.is_complete(folder)


def test_inline_batch_cancel_records_unfinished_scenes(tmp_path: Path, scenes: Path) -> None:
    out = tmp_path / "out"
    seen: list[str] = []
    gen = batch.iter_batch(
        batch.plan([str(scenes / "*.npz")], out),
        out,
        PARAMS,
        scheduler="inline",
        cancel=lambda: len(seen) >= 1,
    )
    with pytest.raises(StopIteration) as stop:
        while True:
            seen.append(next(gen)["scene"])
    result = stop.value.value
    assert [r["status"] for r in result.records].count("cancelled") == 2
    summary = batch.read_summary(out)
    assert summary["counts"]["cancelled"] == 2 and summary["counts"]["done"] == 1


def test_batch_lock_refuses_a_second_batch(tmp_path: Path, scenes: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / batch.LOCK_FILE).write_text(json.dumps({"pid": os.getpid(), "host": os.uname()[1]}))
    with pytest.raises(PolarsegError, match="another polarseg batch"):
        batch.run_batch([scenes / "fruit.npz"], out, PARAMS, scheduler="inline")
    # a stale lock (its process is gone) is taken over
    (out / batch.LOCK_FILE).write_text(json.dumps({"pid": 2**22 + 12345, "host": os.uname()[1]}))
    assert batch.run_batch([scenes / "fruit.npz"], out, PARAMS, scheduler="inline").ok
    assert not (out / batch.LOCK_FILE).exists()


def test_cli_batch_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    code = cli.main(["batch", str(tmp_path / "*.npz"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no file or folder matches" in err[0]
    code = cli.main(["batch", str(tmp_path), "--out", str(tmp_path / "o"), "--workers", "0"])
    assert code == 2


# -- local Dask cluster ---------------------------------------------------------------------


def test_cli_batch_on_local_cluster(
    tmp_path: Path, scenes: Path, capsys: pytest.CaptureFixture
) -> None:
    """`polarseg batch` on three scenes with a local cluster of 2 worker processes."""
    out = tmp_path / "out"
    argv = ["batch", str(scenes / "*.npz"), "--out", str(out), "--workers", "2", *FLAGS]
    assert cli.main(argv) == 0
    captured = capsys.readouterr()
    assert "[3/3]" in captured.err and "local cluster (2 worker" in captured.err
    assert "3 done, 0 skipped, 0 failed" in captured.out
    # the rate says what time it is counted over (not the wall time, which has start-up)
    assert "scenes/s over the " in captured.out and "after the cluster started" in captured.out
    for name in ("leaves", "camouflage", "fruit"):
        check_scene_folder(out / name)
    # the same result as `polarseg segment` with the same parameters
    single = tmp_path / "single"
    assert cli.main(["segment", str(scenes / "fruit.npz"), "--out", str(single), *FLAGS]) == 0
    np.testing.assert_array_equal(
        tifffile.imread(single / "labels.tif"), tifffile.imread(out / "fruit" / "labels.tif")
    )
    # the summary tables
    summary = batch.read_summary(out)
    assert summary["counts"] == {"done": 3, "skipped": 0, "failed": 0, "cancelled": 0}
    assert summary["n_workers"] == 2 and summary["scenes_per_second"] > 0
    assert summary["params"] == PARAMS.to_dict()
    with open(out / batch.SUMMARY_CSV, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["scene"] for r in rows] == ["camouflage", "fruit", "leaves"]
    workers = set()
    for row, scene in zip(rows, summary["scenes"], strict=True):
        assert row["status"] == "done" and row["error"] == ""
        assert int(row["n_segments"]) == 2 and (int(row["height"]), int(row["width"])) == SHAPE
        assert sum(map(int, row["segment_pixels"].split(";"))) == SHAPE[0] * SHAPE[1]
        assert -1 <= float(row["adjusted_rand_index"]) <= 1
        assert float(row["task_seconds"]) > 0 and float(row["segment_seconds"]) > 0
        assert scene["adjusted_rand_index"] == pytest.approx(float(row["adjusted_rand_index"]))
        workers.add(row["worker"])
    assert all(":" in w for w in workers)
    assert no_leftovers(out)


@pytest.fixture(scope="module")
def cluster() -> Iterator[str]:
    """A local cluster of 2 single-threaded worker processes; a dead task is retried once."""
    import dask
    from distributed import LocalCluster

    config = {
        "distributed.scheduler.allowed-failures": 1,
    }
    with dask.config.set(config):
        local = LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            memory_limit="2GiB",
        )
    try:
        yield local.scheduler_address
    finally:
        local.close(timeout=20)


def flaky_task(job: dict) -> dict:
    """run_scene, except: scene ``raises`` raises; scene ``dies`` kills its worker process
    after writing every file into its temporary folder, just before the rename."""
    from napari_polarseg.batch import scene as worker_scene

    if job["name"] == "raises":
        raise RuntimeError("injected task failure")
    if job["name"] == "dies":

        def die(tmp: Path, final: Path) -> None:
            assert (tmp / "labels.tif").is_file() and (tmp / worker_scene.MARKER).is_file()
            os._exit(13)

        worker_scene._commit = die
    return worker_scene.run_scene(job)


def test_failed_scenes_are_recorded_and_rerun_resumes(
    tmp_path: Path, scenes: Path, cluster: str
) -> None:
    """A corrupt file, a task that raises and a worker that dies mid-write, among good
    scenes: the rest complete; a rerun skips the complete ones (same mtimes) and redoes
    the failed and the incomplete ones."""
    folder = tmp_path / "in"
    folder.mkdir()
    good = [write_scene(folder / f"good{i}.npz", "leaves", i) for i in (1, 2)]
    write_scene(folder / "raises.npz")
    write_scene(folder / "dies.npz")
    corrupt = folder / "corrupt.npz"
    corrupt.write_bytes(good[0].read_bytes()[:2000])  # cut short
    out = tmp_path / "out"

    inputs = [str(folder / "*.npz")]
    first = batch.run_batch(inputs, out, PARAMS, scheduler=cluster, task=flaky_task)
    status = {r["scene"]: r for r in first.records}
    assert {k: v["status"] for k, v in status.items()} == {
        "corrupt": "failed",
        "dies": "failed",
        "good1": "done",
        "good2": "done",
        "raises": "failed",
    }
    assert "corrupt.npz" in status["corrupt"]["error"]
    assert status["raises"]["error"] == "RuntimeError: injected task failure"
    assert status["dies"]["error"].startswith("KilledWorker")
    for name in ("corrupt", "dies", "raises"):
        assert not (out / name).exists()
    assert any(p.name.startswith(".dies.tmp-") for p in out.iterdir())  # hidden, never final
    check_scene_folder(out / "good1")
    check_scene_folder(out / "good2")
    summary = batch.read_summary(out)
    assert summary["counts"] == {"done": 2, "skipped": 0, "failed": 3, "cancelled": 0}

    # make good2 incomplete; repair the corrupt file
    mtime = (out / "good1" / "labels.tif").stat().st_mtime_ns
    (out / "good2" / "zenith.tif").unlink()
    write_scene(corrupt)
    second = batch.run_batch(inputs, out, PARAMS, scheduler=cluster)
    status = {r["scene"]: r["status"] for r in second.records}
    assert status == {
        "corrupt": "done",
        "dies": "done",
        "good1": "skipped",
        "good2": "done",
        "raises": "done",
    }
    assert (out / "good1" / "labels.tif").stat().st_mtime_ns == mtime
    for name in ("corrupt", "dies", "good1", "good2", "raises"):
        check_scene_folder(out / name)
    assert no_leftovers(out)
    rows = batch.read_summary(out)["scenes"]
    assert rows[[r["scene"] for r in rows].index("good1")]["n_segments"] == 2  # from disk


# -- an external scheduler and worker -------------------------------------------------------


@contextlib.contextmanager
def started(argv: list[str], log: Path) -> Iterator[subprocess.Popen]:
    """Start a process in its own process group; always terminate the group at the end."""
    handle = open(log, "wb")  # noqa: SIM115 - closed below
    proc = subprocess.Popen(argv, stdout=handle, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        yield proc
    finally:
        for sig, wait in ((signal.SIGTERM, 15), (signal.SIGKILL, 5)):
            if proc.poll() is not None:
                break
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, sig)
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=wait)
        handle.close()


def wait_for_file(path: Path, proc: subprocess.Popen, log: Path, timeout: float = 30) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"process ended early: {log.read_text(errors='replace')[-2000:]}")
        with contextlib.suppress(OSError, ValueError):
            data = json.loads(path.read_text())
            if data.get("address"):
                return data
        time.sleep(0.1)
    pytest.fail(f"no scheduler file after {timeout} s: {log.read_text(errors='replace')[-2000:]}")


@pytest.mark.skipif(not DASK.exists(), reason="the dask command is not installed")
def test_cli_batch_on_external_scheduler(
    tmp_path: Path, scenes: Path, capsys: pytest.CaptureFixture
) -> None:
    """`dask scheduler` and `dask worker` as separate processes on 127.0.0.1."""
    sched_file = tmp_path / "scheduler.json"
    sched_cmd = [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0"]
    sched_cmd += ["--no-dashboard", "--scheduler-file", str(sched_file), "--idle-timeout", "300"]
    with started(sched_cmd, tmp_path / "scheduler.log") as sched:
        address = wait_for_file(sched_file, sched, tmp_path / "scheduler.log")["address"]
        assert address.startswith("tcp://127.0.0.1:")
        worker_cmd = [str(DASK), "worker", address, "--host", "127.0.0.1", "--nthreads", "1"]
        worker_cmd += ["--nworkers", "1", "--memory-limit", "2GiB", "--no-dashboard"]
        worker_cmd += ["--death-timeout", "60", "--local-directory", str(tmp_path / "work")]
        with started(worker_cmd, tmp_path / "worker.log"):
            out = tmp_path / "out"
            argv = ["batch", str(scenes), str(scenes / "*.npz"), "--out", str(out)]
            code = cli.main([*argv, "--scheduler", address, *FLAGS])
            err = capsys.readouterr().err
            assert code == 3, err  # the folder itself is no angle stack
            assert f"on scheduler {address}" in err
    summary = batch.read_summary(out)
    assert summary["scheduler"] == address and summary["n_workers"] == 1
    status = {r["scene"]: r["status"] for r in summary["scenes"]}
    assert status == {"scenes": "failed", "camouflage": "done", "fruit": "done", "leaves": "done"}
    for name in ("leaves", "camouflage", "fruit"):
        check_scene_folder(out / name)
