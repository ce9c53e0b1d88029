"""The w × w blocks stay inside the methods that cut them (the thesis method).

A method declares ``block_maps`` (:class:`~napari_polarseg.engine.methods.base.Segmenter`)
instead of being recognised by its name: the summary names the block grid, the memory
estimate counts blocks, the plugin shows the maps and the time series cuts blocks only
for such a method (the time series of the others: ``tests/test_timeseries.py``). The
degenerate check and its advice, the reported number of segments, ``segments.csv`` and
the evaluation read the pixel labels of the other methods (the plugin's sweep of their
parameters: ``tests/gui/test_sweep_widget.py``).
"""

from __future__ import annotations

import ast
import csv
import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
from test_cli import ANGLES, H, W, two_material_scene
from test_method_own_params import toy_registered

import napari_polarseg
from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import PolarsegError, Scene
from napari_polarseg.engine.analysis.evaluation import adjusted_rand_index, evaluate
from napari_polarseg.engine.degenerate import degenerate_result
from napari_polarseg.engine.features.harmonics import top_left_block_labels
from napari_polarseg.engine.limits import (
    DEFAULT_MAX_BYTES,
    ENV_VAR,
)
from napari_polarseg.engine.methods import MethodOutput, register_method, unregister_method
from napari_polarseg.engine.params import AUTO, RECOMMENDED
from napari_polarseg.engine.registered import computes_block_maps
from napari_polarseg.engine.run_memory import check_pipeline_memory, estimate_pipeline_bytes
from napari_polarseg.messages import degenerate_advice
from napari_polarseg.widgets.session import wants_maps

PACKAGE = Path(napari_polarseg.__file__).parent
#: The one module that may recognise the thesis method by its name.
THESIS_MODULE = PACKAGE / "engine" / "methods" / "thesis.py"
#: A 24 MP frame of a 4-angle camera (frames, rows, columns).
BIG = (4, 4096, 6120)


def _operands(node: ast.Compare) -> list[ast.expr]:
    return [node.left, *node.comparators]


