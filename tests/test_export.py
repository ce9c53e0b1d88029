"""outputs.write_result_folder: the `segment` output folder from any SegmentationResult."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import warnings

import numpy as np
import pytest
import tifffile
from skimage import io as skio
from test_cli import CONTRACT, THESIS_MAPS

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import Pipeline, PolarsegError, SegmentParams
from napari_polarseg.engine.analysis.evaluation import evaluate
from napari_polarseg.engine.classifier.scribbles import scribble_result
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.io import read_params_dict
from napari_polarseg.outputs import OutputError, write_result_folder

SHAPE = (64, 72)
PARAMS = SegmentParams(window=8, degree=4, n_segments=3)
#: The files `polarseg segment --overview` writes.
FOLDER = CONTRACT | THESIS_MAPS | {"overview.png"}  # results of the thesis method
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def scene():
    return make_scene("leaves", shape=SHAPE)


@pytest.fixture(scope="module")
def run(scene):
    pipe = Pipeline(scene.stack, scene.angles, PARAMS)
    return pipe, pipe.run()


def write(out, scene, result, **kwargs):
    """write_result_folder for the scene's stack and angles."""
    return write_result_folder(
        out, stack=scene.stack, angles_deg=scene.angles_deg, result=result, **kwargs
    )


def read_csv(path):
    lines = path.read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    return [dict(zip(header, line.split(","), strict=True)) for line in lines[1:]]


def test_writes_the_segment_folder_from_a_pipeline_result(tmp_path, scene, run):
    pipe, result = run
    out = tmp_path / "out"
    written = write(out, scene, result, mask=pipe.mask, source="synthetic leaves")
    assert set(os.listdir(out)) == FOLDER
    assert sorted(written) == sorted(FOLDER)
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary left

    labels = tifffile.imread(out / "labels.tif")
    assert labels.dtype == np.uint16
    np.testing.assert_array_equal(labels, result.labels)
    np.testing.assert_array_equal(tifffile.imread(out / "mask.tif"), result.valid.astype(np.uint8))
    dop = tifffile.imread(out / "dop.tif")
    assert dop.dtype == np.float32
    np.testing.assert_allclose(dop, result.dop, rtol=1e-6)

    info = json.loads((out / "params.json").read_text(encoding="utf-8"))
    assert SegmentParams.from_dict(info["params"]) == PARAMS
    assert info["command"] == "export" and info["input"] == "synthetic leaves"
    assert info["angles_deg"] == pytest.approx(list(scene.angles_deg))
    assert info["stack_shape"] == list(scene.stack.shape)
    assert info["output_shape"] == list(SHAPE)
    assert info["saturation_level"] == pipe.mask.saturation_level
    assert info["registration"] == {"ran": False, "reference_frame": None, "shifts_px": None}
    # the CLI reads it back with --params
    assert SegmentParams.from_dict(read_params_dict(str(out / "params.json"))) == PARAMS

    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["n_segments"] == result.n_segments
    assert summary["output_shape"] == list(SHAPE)
    assert summary["io_seconds"]["write"] >= 0

    rows = read_csv(out / "segments.csv")
    assert [int(r["segment"]) for r in rows] == list(range(result.n_segments))
    assert sum(int(r["pixels"]) for r in rows) == SHAPE[0] * SHAPE[1]
    for r in rows:
        assert int(r["pixels"]) == np.count_nonzero(result.labels == int(r["segment"]))
        assert float(r["mean_pca_1"]) == float(r["mean_pca_1"])  # a number

    data = (out / "overview.png").read_bytes()
    assert data.startswith(PNG_SIGNATURE)
    figure = skio.imread(out / "overview.png")
    assert figure.ndim == 3 and figure.shape[2] in (3, 4)
    assert 1.0 <= figure.shape[1] / figure.shape[0] <= 2.5  # a grid of 2 x 4 panels


