"""The job layer: segment one input into a result folder, messages as data."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
from test_cli import CONTRACT

from napari_polarseg import batch, job_options, jobs
from napari_polarseg.engine import PolarsegError
from napari_polarseg.engine.params import RECOMMENDED, SegmentParams

SAMPLES = Path(jobs.__file__).parent / "sample_data"


def test_segment_to_folder_writes_the_contract_files(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = jobs.segment_to_folder(
        SAMPLES / "fruit.npz",
        out,
        RECOMMENDED,
        jobs.ReadOptions(),
        jobs.OutputOptions(overview=True),
    )
    names = {p.name for p in out.iterdir()}
    assert CONTRACT <= names and "overview.png" in names
    assert set(done.written) == names
    assert done.out == out and done.degenerate is None
    labels = tifffile.imread(out / "labels.tif")
    np.testing.assert_array_equal(labels, done.run.result.labels)
    assert all(isinstance(m, jobs.Message) for m in done.messages)
    assert done.messages[0].text.startswith("polarseg: 3 segments over 120 x 130 pixels")
    assert done.messages[-1].text == f"polarseg: wrote {', '.join(done.written)} to {out}"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["adjusted_rand_index"] == done.summary["adjusted_rand_index"]


def test_a_degenerate_input_returns_the_message_as_data(tmp_path: Path, capsys) -> None:
    done = jobs.segment_to_folder(
        SAMPLES / "camouflage.npz", tmp_path / "out", SegmentParams(method="thesis", n_segments=2)
    )
    assert done.degenerate is not None
    assert done.degenerate.startswith("polarseg: warning: degenerate result: one segment holds")
    assert "--preset recommended" in done.degenerate
    assert jobs.Message(done.degenerate, "stderr") in done.messages
    assert capsys.readouterr() == ("", "")  # nothing printed
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["degenerate"] is True


def test_data_to_folder_takes_read_data_and_checks_the_label_options(tmp_path: Path) -> None:
    from napari_polarseg import io as pio

    data = pio.read_stack(SAMPLES / "leaves.npz")
    read = jobs.ReadOptions(register=True)
    done = jobs.data_to_folder(data, tmp_path / "a", RECOMMENDED, read, extra={"scene": "x"})
    assert done.run.shifts is not None and done.summary["scene"] == "x"
    with pytest.raises(PolarsegError, match="--save-classifier needs --scribbles"):
        jobs.data_to_folder(
            data, tmp_path / "b", RECOMMENDED, outputs=jobs.OutputOptions(save_classifier="c")
        )
    assert not (tmp_path / "b").exists()


def test_segment_args_are_the_flags_of_the_options() -> None:
    read = jobs.ReadOptions(
        angles_deg=(0.0, 45.0, 90.0),
        demosaic="interpolated",
        channel=1,
        register=True,
        saturation=None,
        dark_level=2.5,
    )
    args = job_options.segment_args(read, jobs.OutputOptions(overview=True))
    assert args == [
        "--angles",
        "0,45,90",
        "--demosaic",
        "interpolated",
        "--channel",
        "1",
        "--saturation",
        "none",
        "--dark-level",
        "2.5",
        "--register",
        "--overview",
    ]
    assert job_options.segment_args(jobs.ReadOptions(), jobs.OutputOptions()) == []


def test_batch_imports_no_cli() -> None:
    """batch runs the job directly: no command line, argv or captured stdout."""
    for path in sorted(Path(batch.__file__).parent.glob("*.py")):  # every module of batch/
        text = path.read_text(encoding="utf-8")
        names = set()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ImportFrom):
                names.add(node.module or "")
                names.update(f"{node.module or ''}.{a.name}" for a in node.names)
            elif isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
        assert not any(n == "cli" or n.endswith(".cli") or ".cli." in n for n in names), path
        assert "contextlib.redirect_stdout" not in text, path


def test_batch_scene_log_is_the_jobs_messages(tmp_path: Path) -> None:
    result = batch.run_batch(
        [SAMPLES / "camouflage.npz"],
        tmp_path / "out",
        SegmentParams(method="thesis", n_segments=2),  # the thesis cut: degenerate here
        scheduler="inline",
    )
    (row,) = result.records
    assert row["status"] == "done" and row["degenerate"] is True
    assert "polarseg: warning: degenerate result" in row["log"]
    assert batch.read_marker(tmp_path / "out" / "camouflage")["segment_args"] == []
