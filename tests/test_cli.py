"""The ``polarseg`` command line: outputs of ``segment`` and ``demo``, and bad input."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile
from skimage import io as skio
from sklearn.metrics import adjusted_rand_score

import napari_polarseg
from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.cli import demo as cli_demo
from napari_polarseg.cli.options import method_options
from napari_polarseg.engine import SegmentParams, diffuse_dop
from napari_polarseg.engine.physics.mosaic import mosaic_superpixel

ANGLES = np.arange(0.0, 180.0, 30.0)  # 6 frames
H, W = 57, 63  # not multiples of the window
# the thesis pipeline (the default preset "auto" is tested in test_auto_preset.py): the
# scene's two materials differ in how Î follows the tilt, not in ρ
#: What a run with the thesis maps (``--method thesis``, ``--thesis-maps``) adds.
THESIS_MAPS = {"reconstruction_error.tif"}
FAST = ["--preset", "thesis", "--window", "10", "--degree", "4", "--segments", "2"]
#: FAST for a run whose labels come from scribbles or a classifier, which reads no block
#: parameter (a block flag would be named in a warning) and is evaluated without blocks.
FAST_INPUTS = ["--preset", "thesis", "--segments", "2"]
#: What every result folder holds (the default method computes no thesis maps).
CONTRACT = {
    "labels.tif",
    "intensity.tif",
    "dop.tif",
    "phase.tif",
    "zenith.tif",
    "residual.tif",
    "mask.tif",
    "segments.csv",
    "params.json",
    "summary.json",
    # the polarisation views (issue 14): Stokes components and the HSV composite
    "stokes.tif",
    "aolp_dolp.png",
}
FLOAT_MAPS = [
    "intensity.tif",
    "dop.tif",
    "phase.tif",
    "zenith.tif",
    "reconstruction_error.tif",
    "residual.tif",
]


def two_material_scene(h=H, w=W, angles=ANGLES, seed=0, noise=0.5):
    """Angle stack of a field of domes, left material Lambertian-like, right one not.

    I(a) = I0 (1 + rho cos(2a - 2 phi)) with rho the diffuse Fresnel degree of
    polarisation of the zenith at n = 1.45 and phi the azimuth mod pi.
    Returns (stack float64, truth labels, (I0, rho, phi)).
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    cy, cx = (yy % 10) - 4.5, (xx % 10) - 4.5
    zenith = np.clip(np.hypot(cx, cy) / 6.0, 0, 1) * 1.3
    azimuth = np.arctan2(cy, cx)
    truth = (xx >= 30).astype(np.uint8)
    i0 = np.where(
        truth == 0,
        100 + 80 * np.cos(zenith),
        60 + 120 * np.sin(zenith) ** 2 * (1 + 0.5 * np.cos(azimuth)),
    )
    rho = diffuse_dop(zenith, 1.45)
    phi = np.mod(azimuth, np.pi)
    a = np.deg2rad(np.asarray(angles, dtype=float))[:, None, None]
    stack = i0 * (1 + rho * np.cos(2 * a - 2 * phi)) + rng.normal(0, noise, (len(a), h, w))
    return stack, truth, (i0, rho, phi)


@pytest.fixture
def scene_tif(tmp_path):
    stack, truth, maps = two_material_scene()
    path = tmp_path / "scene.tif"
    pio.write_stack_tiff(path, np.round(stack).astype(np.uint16), ANGLES)
    return path, truth, maps


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def read_tif(path):
    return tifffile.imread(path)


# -- segment ------------------------------------------------------------------------------


def test_segment_writes_the_contract_for_a_size_not_multiple_of_w(tmp_path, capsys, scene_tif):
    path, truth, (i0, rho, phi) = scene_tif
    out = tmp_path / "out"
    code, stdout, err = run(capsys, "segment", path, "--out", out, *FAST)
    assert code == 0, err
    assert err == ""
    assert set(os.listdir(out)) == CONTRACT | THESIS_MAPS
    assert str(out) in stdout and "2 segments" in stdout

    labels = read_tif(out / "labels.tif")
    assert labels.shape == (H, W)
    assert np.issubdtype(labels.dtype, np.integer)
    assert set(np.unique(labels)) == {0, 1}  # every pixel labelled, 0 = first segment
    assert adjusted_rand_score(truth.ravel(), labels.ravel()) > 0.9
    for name in FLOAT_MAPS:
        image = read_tif(out / name)
        assert image.shape == (H, W) and image.dtype == np.float32, name
    np.testing.assert_allclose(read_tif(out / "intensity.tif"), i0, rtol=0.02, atol=1.0)
    np.testing.assert_allclose(read_tif(out / "dop.tif"), rho, atol=0.03)
    phase = read_tif(out / "phase.tif")
    assert phase.min() >= 0 and phase.max() < np.pi
    zenith = read_tif(out / "zenith.tif")
    assert zenith.min() >= 0 and zenith.max() <= np.pi / 2 + 1e-6

    params = json.loads((out / "params.json").read_text())
    assert params["polarseg_version"] == napari_polarseg.__version__
    assert params["input"] == str(path.resolve())
    assert params["angles_deg"] == ANGLES.tolist()
    assert params["registration"] == {"ran": False, "reference_frame": None, "shifts_px": None}
    assert params["params"]["method_params"]["thesis"]["window"] == 10
    assert params["params"]["method_params"]["thesis"]["degree"] == 4
    assert params["params"]["n_segments"] == 2 and params["params"]["refractive_index"] == 1.45
    assert params["output_shape"] == [H, W]

    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_segments"] == 2
    assert summary["block_grid"] == [5, 6]
    assert sum(summary["segment_pixels"]) == H * W
    error = read_tif(out / "reconstruction_error.tif")
    assert summary["mean_reconstruction_error"] == pytest.approx(float(error.mean()), rel=1e-5)
    assert 0 < summary["explained_variance"] <= 1
    assert set(summary["stage_seconds"]) >= {"polarisation", "harmonics", "cut"}
    assert set(summary["io_seconds"]) == {"read", "register", "write"}


