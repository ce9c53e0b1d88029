"""``polarseg sweep`` and the ``--plots`` flag of ``segment`` and ``demo``."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import tifffile
from skimage import io as skio

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import SegmentParams, diffuse_dop
from napari_polarseg.outputs import FLOAT_OUTPUTS, PLOT_FILES

ANGLES_DEG = np.arange(0.0, 180.0, 30.0)
SWEEP_FILES = {"sweep.csv", "sweep.json", "sweep_heatmap.png", "best_params.json"}
GRID = ["--windows", "7,10,64", "--degrees", "2,4", "--preset", "thesis", "--segments", "2"]


def domes_stack(h=40, w=60, seed=0):
    """Left and right materials made of domes of period 10 px (w = 10 separates them)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    cy, cx = (yy % 10) - 4.5, (xx % 10) - 4.5
    zenith = np.clip(np.hypot(cx, cy) / 6.0, 0, 1) * 1.3
    azimuth = np.arctan2(cy, cx)
    truth = (xx >= w // 2).astype(np.uint8)
    i0 = np.where(
        truth == 0,
        100 + 80 * np.cos(zenith),
        60 + 120 * np.sin(zenith) ** 2 * (1 + 0.5 * np.cos(azimuth)),
    )
    rho, phi = diffuse_dop(zenith, 1.45), np.mod(azimuth, np.pi)
    a = np.deg2rad(ANGLES_DEG)[:, None, None]
    stack = i0 * (1 + rho * np.cos(2 * a - 2 * phi)) + rng.normal(0, 0.5, (len(a), h, w))
    return np.round(stack).astype(np.uint16), truth


@pytest.fixture
def scene(tmp_path):
    stack, truth = domes_stack()
    path = tmp_path / "domes.tif"
    pio.write_stack_tiff(path, stack, ANGLES_DEG)
    np.save(tmp_path / "truth.npy", truth)
    return path, tmp_path / "truth.npy", truth


def run(argv, capsys):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_usage_error(code, err, text):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("polarseg: error:"), err
    assert text in lines[0]
    assert "Traceback" not in err


def test_sweep_writes_table_json_heatmap_and_best_params(scene, tmp_path, capsys):
    path, truth_file, _ = scene
    out = tmp_path / "sweep"
    code, stdout, err = run(
        ["sweep", path, "--out", out, *GRID, "--ground-truth", truth_file], capsys
    )
    assert code == 0, err
    assert SWEEP_FILES <= {p.name for p in out.iterdir()}
    with open(out / "sweep.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6
    assert [(r["window"], r["degree"]) for r in rows] == [
        ("7", "2"),
        ("7", "4"),
        ("10", "2"),
        ("10", "4"),
        ("64", "2"),
        ("64", "4"),
    ]
    for r in rows:
        if r["window"] == "64":
            assert "larger than the image" in r["error"] and r["score"] == ""
        else:
            assert r["error"] == "" and 0 <= float(r["score"]) <= 1
        if r["window"] == "10":
            assert float(r["ari"]) == pytest.approx(1.0)
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["command"] == "sweep" and summary["n_cells"] == 6
    assert summary["n_failed"] == 2 and summary["total_seconds"] > 0
    assert summary["ground_truth"] == str(truth_file.resolve())
    assert summary["stage_calls"]["polarisation"] == 1
    assert summary["best"]["by"] == "stability"
    assert summary["best"]["cell"]["window"] == 10
    best = SegmentParams.from_json((out / "best_params.json").read_text())
    assert best.to_dict() == summary["best"]["params"]
    assert best == SegmentParams(n_segments=2, window=10, degree=best.degree)
    image = skio.imread(out / "sweep_heatmap.png")
    assert image.ndim == 3 and image.shape[0] > 200 and image[..., :3].std() > 10
    # the short table and the best cell on stdout
    assert "stability" in stdout and "error: window size 64" in stdout
    assert "best by stability: w = 10" in stdout and "--params" in stdout

    # one flag away: segment accepts best_params.json as it is
    seg = tmp_path / "seg"
    code, _, err = run(
        ["segment", path, "--params", out / "best_params.json", "--out", seg], capsys
    )
    assert code == 0, err
    params = json.loads((seg / "params.json").read_text())["params"]
    assert SegmentParams.from_dict(params) == best
    assert tifffile.imread(seg / "labels.tif").shape == (40, 60)


def test_sweep_apply_best_and_scores(scene, tmp_path, capsys):
    path, truth_file, truth = scene
    out = tmp_path / "sweep"
    code, stdout, err = run(
        [
            "sweep",
            path,
            "--out",
            out,
            *GRID,
            "--refractive-indices",
            "1.6,1.45",
            "--ground-truth",
            truth_file,
            "--score",
            "ari",
            "--apply-best",
        ],
        capsys,
    )
    assert code == 0, err
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["refractive_indices"] == [1.45, 1.6]
    assert summary["n_cells"] == 12 and summary["stage_calls"]["normals"] == 2
    assert summary["best"]["by"] == "ari" and summary["best"]["cell"]["ari"] == pytest.approx(1)
    best = SegmentParams.from_json((out / "best_params.json").read_text())
    # --apply-best: the segment contract in OUT/best/
    for name in FLOAT_OUTPUTS:
        assert (out / "best" / name).is_file()
    info = json.loads((out / "best" / "params.json").read_text())
    assert info["command"] == "segment"
    assert SegmentParams.from_dict(info["params"]) == best
    labels = tifffile.imread(out / "best" / "labels.tif")
    assert np.array_equal(labels == labels[0, 0], truth == truth[0, 0])
    evaluation = json.loads((out / "best" / "evaluation.json").read_text())
    assert evaluation["adjusted_rand_index"] == pytest.approx(1.0)


def test_sweep_without_ground_truth_has_no_ari(scene, tmp_path, capsys):
    path, _, _ = scene
    out = tmp_path / "sweep"
    code, stdout, err = run(
        [
            "sweep",
            path,
            "--out",
            out,
            "--windows",
            "10,7",
            "--degrees",
            "2",
            "--score",
            "combined",
            "--segments",
            "2",
        ],
        capsys,
    )
    assert code == 0, err
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["has_ground_truth"] is False and summary["ground_truth"] is None
    assert summary["windows"] == [7, 10]
    assert all(c["ari"] is None for c in summary["cells"])
    assert summary["best"]["by"] == "combined"
    thesis = summary["base_params"]["method_params"]["thesis"]
    assert thesis["features"] == "zonal"  # sweep starts from 'recommended'
    assert "ARI" not in stdout.splitlines()[0]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--windows", "a,b"], "argument --windows"),
        (["--windows", ""], "argument --windows"),
        (["--windows", "0,8"], "window must be a positive integer"),
        (["--degrees", "99"], "degree must be"),
        (["--refractive-indices", "0.9"], "refractive index"),
        (["--windows", "64,100"], "no cell of the sweep could run"),
        (["--score", "ari"], "--score ari needs --ground-truth"),
        (["--score", "best"], "argument --score"),
        (["--segments", "1"], "at least 2"),
        (["--plots"], "give --apply-best"),
    ],
)
def test_sweep_bad_input_exits_2_with_one_line(scene, tmp_path, capsys, extra, message):
    path, _, _ = scene
    out = tmp_path / "sweep"
    code, _, err = run(["sweep", path, "--out", out, "--degrees", "2", *extra], capsys)
    assert_usage_error(code, err, message)
    assert not out.exists()


