"""Progress of ``segment``, ``demo`` and ``sweep`` on a terminal (napari_polarseg.status_line).

A fake terminal is made by patching ``isatty`` of the captured stdout/stderr; the stage
line must appear there, be erased before the command's own output, and never appear with
``--quiet``, with ``--verbose`` (permanent lines instead) or without a terminal. stdout is
the CLI's contract and must be the same with and without the terminal line.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
import tifffile
from test_cli_sweep import ANGLES_DEG, domes_stack

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import STAGES
from napari_polarseg.status_line import ERASE, StatusLine

# the thesis pipeline runs every stage of STAGES (preset auto skips affinity and cut);
# the scene's two materials differ in how Î follows the tilt (test_cli.two_material_scene)
FAST = ["--preset", "thesis", "--window", "10", "--degree", "4", "--segments", "2"]
GRID = ["--windows", "7,10", "--degrees", "2,4", "--segments", "2"]


@pytest.fixture
def scene(tmp_path):
    stack, truth = domes_stack()
    path = tmp_path / "domes.tif"
    pio.write_stack_tiff(path, stack, ANGLES_DEG)
    return path, truth


def run(capsys, monkeypatch, *argv, stdout_tty=False, stderr_tty=False):
    with monkeypatch.context() as patch:
        patch.setenv("COLUMNS", "400")  # wide enough for the test's long paths
        patch.setattr(sys.stdout, "isatty", lambda: stdout_tty)
        patch.setattr(sys.stderr, "isatty", lambda: stderr_tty)
        code = cli.main([str(a) for a in argv])
        out, err = capsys.readouterr()
    return code, out, err


def test_segment_on_a_terminal_shows_every_stage_then_erases_it(
    scene, tmp_path, capsys, monkeypatch
):
    path, truth = scene
    out = tmp_path / "out"
    argv = ["segment", path, "--out", out, *FAST]
    code, plain_out, plain_err = run(capsys, monkeypatch, *argv)
    assert code == 0 and plain_err == ""
    plain_labels = tifffile.imread(out / "labels.tif")

    code, tty_out, tty_err = run(capsys, monkeypatch, *argv, stdout_tty=True, stderr_tty=True)
    assert code == 0
    assert tty_out == plain_out  # stdout is the contract: untouched
    np.testing.assert_array_equal(tifffile.imread(out / "labels.tif"), plain_labels)
    lines = tty_err.split(ERASE)
    assert lines[0] == "" and lines[-1] == ""  # every update rewrites the line; erased at the end
    shown = [line for line in lines if line]
    assert shown[0].startswith(f"polarseg: reading {path.name} (")
    for k, stage in enumerate(STAGES, start=1):
        assert any(f"segmenting: [{k}/{len(STAGES)}] {stage} (" in line for line in shown), stage
    assert shown[-1].startswith(f"polarseg: writing the results to {out}")
    assert "\n" not in tty_err  # nothing is left on the screen


@pytest.mark.parametrize(
    ("flags", "stdout_tty", "stderr_tty"),
    [
        (["--quiet"], True, True),
        ([], False, True),  # stdout into a file or pipe
        ([], True, False),  # stderr into a file or pipe
        ([], False, False),
    ],
)
def test_segment_prints_no_progress_quiet_or_off_a_terminal(
    scene, tmp_path, capsys, monkeypatch, flags, stdout_tty, stderr_tty
):
    path, _ = scene
    argv = ["segment", path, "--out", tmp_path / "out", *FAST, *flags]
    code, out, err = run(capsys, monkeypatch, *argv, stdout_tty=stdout_tty, stderr_tty=stderr_tty)
    assert code == 0
    assert err == ""
    assert out.startswith("polarseg: 2 segments over 40 x 60 pixels")


def test_verbose_keeps_its_permanent_stage_lines(scene, tmp_path, capsys, monkeypatch):
    path, _ = scene
    argv = ["segment", path, "--out", tmp_path / "out", *FAST, "--verbose"]
    code, _, err = run(capsys, monkeypatch, *argv, stdout_tty=True, stderr_tty=True)
    assert code == 0
    assert ERASE not in err
    assert [line for line in err.splitlines() if "[" in line] == [
        f"polarseg: [{k}/{len(STAGES)}] {stage}" for k, stage in enumerate(STAGES, start=1)
    ]


def test_quiet_and_verbose_together_is_a_usage_error(scene, tmp_path, capsys, monkeypatch):
    path, _ = scene
    argv = ["segment", path, "--out", tmp_path / "out", "--quiet", "--verbose"]
    code, out, err = run(capsys, monkeypatch, *argv)
    assert code == 2 and out == ""
    assert err.startswith("polarseg: error:") and "--verbose" in err


def test_an_error_on_a_terminal_comes_after_the_erased_line(tmp_path, capsys, monkeypatch):
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"not a tiff at all")
    argv = ["segment", bad, "--out", tmp_path / "out"]
    code, out, err = run(capsys, monkeypatch, *argv, stdout_tty=True, stderr_tty=True)
    assert code == 2 and out == ""
    assert err.startswith(ERASE + "polarseg: reading bad.tif (")
    last = err.rsplit(ERASE, 1)[1]
    assert last.startswith(f"polarseg: error: {bad}:") and last.count("\n") == 1


def test_sweep_on_a_terminal_counts_cells(scene, tmp_path, capsys, monkeypatch):
    path, _ = scene
    out = tmp_path / "sweep"
    argv = ["sweep", path, "--out", out, *GRID]
    code, plain_out, plain_err = run(capsys, monkeypatch, *argv)
    assert code == 0 and plain_err == ""
    code, tty_out, tty_err = run(capsys, monkeypatch, *argv, stdout_tty=True, stderr_tty=True)
    assert code == 0

    def without_seconds(text):  # the seconds (last column, total line) differ between runs
        lines = [line for line in text.splitlines() if " cells (" not in line]
        return [line if line.startswith("polarseg:") else line.rsplit(None, 1)[0] for line in lines]

    assert without_seconds(tty_out) == without_seconds(plain_out)
    assert len(tty_out.splitlines()) == len(plain_out.splitlines())
    shown = [line for line in tty_err.split(ERASE) if line]
    for done in range(1, 5):
        assert any(f"sweep: {done}/4 cells done, about " in line for line in shown), done
    assert tty_err.endswith(ERASE) and "\n" not in tty_err

    code, _, quiet_err = run(
        capsys, monkeypatch, *argv, "--quiet", stdout_tty=True, stderr_tty=True
    )
    assert code == 0 and quiet_err == ""


def test_status_line_fits_a_narrow_terminal(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "30")
    line = StatusLine(True)
    line.show("segmenting: [3/7] a very long stage name indeed")
    err = capsys.readouterr().err
    assert err.startswith(ERASE)
    assert len(err[len(ERASE) :]) <= 29 and err.endswith("…")
    line.clear()
    assert capsys.readouterr().err == ERASE
    StatusLine(False).show("nothing")
    assert capsys.readouterr().err == ""