def test_segment_flags_override_params_file_and_params_json_reruns(tmp_path, capsys, scene_tif):
    path, _, _ = scene_tif
    pfile = tmp_path / "p.json"
    pfile.write_text(json.dumps({"window": 10, "degree": 6, "n_segments": 3, "variance": 0.9}))
    out = tmp_path / "a"
    code, _, err = run(capsys, "segment", path, "--out", out, "--params", pfile, "--degree", "4")
    assert code == 0, err
    params = json.loads((out / "params.json").read_text())["params"]
    thesis = params["method_params"]["thesis"]  # block fields at the top level: the thesis's
    assert (thesis["window"], thesis["degree"], params["n_segments"]) == (10, 4, 3)
    assert thesis["variance"] == 0.9 and params["method"] == "thesis"
    # a params.json written by polarseg is accepted as --params and reproduces the run
    again = tmp_path / "b"
    code, _, err = run(capsys, "segment", path, "--out", again, "--params", out / "params.json")
    assert code == 0, err
    assert json.loads((again / "params.json").read_text())["params"] == params
    np.testing.assert_array_equal(read_tif(again / "labels.tif"), read_tif(out / "labels.tif"))


def test_segment_all_parameter_flags_reach_params_json(tmp_path, capsys, scene_tif):
    path, _, _ = scene_tif
    out = tmp_path / "out"
    flags = [
        *("--window", "9", "--degree", "5", "--refractive-index", "1.6", "--segments", "3"),
        *("--model", "specular", "--specular-branch", "above-brewster"),
        *("--coefficients", "ridge", "--ridge", "0.01", "--variance", "0.9", "--scale", "2"),
        *("--features", "zonal"),
        *("--scale-mode", "median", "--spatial-radius", "1.5", "--spatial-sigma", "3"),
        *("--ncut-threshold", "0.8", "--min-segment-blocks", "2", "--fit", "robust"),
        *("--affinity-graph", "sparse", "--clustering", "kway", "--method", "thesis"),
        *("--object-size", "30"),
    ]
    code, _, err = run(capsys, "segment", path, "--out", out, *flags)
    assert code == 0, err
    assert json.loads((out / "params.json").read_text())["params"] == {
        "method": "thesis",
        "refractive_index": 1.6,
        "model": "specular",
        "specular_branch": "above-brewster",
        "n_segments": 3,
        "object_size": 30.0,
        "fit": "robust",
        "method_params": {
            "thesis": {
                "window": 9,
                "degree": 5,
                "coefficients": "ridge",
                "ridge": 0.01,
                "features": "zonal",
                "variance": 0.9,
                "scale": 2.0,
                "scale_mode": "median",
                "spatial_radius": 1.5,
                "spatial_sigma": 3.0,
                "ncut_threshold": 0.8,
                "min_segment_blocks": 2,
                "clustering": "kway",
                "affinity_graph": "sparse",
            }
        },
    }


def test_every_segment_parameter_has_a_named_option():
    names = {f.name for f in dataclasses.fields(SegmentParams)} - {"method_params"}
    assert set(cli.param_options()) == names
    thesis = {f.name for f in dataclasses.fields(SegmentParams(method="thesis").params_of())}
    assert set(method_options()["thesis"]) == thesis
    flags = [flag for flag, _ in cli.param_options().values()]
    flags += [flag for flag, _ in method_options()["thesis"].values()]
    help_text = cli.build_parser()._subparsers._group_actions[0].choices["segment"].format_help()
    assert all(flag in help_text for flag in flags)