def test_sweep_bad_ground_truth_and_input(scene, tmp_path, capsys):
    path, _, _ = scene
    small = tmp_path / "small.npy"
    np.save(small, np.zeros((5, 5), np.uint8))
    out = tmp_path / "sweep"
    code, _, err = run(["sweep", path, "--out", out, "--ground-truth", small], capsys)
    assert_usage_error(code, err, "5 x 5 pixels but the outputs are 40 x 60")
    code, _, err = run(["sweep", tmp_path / "missing.tif", "--out", out], capsys)
    assert_usage_error(code, err, "missing.tif")
    assert not out.exists()


def _check_plots(folder):
    assert {p.name for p in folder.iterdir()} == set(PLOT_FILES)
    for name in PLOT_FILES:
        assert (folder / name).stat().st_size > 5000, name
        image = skio.imread(folder / name)
        assert image.ndim == 3 and min(image.shape[:2]) > 100
        assert image[..., :3].std() > 5, name  # not a blank canvas


def test_segment_plots_flag_writes_the_pngs(scene, tmp_path, capsys):
    path, _, _ = scene
    out = tmp_path / "seg"
    code, stdout, err = run(
        [
            "segment",
            path,
            "--out",
            out,
            "--window",
            "10",
            "--degree",
            "4",
            "--segments",
            "2",
            "--plots",
        ],
        capsys,
    )
    assert code == 0, err
    _check_plots(out / "plots")
    assert "plots/ (6 PNGs)" in stdout
    assert not (out / "overview.png").exists()
    # without the flag: no plots folder
    out2 = tmp_path / "seg2"
    assert run(["segment", path, "--out", out2, "--window", "10", "--degree", "4"], capsys)[0] == 0
    assert not (out2 / "plots").exists()


def test_demo_plots_flag(tmp_path, capsys):
    out = tmp_path / "demo"
    code, _, err = run(["demo", "--out", out, "--plots", "--degree", "4"], capsys)
    assert code == 0, err
    _check_plots(out / "plots")
    assert (out / "overview.png").is_file()