def thesis_name_comparisons(source: str) -> list[str]:
    """Every ``== "thesis"`` / ``!= "thesis"`` whose other side is a method or its name
    (``params.method``, ``method.name``, ``str(method)``, …), as source text. The
    thesis *feature kind* and *coefficient estimator* share the word and are not
    methods (``kind == "thesis"``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Compare):
            continue
        if not any(isinstance(op, (ast.Eq, ast.NotEq)) for op in node.ops):
            continue
        operands = _operands(node)
        thesis = [o for o in operands if isinstance(o, ast.Constant) and o.value == "thesis"]
        others = [ast.unparse(o) for o in operands if o not in thesis]
        if thesis and any("method" in text or text.endswith(".name") for text in others):
            found.append(ast.unparse(node))
    return found


def test_the_scan_finds_method_name_comparisons():
    source = (
        'a = params.method == "thesis"\n'
        "b = 'thesis' != result.method\n"
        'c = method.name == "thesis"\n'
        'd = str(method) == "thesis"\n'
        'e = kind == "thesis"\n'
        'f = method not in ("thesis", "ridge")\n'
    )
    assert len(thesis_name_comparisons(source)) == 4


def test_no_method_name_comparison_with_thesis_outside_its_module():
    hits = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == THESIS_MODULE:
            continue
        found = thesis_name_comparisons(path.read_text(encoding="utf-8"))
        if found:
            hits[str(path.relative_to(PACKAGE))] = found
    assert hits == {}


def test_only_the_thesis_method_declares_block_maps():
    assert computes_block_maps("thesis")
    assert not computes_block_maps(AUTO.method)
    assert not computes_block_maps("no such method")


@pytest.fixture
def scene_tif(tmp_path):
    stack, _, _ = two_material_scene()
    path = tmp_path / "scene.tif"
    pio.write_stack_tiff(path, np.round(stack).astype(np.uint16), ANGLES)
    return path


def _summary(tmp_path: Path, name: str, *argv: str) -> dict:
    out = tmp_path / name
    assert cli.main(["segment", *argv, "--out", str(out), "--segments", "2"]) == 0
    return json.loads((out / "summary.json").read_text())


def test_a_default_run_summary_has_no_block_keys(tmp_path, scene_tif):
    default = _summary(tmp_path, "default", str(scene_tif))
    assert default["method"] == AUTO.method
    assert "n_blocks" not in default and "block_grid" not in default
    assert default["n_segments"] == 2  # the rest of the summary is there
    # the thesis method and a run asked for the thesis maps name the block grid
    thesis = _summary(tmp_path, "thesis", str(scene_tif), "--preset", "recommended")
    grid = [H // RECOMMENDED.window, W // RECOMMENDED.window]
    assert thesis["block_grid"] == grid and thesis["n_blocks"] == grid[0] * grid[1]
    maps = _summary(tmp_path, "maps", str(scene_tif), "--thesis-maps")
    assert maps["method"] == AUTO.method and maps["block_grid"] == grid


def test_the_default_on_a_24_mp_stack_is_not_refused_by_the_thesis_estimate(monkeypatch):
    monkeypatch.setenv(ENV_VAR, "8G")  # the thesis estimate of 24 MP is above it
    needed = check_pipeline_memory(BIG, AUTO)  # the default: no block estimate
    assert needed == estimate_pipeline_bytes(BIG, AUTO) < 8 * 2**30 <= DEFAULT_MAX_BYTES
    # the thesis method with the same window and degree is refused by its blocks
    with pytest.raises(PolarsegError, match=r"window 12 \(173910 blocks\) and degree 8"):
        check_pipeline_memory(BIG, RECOMMENDED)
    # and so is the default when the thesis maps are asked for
    with pytest.raises(PolarsegError, match="173910 blocks"):
        check_pipeline_memory(BIG, AUTO, blocks=True)
    assert estimate_pipeline_bytes(BIG, AUTO) < estimate_pipeline_bytes(BIG, AUTO, blocks=True)


class Quarters:
    """A toy method registered from outside: four quadrants; ``block_maps`` on demand."""

    name = "quarters"
    title = "four quadrants"
    reads: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()

    def stages(self, params):
        return ("quartering",)

    def segment(self, scene, params, inputs, run):
        run.begin("quartering")
        h, w = scene.shape
        rows, cols = np.mgrid[0:h, 0:w]
        return MethodOutput(((rows >= h // 2) * 2 + (cols >= w // 2)).astype(np.int32))


@pytest.mark.parametrize("declared", [None, True])
def test_a_method_from_outside_declares_its_block_maps_or_has_none(declared):
    method = Quarters()
    if declared is not None:
        method.block_maps = declared
    register_method(method)
    try:
        blocks = bool(declared)
        assert computes_block_maps("quarters") is blocks
        params = AUTO.replace(method="quarters")
        stack, _, _ = two_material_scene()
        result = Scene(stack, np.deg2rad(ANGLES)).segment(params)
        assert (result.features is not None) is blocks  # the maps come with block_maps
        assert ("block_grid" in result.summary()) is blocks
        assert wants_maps(params) is blocks  # the plugin shows the maps of such a method
        estimate = estimate_pipeline_bytes(BIG, params)
        assert (estimate == estimate_pipeline_bytes(BIG, params, blocks=True)) is blocks
    finally:
        unregister_method("quarters")
    assert not computes_block_maps("quarters")


# -- the degenerate check, the reported k, segments.csv and evaluation read the pixel
# -- labels of a method without blocks -------------------------------------------------

#: The polariser angles of the 4-angle stacks below (degrees).
FOUR = np.array([0.0, 45.0, 90.0, 135.0])


def patch_tif(tmp_path: Path, rows: slice, size: int = 64) -> Path:
    """A 4-angle TIFF of one material (ρ 0.1, φ 0.3) with a patch of another (ρ 0.4,
    φ 1.2) at ``rows`` × ``rows``, no noise."""
    rho, phi = np.full((size, size), 0.1), np.full((size, size), 0.3)
    rho[rows, rows], phi[rows, rows] = 0.4, 1.2
    stack = np.stack([1000 * (1 + rho * np.cos(2 * a - 2 * phi)) for a in np.deg2rad(FOUR)])
    path = tmp_path / f"patch_{rows.start}_{rows.stop}.tif"
    pio.write_stack_tiff(path, np.round(stack).astype(np.uint16), FOUR)
    return path


def _segment(capsys, out: Path, *argv: object) -> tuple[str, str, dict, np.ndarray]:
    """``polarseg segment ARGV --out OUT``: stdout, stderr, summary.json, labels.tif."""
    assert cli.main(["segment", *map(str, argv), "--out", str(out)]) == 0
    stdout, err = capsys.readouterr()
    summary = json.loads((out / "summary.json").read_text())
    return stdout, err, summary, tifffile.imread(out / "labels.tif")


def _csv_rows(out: Path) -> list[dict[str, str]]:
    with open(out / "segments.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_a_degenerate_default_run_is_told_from_its_pixel_labels_without_a_window(tmp_path, capsys):
    # 16 pixels of 4096 differ: the default's two segments are that patch and the rest
    path = patch_tif(tmp_path, slice(0, 4))
    _, err, summary, labels = _segment(capsys, tmp_path / "out", path, "--segments", 2)
    share = np.bincount(labels.ravel()).max() / labels.size
    assert share >= 0.95 and summary["degenerate"] is True
    reason = f"one segment holds {100 * share:.4g} % of the pixels"
    assert summary["degenerate_reason"] == reason
    lines = [line for line in err.splitlines() if "degenerate result" in line]
    # the flags the default reads, no block parameter and no thesis preset
    assert lines == [
        f"polarseg: warning: degenerate result: {reason}; try fewer or more segments "
        "(--segments), another object size (--object-size), or scribbles (--scribbles)"
    ]
    # batch says the same
    out = tmp_path / "batch"
    argv = ["batch", str(path), "--out", str(out), "--scheduler", "inline", "--segments", "2"]
    assert cli.main(argv) == 0
    err = capsys.readouterr().err
    (line,) = [line for line in err.splitlines() if "degenerate result" in line]
    assert line.endswith(
        "try fewer or more segments (--segments), another object size "
        "(--object-size), or scribbles (--scribbles)"
    )
    assert "window" not in line and "--preset recommended" not in line
    # the thesis method keeps its block advice
    _, err, summary, _ = _segment(capsys, tmp_path / "thesis", path, "--preset", "thesis")
    assert summary["degenerate"] is True and "a larger window (--window)" in err


def test_a_non_degenerate_default_run_is_not_flagged_by_the_block_minimum(tmp_path, capsys):
    rng = np.random.default_rng(0)
    noise = tmp_path / "noise.tif"
    pio.write_stack_tiff(noise, rng.uniform(1000, 2000, (4, 32, 40)).astype(np.uint16), FOUR)
    _, err, summary, labels = _segment(capsys, tmp_path / "out", noise)
    # the thesis's minimum segment size (min_segment_blocks · w² = 576 pixels of 1280)
    # would call it degenerate: no segment but the largest reaches it
    minimum = RECOMMENDED.min_segment_blocks * AUTO.window**2
    assert degenerate_result(labels, minimum).degenerate
    assert summary["degenerate"] is False and summary["degenerate_reason"] == ""
    assert "degenerate" not in err
    assert summary["largest_segment_share"] == pytest.approx(
        np.bincount(labels.ravel()).max() / labels.size, abs=1e-6
    )


def test_segments_csv_and_the_reported_k_read_the_pixel_labels(tmp_path, capsys):
    # a 6 x 6 patch off the block grid's sampled pixels (every 12th row and column)
    path = patch_tif(tmp_path, slice(3, 9))
    out = tmp_path / "out"
    # at the frame-share scales: the 9 px superpixels of the patch's estimated size give
    # the frame's corner a third cluster, which the merge puts with the patch
    argv = (path, "--segments", 2, "--object-size", 64)
    stdout, _, summary, labels = _segment(capsys, out, *argv)
    counts = np.bincount(labels.ravel())
    assert counts.size == 2 and counts.min() > 0
    assert np.unique(top_left_block_labels(labels, AUTO.window)).size == 1  # blocks see one
    assert summary["n_segments"] == 2 and summary["segment_pixels"] == counts.tolist()
    assert stdout.startswith("polarseg: 2 segments over 64 x 64 pixels")
    rows = _csv_rows(out)
    assert [int(r["segment"]) for r in rows] == list(range(counts.size))
    assert [int(r["pixels"]) for r in rows] == counts.tolist()
    assert all(r["mean_pca_1"] == "" for r in rows)  # no thesis maps: no block features
    intensity = tifffile.imread(out / "intensity.tif")
    for r in rows:
        mean = intensity[labels == int(r["segment"])].mean()
        assert float(r["mean_intensity"]) == pytest.approx(mean, rel=1e-4)


def test_the_evaluation_of_a_method_without_blocks_needs_no_window(tmp_path, capsys):
    path = patch_tif(tmp_path, slice(3, 9))
    truth = np.zeros((64, 64), np.uint8)
    truth[3:9, 3:9] = 1
    gt = tmp_path / "truth.npy"
    np.save(gt, truth)
    out = tmp_path / "out"
    stdout, _, summary, labels = _segment(capsys, out, path, "--segments", 2, "--ground-truth", gt)
    evaluation = json.loads((out / "evaluation.json").read_text())
    assert evaluation["adjusted_rand_index"] == pytest.approx(adjusted_rand_index(truth, labels))
    assert evaluation["window"] is None and evaluation["block_accuracy_worst"] is None
    assert summary["evaluation"]["block_accuracy_optimistic"] is None
    (line,) = [line for line in stdout.splitlines() if "ground truth" in line]
    assert "mean IoU" in line and "block accuracy" not in line
    assert evaluate(truth, labels) == evaluate(truth, labels, None)
    # the thesis method's evaluation keeps its block accuracy over its window
    thesis = tmp_path / "thesis"
    argv = ("--preset", "recommended", "--segments", 2, "--ground-truth", gt)
    stdout, _, _, _ = _segment(capsys, thesis, path, *argv)
    evaluation = json.loads((thesis / "evaluation.json").read_text())
    assert evaluation["window"] == RECOMMENDED.window
    assert 0 <= evaluation["block_accuracy_worst"] <= evaluation["block_accuracy_optimistic"]
    assert "block accuracy" in stdout


def test_the_advice_names_the_own_parameters_of_a_method_from_outside(tmp_path, capsys):
    path = patch_tif(tmp_path, slice(0, 4))
    with toy_registered() as toy:
        argv = (path, "--method", toy, "--toy-share", "0.97")
        _, err, summary, _ = _segment(capsys, tmp_path / "toy", *argv)
        assert summary["degenerate"] is True
        advice = degenerate_advice(toy, AUTO.replace(method=toy))
    (line,) = [line for line in err.splitlines() if "degenerate result" in line]
    # the toy reads no shared parameter of the advice: only its own and scribbles
    assert line.endswith(
        "; try other values of its parameters (--toy-share), or scribbles (--scribbles)"
    )
    assert advice == "try other values of its parameters (--toy-share), or scribbles (--scribbles)"