def test_segment_folder_with_registration(tmp_path, capsys):
    stack, truth, _ = two_material_scene()
    frames = tmp_path / "frames"
    frames.mkdir()
    for k, angle in enumerate(ANGLES):
        frame = np.round(stack[k]).astype(np.uint16)  # values ~60..200 of 65535, as a camera's
        skio.imsave(frames / f"nir_{int(angle)}_aligned.png", frame, check_contrast=False)
    out = tmp_path / "out"
    code, _, err = run(capsys, "segment", frames, "--out", out, "--register", *FAST)
    assert code == 0, err
    params = json.loads((out / "params.json").read_text())
    assert params["angles_deg"] == ANGLES.tolist() and params["angles_from"] == "folder"
    assert params["registration"]["ran"] is True
    shifts = np.array(params["registration"]["shifts_px"])
    assert shifts.shape == (6, 2) and np.abs(shifts).max() < 0.2  # frames were aligned
    assert read_tif(out / "labels.tif").shape == (H, W)


def test_segment_mosaic_outputs_are_half_size(tmp_path, capsys):
    layout = (90, 45, 135, 0)
    stack, truth, _ = two_material_scene(h=29, w=32, angles=sorted(layout))
    raw = mosaic_superpixel(np.round(stack).astype(np.uint16), layout)
    path = tmp_path / "raw.tif"
    tifffile.imwrite(path, raw, photometric="minisblack")
    out = tmp_path / "out"
    code, _, err = run(capsys, "segment", path, "--out", out, "--mosaic", "90,45,135,0", *FAST)
    assert code == 0, err
    assert read_tif(out / "labels.tif").shape == (29, 32)
    assert read_tif(out / "dop.tif").shape == (29, 32)
    params = json.loads((out / "params.json").read_text())
    assert params["mosaic_layout_deg"] == [90.0, 45.0, 135.0, 0.0]
    assert params["raw_shape"] == [58, 64] and params["angles_deg"] == [0.0, 45.0, 90.0, 135.0]


def test_segment_overwrites_previous_results(tmp_path, capsys, scene_tif):
    path, _, _ = scene_tif
    out = tmp_path / "out"
    out.mkdir()
    (out / "labels.tif").write_bytes(b"old")
    code, _, err = run(capsys, "segment", path, "--out", out, *FAST, "--overview")
    assert code == 0, err
    assert read_tif(out / "labels.tif").shape == (H, W)
    assert set(os.listdir(out)) == CONTRACT | THESIS_MAPS | {"overview.png"}


def test_a_rerun_removes_the_earlier_runs_files_and_no_other(tmp_path, capsys, scene_tif):
    """A folder describes one run: a run with --overview and plots, then a plain run into
    the same folder, leaves no overview, plots or thesis maps of the first; a user's own
    file stays, and summary.json and a stderr line name what was removed."""
    path, _, _ = scene_tif
    out = tmp_path / "out"
    code, _, err = run(capsys, "segment", path, "--out", out, *FAST, "--overview", "--plots")
    assert code == 0, err
    first = set(os.listdir(out))
    assert {"overview.png", "plots", "reconstruction_error.tif"} <= first
    (out / "notes.txt").write_text("mine", encoding="utf-8")
    (out / "plots" / "mine.png").write_bytes(b"mine")
    code, out_text, err = run(capsys, "segment", path, "--out", out, "--preset", "auto")
    assert code == 0, err
    left = set(os.listdir(out))
    assert "overview.png" not in left and "reconstruction_error.tif" not in left
    assert "notes.txt" in left and os.listdir(out / "plots") == ["mine.png"]
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    removed = summary["removed_from_earlier_run"]
    assert "overview.png" in removed and "reconstruction_error.tif" in removed
    assert not any(name.endswith("mine.png") or name == "notes.txt" for name in removed)
    assert f"removed {len(removed)} file(s) of an earlier run" in err
    # the default computes no reconstruction error, and its first line does not say "n/a"
    assert "n/a" not in out_text.splitlines()[0]


def test_out_naming_a_file_is_bad_input(tmp_path, capsys, scene_tif):
    path, _, _ = scene_tif
    taken = tmp_path / "taken"
    taken.write_text("a file", encoding="utf-8")
    code, _, err = run(capsys, "segment", path, "--out", taken)
    assert code == 2 and "is a file, not a folder" in err
    assert taken.read_text(encoding="utf-8") == "a file"


