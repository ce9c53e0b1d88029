"""No silent degenerate result (issue 13): the test, summary.json, the command line."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from napari_polarseg import cli, jobs
from napari_polarseg.engine import Pipeline, SegmentParams
from napari_polarseg.engine.degenerate import DEGENERATE_SHARE, degenerate_result
from napari_polarseg.engine.params import RECOMMENDED

SAMPLES = Path(__file__).resolve().parents[1] / "napari_polarseg" / "sample_data"


def test_one_segment_with_nearly_every_pixel_is_degenerate():
    labels = np.zeros((100, 100), dtype=int)
    labels[:2, :3] = 1  # 6 pixels
    labels[50, 50] = 7  # values need not be consecutive
    check = degenerate_result(labels)
    assert check.degenerate and check.largest_share == pytest.approx(9993 / 10_000)
    assert check.reason == "one segment holds 99.93 % of the pixels"
    # at the threshold and just below it
    labels = np.repeat(np.arange(2), [95, 5])
    assert degenerate_result(labels).degenerate
    assert DEGENERATE_SHARE == 0.95
    labels = np.repeat(np.arange(2), [94, 6])
    check = degenerate_result(labels)
    assert not check.degenerate and check.reason == "" and check.largest_share == 0.94


def test_every_other_segment_below_the_minimum_size_is_degenerate():
    labels = np.repeat(np.arange(3), [800, 150, 50])  # largest 80 %
    assert not degenerate_result(labels, min_pixels=100).degenerate  # 150 >= 100
    check = degenerate_result(labels, min_pixels=200)
    assert check.degenerate and "below the minimum segment size of 200 pixels" in check.reason
    assert check.largest_share == pytest.approx(0.8)


def test_one_segment_is_degenerate_only_when_more_were_asked_for():
    labels = np.zeros((10, 10), dtype=int)
    assert degenerate_result(labels).degenerate
    assert degenerate_result(labels, requested=3).degenerate
    check = degenerate_result(labels, requested=1)
    assert not check.degenerate and check.largest_share == 1.0


def load(scene):
    with np.load(SAMPLES / f"{scene}.npz") as f:
        return f["stack"], np.deg2rad(f["angles"])


def test_summary_records_whether_the_result_is_degenerate():
    stack, angles = load("leaves")
    thesis = Pipeline(stack, angles, SegmentParams(method="thesis"))
    thesis = thesis.run(reconstruction=False).summary()
    # the thesis cut peels off a few isolated blocks (e.g. [15200, 300, 100] pixels);
    # which ones depends on rounding (BLAS threads), so the share is checked, not its digits
    assert thesis["degenerate"] is True
    share = thesis["largest_segment_share"]
    assert DEGENERATE_SHARE <= share < 1.0
    assert thesis["degenerate_reason"] == f"one segment holds {100 * share:.2f} % of the pixels"
    good = Pipeline(stack, angles, RECOMMENDED).run(reconstruction=False).summary()
    assert good["degenerate"] is False and good["degenerate_reason"] == ""
    assert good["largest_segment_share"] < DEGENERATE_SHARE
    assert set(good["cut_limits"]) == {
        "eigensolver_capped",
        "isolated_skipped",
        "products",
        "max_products",
    }


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def warnings_of(err):
    return [line for line in err.splitlines() if "degenerate result" in line]


def test_segment_warns_on_stderr_and_records_it(tmp_path, capsys):
    out = tmp_path / "thesis"
    code, stdout, err = run(
        capsys, "segment", SAMPLES / "leaves.npz", "--out", out, "--preset", "thesis"
    )
    assert code == 0
    (line,) = warnings_of(err)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["degenerate"] is True
    share = summary["largest_segment_share"]
    assert 0.95 <= share < 1.0  # a few isolated blocks peeled off (which: rounding)
    assert line == (
        f"polarseg: warning: degenerate result: one segment holds {100 * share:.2f} % of "
        "the pixels; try --preset recommended, fewer or more segments (--segments), a "
        "larger window (--window), or scribbles (--scribbles)"
    )
    assert "degenerate" not in stdout
    assert summary["cut_limits"]["eigensolver_capped"] == 0

    out = tmp_path / "recommended"
    code, _, err = run(
        capsys, "segment", SAMPLES / "leaves.npz", "--out", out, "--preset", "recommended"
    )
    assert code == 0 and warnings_of(err) == []
    summary = json.loads((out / "summary.json").read_text())
    assert summary["degenerate"] is False and summary["largest_segment_share"] < 0.95


def test_demo_warns_and_the_advice_leaves_out_the_preset_in_use(tmp_path, capsys):
    code, _, err = run(capsys, "demo", "--scene", "camouflage", "--out", tmp_path / "a")
    assert code == 0 and warnings_of(err) == []  # demo's recommended preset: fine here
    code, _, err = run(
        capsys, "demo", "--scene", "camouflage", "--out", tmp_path / "b", "--preset", "thesis"
    )
    assert code == 0
    (line,) = warnings_of(err)
    assert "one segment holds 99.36 % of the pixels; try --preset recommended" in line
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["degenerate"] is True
    # a degenerate result of the recommended preset does not suggest it again
    stack, angles = load("camouflage")
    result = Pipeline(stack, angles, RECOMMENDED).run(reconstruction=False)
    labels = np.zeros_like(result.labels)
    labels[:5, :5] = 1
    fake = SimpleNamespace(
        result=dataclasses.replace(result, labels=labels), params=RECOMMENDED, seconds={}
    )
    line = jobs.degenerate_warning(fake)
    assert line.startswith("polarseg: warning: degenerate result: one segment holds 99.84 %")
    assert "--preset recommended" not in line and "--segments" in line
    # labels from a pixel classifier: another advice
    fake.seconds["classifier"] = 0.1
    assert "strokes on every material" in jobs.degenerate_warning(fake)
    fake.result = result
    assert jobs.degenerate_warning(fake) is None


def test_batch_warns_per_scene_and_lists_the_flag(tmp_path, capsys):
    out = tmp_path / "batch"
    inputs = [SAMPLES / f"{scene}.npz" for scene in ("leaves", "fruit")]
    code, stdout, err = run(
        capsys, "batch", *inputs, "--out", out, "--scheduler", "inline", "--preset", "thesis"
    )
    assert code == 0
    (line,) = warnings_of(err)
    assert line.startswith("polarseg: warning: leaves: degenerate result: one segment holds")
    with open(out / "batch_summary.csv", newline="") as f:
        rows = {row["scene"]: row for row in csv.DictReader(f)}
    assert rows["leaves"]["degenerate"] == "True" and rows["fruit"]["degenerate"] == "False"
    scenes = json.loads((out / "batch_summary.json").read_text())["scenes"]
    assert {s["scene"]: s["degenerate"] for s in scenes} == {"leaves": True, "fruit": False}
    assert json.loads((out / "leaves" / "summary.json").read_text())["degenerate"] is True


@pytest.mark.parametrize("dtype", [np.uint8, np.int32, np.int64])
def test_used_segment_sizes_count_in_chunks_what_the_used_labels_hold(monkeypatch, dtype):
    """The used pixels' segment sizes, counted a chunk at a time, equal the sizes of the
    used labels copied out (what the check did before), and so does the verdict."""
    from napari_polarseg.engine import degenerate

    rng = np.random.default_rng(3)
    labels = rng.integers(0, 5, (120, 130)).astype(dtype)
    labels[labels == 3] = 4  # a label with no pixels
    valid = rng.random(labels.shape) > 0.3
    monkeypatch.setattr(degenerate, "COUNT_CHUNK", 1000)  # many chunks
    got = degenerate.used_segment_sizes(labels, valid)
    np.testing.assert_array_equal(got, degenerate.segment_sizes(labels[valid]))
    assert got.sum() == valid.sum() and got.size == 4
    labels[valid & (labels > 0)] = 0  # every used pixel in segment 0
    check = degenerate.degenerate_result(labels, valid=valid)
    assert check.degenerate and "every used pixel" in check.reason