def test_cli_and_write_result_folder_write_the_same_folder(tmp_path, scene, run, capsys):
    pipe, result = run
    path = tmp_path / "scene.tif"
    pio.write_stack_tiff(path, scene.stack, scene.angles_deg)
    mine = tmp_path / "mine"
    write(mine, scene, result, mask=pipe.mask)
    # the exported params.json repeats the run on the command line
    theirs = tmp_path / "cli"
    argv = ["segment", str(path), "--out", str(theirs), "--params", str(mine / "params.json")]
    assert cli.main([*argv, "--overview"]) == 0, capsys.readouterr().err

    assert set(os.listdir(theirs)) == set(os.listdir(mine)) == FOLDER
    np.testing.assert_array_equal(
        tifffile.imread(theirs / "labels.tif"), tifffile.imread(mine / "labels.tif")
    )
    for name in ("mask.tif", "dop.tif", "phase.tif", "reconstruction_error.tif"):
        np.testing.assert_array_equal(tifffile.imread(theirs / name), tifffile.imread(mine / name))
    assert (theirs / "segments.csv").read_text() == (mine / "segments.csv").read_text()
    a = json.loads((theirs / "params.json").read_text())
    b = json.loads((mine / "params.json").read_text())
    assert list(a) == list(b)  # one format, the same keys in the same order
    assert a["params"] == b["params"]
    same = ("stack_shape", "output_shape", "angles_deg", "duplicate_angles", "registration")
    assert {k: a[k] for k in same} == {k: b[k] for k in same}
    extra = set(json.loads((theirs / "summary.json").read_text())) - set(
        json.loads((mine / "summary.json").read_text())
    )
    assert extra == {"segment_seconds"}  # the CLI also times its own run


def test_scribble_probabilities_evaluation_plots_and_extra_items(tmp_path, scene, run, caplog):
    pipe, result = run
    strokes = np.zeros(SHAPE, dtype=np.int32)  # a dotted grid over every material
    strokes[2::4, 2::4] = scene.labels[2::4, 2::4] + 1
    labels, proba = scribble_result(pipe, strokes)
    w, (r, c) = PARAMS.window, result.block_labels.shape
    block = labels[: r * w : w, : c * w : w]
    scribbled = dataclasses.replace(result, labels=labels, block_labels=block, ncut_values=[])
    evaluation = evaluate(scene.labels, labels, PARAMS.window)
    out = tmp_path / "out"
    written = write(
        out,
        scene,
        scribbled,
        command="napari",
        overview=False,
        plots=True,
        probabilities=proba,
        evaluation=evaluation,
        info={"napari": {"stack_layer": "leaves"}},
        summary={"labels_from": "scribbles"},
    )
    plots = sorted(name for name in written if name.startswith("plots/"))
    assert len(plots) == 6 and plots == sorted(f"plots/{p}" for p in os.listdir(out / "plots"))
    assert set(os.listdir(out)) == (FOLDER - {"overview.png"}) | {
        "probabilities.tif",
        "evaluation.json",
        "plots",
    }
    # read without a warning (tifffile warns through its logger, not only warnings)
    with warnings.catch_warnings(), caplog.at_level(logging.WARNING):
        warnings.simplefilter("error")
        stored = tifffile.imread(out / "probabilities.tif")
        with tifffile.TiffFile(out / "probabilities.tif") as tif:
            meta, axes = tif.shaped_metadata[0], tif.series[0].axes
    assert not caplog.records, [r.getMessage() for r in caplog.records]
    assert axes == meta["axes"] == "CYX"
    assert "k-th smallest scribble value" in meta["dimensions"]
    assert meta["quantity"] == "class probability from the pixel classifier"
    assert stored.shape == proba.shape and stored.dtype == np.float32
    np.testing.assert_array_equal(np.argmax(stored, axis=0), tifffile.imread(out / "labels.tif"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["labels_from"] == "scribbles"
    assert summary["adjusted_rand_index"] == pytest.approx(evaluation["adjusted_rand_index"])
    assert summary["evaluation"]["mean_iou"] == pytest.approx(evaluation["mean_iou"])
    info = json.loads((out / "params.json").read_text())
    assert info["command"] == "napari" and info["napari"] == {"stack_layer": "leaves"}
    assert info["saturation_level"] is None  # no mask given


def test_mismatched_inputs_raise_before_writing(tmp_path, scene, run):
    _, result = run
    out = tmp_path / "out"
    common = {"angles_deg": scene.angles_deg, "result": result}
    with pytest.raises(PolarsegError, match="does not match"):
        write_result_folder(out, stack=scene.stack[:, :-1], **common)
    with pytest.raises(PolarsegError, match="angles"):
        write_result_folder(out, stack=scene.stack[:-1], **common)
    with pytest.raises(PolarsegError, match="probabilities"):
        write_result_folder(out, stack=scene.stack, probabilities=np.zeros((2, 3, 4)), **common)
    assert not out.exists()


def test_unwritable_folder_raises_output_error(tmp_path, scene, run):
    _, result = run
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(OutputError, match=f"cannot write {blocker}"):
        write(blocker, scene, result)
    assert blocker.read_text() == "not a folder"