def test_console_script_in_a_subprocess(tmp_path, scene_tif):
    path, _, _ = scene_tif
    script = Path(sys.executable).with_name("polarseg")
    assert script.exists(), "the polarseg console script is not installed in this environment"
    out = tmp_path / "out"
    # the package under test, also when the script was installed from another checkout
    package_root = str(Path(napari_polarseg.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": package_root}
    done = subprocess.run(
        [script, "segment", path, "--out", out, *FAST], capture_output=True, text=True, env=env
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    assert set(os.listdir(out)) == CONTRACT | THESIS_MAPS
    assert "2 segments" in done.stdout


def test_help_and_version(capsys):
    assert cli.main(["--version"]) == 0
    assert napari_polarseg.__version__ in capsys.readouterr().out
    assert cli.main(["segment", "--help"]) == 0
    assert "--refractive-index" in capsys.readouterr().out


# -- demo ---------------------------------------------------------------------------------


@pytest.fixture
def toy_samples(tmp_path, monkeypatch):
    stack, truth, _ = two_material_scene()
    folder = tmp_path / "samples"
    folder.mkdir()
    np.savez(
        folder / "toy.npz", stack=np.round(stack).astype(np.uint16), angles=ANGLES, labels=truth
    )
    monkeypatch.setattr(cli_demo, "SAMPLE_DIR", folder)
    return folder


def test_demo_writes_outputs_overview_and_rand_index(tmp_path, capsys, toy_samples):
    out = tmp_path / "demo"
    code, stdout, err = run(
        capsys, "demo", "--out", out, "--scene", "toy", "--preset", "thesis", "--degree", "4"
    )
    assert code == 0, err
    assert set(os.listdir(out)) == CONTRACT | THESIS_MAPS | {"overview.png"}
    assert str(out) in stdout
    assert "adjusted Rand index against the ground truth: 1.000" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_segments"] == 2  # taken from the ground truth
    assert summary["adjusted_rand_index"] == pytest.approx(1.0)
    assert summary["scene"] == "toy"
    figure = skio.imread(out / "overview.png")
    assert figure.ndim == 3 and figure.shape[2] in (3, 4)
    assert 1.0 <= figure.shape[1] / figure.shape[0] <= 2.5  # a grid of 2 x 4 panels
    assert len(np.unique(figure.reshape(-1, figure.shape[2]), axis=0)) > 100


def test_demo_with_sample_file_and_default_out(tmp_path, capsys, toy_samples, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, stdout, err = run(
        capsys,
        "demo",
        "--sample",
        toy_samples / "toy.npz",
        *("--preset", "thesis", "--degree", "4", "--segments", "3"),
    )
    assert code == 0, err
    out = tmp_path / "polarseg-demo"
    assert set(os.listdir(out)) == CONTRACT | THESIS_MAPS | {"overview.png"}
    assert json.loads((out / "summary.json").read_text())["n_segments"] == 3


def test_demo_unknown_scene_lists_the_available_ones(tmp_path, capsys, toy_samples):
    code, _, err = run(capsys, "demo", "--out", tmp_path / "d", "--scene", "nope")
    assert code == 2
    assert err.splitlines() == ["polarseg: error: no bundled sample scene 'nope' (available: toy)"]
    assert not (tmp_path / "d").exists()


@pytest.mark.skipif(
    not (cli_demo.SAMPLE_DIR / "leaves.npz").is_file(), reason="bundled sample data not installed"
)
def test_demo_on_the_bundled_leaves_scene(tmp_path, capsys):
    out = tmp_path / "demo"
    code, stdout, err = run(capsys, "demo", "--out", out, "--unsupervised")
    assert code == 0, err
    assert set(os.listdir(out)) == CONTRACT | {"overview.png"}
    assert "bundled strokes" not in stdout
    truth = np.load(cli_demo.SAMPLE_DIR / "leaves.npz")["labels"]
    labels = read_tif(out / "labels.tif")
    assert labels.shape == truth.shape
    ari = json.loads((out / "summary.json").read_text())["adjusted_rand_index"]
    assert ari == pytest.approx(adjusted_rand_score(truth.ravel(), labels.ravel()))
    assert f"adjusted Rand index against the ground truth: {ari:.3f}" in stdout
    # 0 and 180 degrees in the bundled scene: one polariser state, averaged, said once
    line = "polarseg: frames 0, 6 (0 and 180 degrees) are one polariser state: averaged"
    assert stdout.count(line) == 1 and err == ""
    params = json.loads((out / "params.json").read_text())
    assert [d["frames"] for d in params["duplicate_angles"]] == [[0, 6]]
    # `segment` on the same file says the same (issue 25)
    code, stdout, err = run(
        capsys,
        "segment",
        cli_demo.SAMPLE_DIR / "leaves.npz",
        "--out",
        tmp_path / "seg",
        "--preset",
        "recommended",
        "--segments",
        "4",
    )
    assert code == 0, err
    assert stdout.count(line) == 1


@pytest.mark.skipif(
    cli_demo.bundled_strokes("leaves") is None, reason="bundled sample data not installed"
)
@pytest.mark.parametrize("scene", ["leaves", "fruit"])
def test_demo_showcase_trains_on_the_bundled_strokes(tmp_path, capsys, scene):
    """The diffuse-regime sample scenes: the demo says scribbles do best there, trains
    the pixel classifier on the bundled strokes and beats the unsupervised default,
    whose figure it prints beside; the leaves reach ARI 0.5 and the fruit's bruise is
    found (issue 37)."""
    out = tmp_path / scene
    code, stdout, err = run(capsys, "demo", "--scene", scene, "--out", out)
    assert code == 0, err
    assert f"training the pixel classifier on the bundled strokes ({scene}_strokes.tif)" in stdout
    truth = np.load(cli_demo.SAMPLE_DIR / f"{scene}.npz")["labels"]
    labels = read_tif(out / "labels.tif")
    ari = adjusted_rand_score(truth.ravel(), labels.ravel())
    assert ari >= 0.5
    plain = float(
        re.search(r"unsupervised default \(--unsupervised\) scores (-?[\d.]+)", stdout)[1]
    )
    assert ari > plain + 0.2
    assert json.loads((out / "summary.json").read_text())["adjusted_rand_index"] == pytest.approx(
        ari
    )
    # a method chosen on the command line runs without the strokes
    code, stdout, _ = run(capsys, "demo", "--scene", scene, "--out", out, "--preset", "recommended")
    assert code == 0 and "bundled strokes" not in stdout


# -- bad input ----------------------------------------------------------------------------


def _stack_file(tmp_path, stack=None, angles=ANGLES, name="s.tif"):
    stack = two_material_scene()[0] if stack is None else stack
    path = tmp_path / name
    pio.write_stack_tiff(path, np.asarray(stack, dtype=np.float32), angles)
    return path


def _truncated(tmp_path):
    good = _stack_file(tmp_path)
    raw = good.read_bytes()
    bad = tmp_path / "cut.tif"
    bad.write_bytes(raw[: len(raw) // 2])
    return [bad]


def _different_sizes(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    for angle in (0, 60, 120):
        skio.imsave(folder / f"f_{angle}.png", np.full((20, 30), 9, np.uint8), check_contrast=False)
    skio.imsave(folder / "f_150.png", np.full((20, 31), 9, np.uint8), check_contrast=False)
    return [folder]


def _text_as_tif(tmp_path):
    path = tmp_path / "notes.tif"
    path.write_text("these are my notes, not an image\n")
    return [path]


def _odd_mosaic(tmp_path):
    path = tmp_path / "raw.png"
    skio.imsave(path, np.full((41, 64), 100, np.uint8), check_contrast=False)
    return [path, "--mosaic", "90,45,135,0"]


def _nan_only(tmp_path):
    return [_stack_file(tmp_path, np.full((6, 20, 20), np.nan))]


def _npy_without_angles(tmp_path):
    path = tmp_path / "s.npy"
    np.save(path, np.ones((4, 8, 8)))
    return [path]


def _with_params_file(text):
    def build(tmp_path):
        path = tmp_path / "p.json"
        path.write_text(text)
        return [_stack_file(tmp_path), "--params", path]

    return build


BAD_INPUTS = {
    # case: (builder of the arguments after "segment", words the error line must contain)
    "missing file": (lambda t: [t / "nowhere.tif"], "nowhere.tif: no such file"),
    "unreadable (truncated) file": (_truncated, "cut.tif: the TIFF file is truncated"),
    "non-image file": (_text_as_tif, "notes.tif: cannot read the TIFF file"),
    "unsupported file type": (
        lambda t: [Path(__file__)],
        "unsupported file type '.py'",
    ),
    "fewer than 3 distinct angles": (
        lambda t: [_stack_file(t), "--angles", "0,90,180,270,0,90"],
        "need at least 3 distinct polariser angles (modulo 180 degrees), got 2",
    ),
    "angle count differs from frame count": (
        lambda t: [_stack_file(t), "--angles", "0,45,90,135"],
        "6 frames but 4 angles",
    ),
    "frames of different sizes": (
        _different_sizes,
        "f_150.png: frame is 20 x 31 pixels but f_0.png is 20 x 30",
    ),
    "window larger than the image": (
        lambda t: [_stack_file(t), "--method", "thesis", "--window", "80"],
        "window size 80 is larger than the image (57 x 63 pixels)",
    ),
    "window leaving one block": (
        lambda t: [_stack_file(t), "--window", "40", "--method", "thesis"],
        "window size 40 leaves fewer than 2 blocks",
    ),
    "refractive index n = 1": (
        lambda t: [_stack_file(t), "--refractive-index", "1.0"],
        "refractive index must be a finite number > 1, got 1.0",
    ),
    "refractive index n < 1": (
        lambda t: [_stack_file(t), "--refractive-index", "0.8"],
        "refractive index must be a finite number > 1, got 0.8",
    ),
    "degree too high": (
        lambda t: [_stack_file(t), "--degree", "61"],
        "degree must be an integer in 0..60, got 61",
    ),
    "negative degree": (
        lambda t: [_stack_file(t), "--degree", "-1"],
        "degree must be an integer in 0..60, got -1",
    ),
    "NaN-only data": (_nan_only, "s.tif: the data has no finite values"),
    "bad --angles syntax": (
        lambda t: [_stack_file(t), "--angles", "0,30,sixty"],
        "argument --angles: expected comma-separated numbers in degrees",
    ),
    "bad --mosaic syntax": (
        lambda t: [_odd_mosaic(t)[0], "--mosaic", "90:45:135:0"],
        "argument --mosaic: expected comma-separated numbers",
    ),
    "odd-size mosaic": (
        _odd_mosaic,
        "raw.png: a 2 x 2 polarisation mosaic needs an even height and width, got 41 x 64",
    ),
    "mosaic layout of 3 angles": (
        lambda t: [_odd_mosaic(t)[0], "--mosaic", "0,45,90"],
        "needs 4 finite angles",
    ),
    "no angles anywhere": (_npy_without_angles, "s.npy: no polariser angles in the file"),
    "non-numeric parameter": (
        lambda t: [_stack_file(t), "--window", "ten"],
        "argument --window: invalid int value: 'ten'",
    ),
    "unknown model": (
        lambda t: [_stack_file(t), "--model", "glossy"],
        "argument --model: invalid choice: 'glossy'",
    ),
    "zero segments": (  # 0 = find k: only a method that can (the default, not the thesis)
        lambda t: [_stack_file(t), "--preset", "thesis", "--segments", "0"],
        "number of segments must be a positive integer, got 0",
    ),
    "params file with an unknown key": (
        _with_params_file('{"windw": 5}'),
        "p.json: unknown parameter(s): windw",
    ),
    "params file that is not JSON": (
        _with_params_file("{"),
        "p.json: parameters file is not valid JSON",
    ),
    "params file with a wrong type": (
        _with_params_file('{"variance": "most"}'),
        "p.json: variance share must be in (0, 1], got 'most'",
    ),
    "missing params file": (
        lambda t: [_stack_file(t), "--params", t / "none.json"],
        "none.json: cannot read the parameters file",
    ),
    "unknown option": (lambda t: [_stack_file(t), "--colour", "red"], "unrecognized arguments"),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_one_line_error_and_no_partial_file(tmp_path, capsys, case):
    build, words = BAD_INPUTS[case]
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    args = build(inputs)
    out = tmp_path / "out"
    out.mkdir()
    good = b"a good labels.tif from an earlier run"
    (out / "labels.tif").write_bytes(good)
    code, stdout, err = run(capsys, "segment", *args, "--out", out)
    assert code == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("polarseg: error: ")
    assert words in lines[0]
    assert "Traceback" not in err + stdout
    assert (out / "labels.tif").read_bytes() == good
    assert os.listdir(out) == ["labels.tif"]


def test_missing_out_and_missing_command(capsys):
    code, _, err = run(capsys, "segment", "x.tif")
    assert code == 2
    assert err.splitlines() == ["polarseg: error: the following arguments are required: -o/--out"]
    code, _, err = run(capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "required: COMMAND" in err


def test_unwritable_output_is_exit_code_1(tmp_path, capsys, scene_tif):
    path, _, _ = scene_tif
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    inside = blocker / "out"  # a folder that cannot be made: its parent is a file
    code, _, err = run(capsys, "segment", path, "--out", inside, *FAST)
    assert code == 1
    assert len(err.splitlines()) == 1 and err.startswith(f"polarseg: error: cannot write {inside}")
    assert blocker.read_text() == "not a folder"


# -- scribbles, ground truth and per-segment statistics ------------------------------------


def _strokes(h=H, w=W):
    """Two short horizontal strokes per material of the two-material scene (x < 30 | x >= 30)."""
    strokes = np.zeros((h, w), dtype=np.uint16)
    for row in (8, 44):
        strokes[row, 4:24] = 1
        strokes[row, 36:58] = 2
    return strokes


def test_segment_with_scribbles_and_ground_truth(tmp_path, capsys, scene_tif):
    path, truth, _ = scene_tif
    scribbles = tmp_path / "strokes.tif"
    tifffile.imwrite(scribbles, _strokes())
    gt = tmp_path / "truth.png"
    skio.imsave(gt, truth.astype(np.uint8), check_contrast=False)
    out = tmp_path / "out"
    code, stdout, err = run(
        capsys,
        "segment",
        path,
        "--out",
        out,
        *FAST_INPUTS,
        "--scribbles",
        scribbles,
        "--ground-truth",
        gt,
    )
    assert code == 0, err
    assert set(os.listdir(out)) == CONTRACT | {
        "probabilities.tif",
        "uncertainty.tif",
        "evaluation.json",
    }
    labels = read_tif(out / "labels.tif")
    # the scribble values 1 and 2, as painted (issue 23: one numbering everywhere)
    assert labels.shape == (H, W) and set(np.unique(labels)) == {1, 2}
    uncertainty = read_tif(out / "uncertainty.tif")
    assert uncertainty.shape == (H, W) and 0 <= uncertainty.min() <= uncertainty.max() <= 1
    # the walk over the superpixels (issue 23) costs a little on this scene, whose
    # material border is no edge: 0.947 (the classifier alone 0.957; test_region_walk.py)
    assert adjusted_rand_score(truth.ravel(), labels.ravel()) > 0.9
    # value 1 left of the boundary at column 30, value 2 right of it (the superpixels
    # along the boundary may go either way)
    assert np.mean(labels[:, :26] == 1) > 0.95 and np.mean(labels[:, 34:] == 2) > 0.95
    proba = read_tif(out / "probabilities.tif")
    assert proba.shape == (2, H, W) and proba.dtype == np.float32
    np.testing.assert_allclose(proba.sum(axis=0), 1.0, atol=1e-5)
    assert np.array_equal(np.argmax(proba, axis=0) + 1, labels)  # plane k: k-th value

    evaluation = json.loads((out / "evaluation.json").read_text())
    ari = adjusted_rand_score(truth.ravel(), labels.ravel())
    assert evaluation["adjusted_rand_index"] == pytest.approx(ari)
    assert set(evaluation["iou_per_segment"]) == {"0", "1"}  # the true materials
    assert 0.9 < evaluation["mean_iou"] <= 1.0
    # the classifier cuts no blocks: no block accuracy, no window
    assert evaluation["block_accuracy_worst"] is evaluation["block_accuracy_optimistic"] is None
    assert evaluation["window"] is None
    summary = json.loads((out / "summary.json").read_text())
    assert summary["labels_from"] == "scribbles" and summary["scribble_classes"] == [1, 2]
    assert summary["evaluation"]["mean_iou"] == pytest.approx(evaluation["mean_iou"])
    assert summary["adjusted_rand_index"] == pytest.approx(ari)
    assert "adjusted Rand index" in stdout and "block accuracy" not in stdout
    params = json.loads((out / "params.json").read_text())
    assert params["scribbles_file"] == str(scribbles.resolve())


def test_saved_classifier_applies_to_another_stack_without_retraining(tmp_path, capsys, scene_tif):
    """--save-classifier then --classifier on another stack: the same labels as training
    there would give from the same classifier, and a bad classifier file is one line."""
    path, truth, _ = scene_tif
    scribbles = tmp_path / "strokes.tif"
    tifffile.imwrite(scribbles, _strokes())
    clf = tmp_path / "mine.polarseg-clf"
    code, stdout, err = run(
        capsys,
        "segment",
        path,
        "--out",
        tmp_path / "a",
        *FAST_INPUTS,
        "--scribbles",
        scribbles,
        "--save-classifier",
        clf,
    )
    assert code == 0, err and clf.is_file()
    assert f"wrote the classifier to {clf}" in stdout
    # the same stack with the saved classifier: the labels of training there, but for
    # the strokes the walk started from (issue 23: a loaded classifier walks from its
    # probabilities alone), so they agree on nearly every pixel
    code, stdout, err = run(
        capsys, "segment", path, "--out", tmp_path / "b", *FAST_INPUTS, "--classifier", clf
    )
    assert code == 0, err and "not retrained" in stdout
    trained, applied = (read_tif(tmp_path / d / "labels.tif") for d in ("a", "b"))
    assert np.mean(trained == applied) > 0.95
    proba = read_tif(tmp_path / "b" / "probabilities.tif")
    np.testing.assert_allclose(proba.sum(axis=0), 1.0, atol=1e-5)
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["labels_from"] == "classifier"
    assert summary["classifier"]["seconds"]["train"] == 0
    # another stack (its frames reversed left-right): the materials swap sides
    other = tmp_path / "mirrored.tif"
    pio.write_stack_tiff(other, read_tif(path)[..., ::-1].copy(), ANGLES)
    code, _, err = run(
        capsys, "segment", other, "--out", tmp_path / "c", *FAST_INPUTS, "--classifier", clf
    )
    assert code == 0, err
    labels = read_tif(tmp_path / "c" / "labels.tif")
    assert adjusted_rand_score(truth[:, ::-1].ravel(), labels.ravel()) > 0.85
    # a tampered file: one line, exit 2, no output folder
    bad = tmp_path / "bad.polarseg-clf"
    data = bytearray(clf.read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(data))
    code, _, err = run(
        capsys, "segment", path, "--out", tmp_path / "d", *FAST_INPUTS, "--classifier", bad
    )
    assert code == 2 and len(err.strip().splitlines()) == 1 and "bad.polarseg-clf" in err
    assert not (tmp_path / "d").exists()
    code, _, err = run(
        capsys, "segment", path, "--out", tmp_path / "e", *FAST_INPUTS, "--save-classifier", clf
    )
    assert code == 2 and "--save-classifier needs --scribbles" in err


def test_segment_ground_truth_only_and_segments_csv(tmp_path, capsys, scene_tif):
    path, truth, _ = scene_tif
    gt = tmp_path / "truth.npy"
    np.save(gt, truth + 5)  # label ids do not matter
    out = tmp_path / "out"
    code, _, err = run(capsys, "segment", path, "--out", out, *FAST, "--ground-truth", gt)
    assert code == 0, err
    assert set(os.listdir(out)) == CONTRACT | THESIS_MAPS | {"evaluation.json"}
    labels = read_tif(out / "labels.tif")
    evaluation = json.loads((out / "evaluation.json").read_text())
    assert evaluation["adjusted_rand_index"] == pytest.approx(
        adjusted_rand_score(truth.ravel(), labels.ravel())
    )
    assert set(evaluation["iou_per_segment"]) == {"5", "6"}
    assert "labels_from" not in json.loads((out / "summary.json").read_text())

    lines = (out / "segments.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[:4] == ["segment", "name", "pixels", "area_fraction"]
    assert header[-3:] == ["mean_pca_1", "mean_pca_2", "mean_pca_3"]
    rows = [dict(zip(header, line.split(","), strict=True)) for line in lines[1:]]
    assert [int(r["segment"]) for r in rows] == [0, 1]
    assert sum(int(r["pixels"]) for r in rows) == H * W
    assert sum(float(r["area_fraction"]) for r in rows) == pytest.approx(1.0, abs=1e-5)
    intensity = read_tif(out / "intensity.tif")
    for r in rows:
        seg = labels == int(r["segment"])
        assert float(r["mean_intensity"]) == pytest.approx(intensity[seg].mean(), rel=1e-4)
        assert 0 <= float(r["circular_mean_phase_deg"]) < 180
        assert 0 <= float(r["mean_zenith_deg"]) <= 90
        assert float(r["mean_pca_1"]) == float(r["mean_pca_1"])  # a number, not empty


def _one_class(t):
    strokes = np.zeros((H, W), np.uint8)
    strokes[8, 4:24] = 3
    np.save(t / "one.npy", strokes)
    return t / "one.npy"


BAD_EVALUATION_INPUTS = {
    "scribbles of the wrong size": (
        lambda t: ["--scribbles", _saved(t, "s.npy", _strokes(H - 1, W))],
        f"the scribbles image is {H - 1} x {W} pixels but the outputs are {H} x {W}",
    ),
    "only one class scribbled": (
        lambda t: ["--scribbles", _one_class(t)],
        "scribbles must mark at least 2 materials (non-zero labels), found only label 3",
    ),
    "no scribble at all": (
        lambda t: ["--scribbles", _saved(t, "z.npy", np.zeros((H, W), np.uint8))],
        "the scribbles label no pixel",
    ),
    "fractional scribbles": (
        lambda t: ["--scribbles", _saved(t, "f.npy", _strokes() + 0.5)],
        "must hold integer labels",
    ),
    "missing scribbles file": (
        lambda t: ["--scribbles", t / "none.tif"],
        "none.tif: no such file",
    ),
    "ground truth of the wrong size": (
        lambda t: ["--ground-truth", _saved(t, "g.npy", np.zeros((H, W + 2), np.uint8))],
        f"the ground truth image is {H} x {W + 2} pixels but the outputs are {H} x {W}",
    ),
    "ground truth of an unknown type": (
        lambda t: ["--ground-truth", _saved(t, "g.txt", None)],
        "unsupported ground truth file type '.txt'",
    ),
}


def _saved(folder, name, array):
    path = folder / name
    if array is None:
        path.write_text("0 1")
    else:
        np.save(path, array)
    return path


@pytest.mark.parametrize("case", list(BAD_EVALUATION_INPUTS))
def test_bad_scribbles_or_ground_truth_one_line_error(tmp_path, capsys, case, scene_tif):
    path, _, _ = scene_tif
    build, words = BAD_EVALUATION_INPUTS[case]
    extra = build(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    good = b"a good labels.tif from an earlier run"
    (out / "labels.tif").write_bytes(good)
    code, stdout, err = run(capsys, "segment", path, "--out", out, *FAST_INPUTS, *extra)
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("polarseg: error: ")
    assert words in lines[0]
    assert "Traceback" not in err + stdout
    assert os.listdir(out) == ["labels.tif"] and (out / "labels.tif").read_bytes() == good


@pytest.mark.parametrize(
    "flags", [(), ("--thesis-maps",), ("--method", "thesis"), ("--preset", "recommended")]
)
def test_the_thesis_maps_are_written_when_the_method_needs_them_or_asked(
    tmp_path, capsys, scene_tif, flags
):
    path, _, _ = scene_tif
    out = tmp_path / "out"
    code, _, err = run(capsys, "segment", path, "--out", out, "--segments", "2", *flags)
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    wanted = bool(flags)
    assert set(os.listdir(out)) == (CONTRACT | THESIS_MAPS if wanted else CONTRACT)
    assert summary["thesis_maps"] is wanted and summary["reconstruction_error_map"] is wanted
    assert (summary["explained_variance"] is not None) is wanted
    rows = (out / "segments.csv").read_text().splitlines()
    assert len(rows) == 3  # the header and two segments, with or without the maps


def test_segments_auto_says_what_it_found_and_how_sure(tmp_path, capsys):
    """``--segments auto`` (preset auto): the number is found by the method, the lines say
    which k of which range and the silhouettes it was chosen on, and summary.json keeps
    them; a run with k given says nothing of the kind."""
    stack = _stack_file(tmp_path)
    code, out, _ = run(capsys, "segment", stack, "-o", tmp_path / "found", "--segments", "auto")
    assert code == 0
    record = json.loads((tmp_path / "found" / "summary.json").read_text())["superpixels"]
    assert record["k_found"] is True and record["k_tolerance"] == 0.1
    k, scores = record["k"], record["k_scores"]
    assert f"{k} segments found by itself (k in 2–6, by the silhouette" in out
    assert f"{scores[str(k)]:.2f}" in out and "(k_scores in summary.json)" in out
    code, out, _ = run(capsys, "segment", stack, "-o", tmp_path / "given", "--segments", "2")
    assert code == 0 and "found by itself" not in out
