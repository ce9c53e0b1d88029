"""*Export results…* in "Segment by material": the `polarseg segment` folder from the plugin."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import tifffile
from _gui_helpers import click, error_messages, run_and_wait, wait_idle

from napari_polarseg.engine import SegmentParams
from napari_polarseg.outputs import FLOAT_OUTPUTS

pytestmark = pytest.mark.gui

#: Fast parameters (the synthetic samples are 120 x 130 pixels).
FAST = {"window": 10, "degree": 4, "n_segments": 3}
#: What `polarseg segment --overview` writes.
FOLDER = {"labels.tif", *FLOAT_OUTPUTS, "mask.tif", "segments.csv", "overview.png"}
FOLDER |= {"params.json", "summary.json", "stokes.tif", "aolp_dolp.png"}


def test_export_button_writes_the_folder_and_params_load_back(
    viewer, open_sample, add_widget, qtbot, tmp_path, monkeypatch
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    assert not widget.export_button.enabled  # nothing to export yet
    run_and_wait(qtbot, widget)
    assert widget.export_button.enabled
    result = widget.shown_result(stack)
    params = widget.params()

    out = tmp_path / "export"
    out.mkdir()
    from qtpy.QtWidgets import QFileDialog

    monkeypatch.setattr(QFileDialog, "getExistingDirectory", lambda *a, **k: str(out))
    click(qtbot, widget.export_button)  # folder dialog -> export_results(out)
    wait_idle(qtbot, widget)
    assert error_messages() == []
    assert set(os.listdir(out)) == FOLDER
    assert widget.status.value == f"exported {len(FOLDER)} files to {out}"

    labels = tifffile.imread(out / "labels.tif")
    np.testing.assert_array_equal(labels, result.labels)  # 0 = first segment, as the CLI
    np.testing.assert_array_equal(labels + 1, widget.output("segments").data)
    info = json.loads((out / "params.json").read_text(encoding="utf-8"))
    assert info["command"] == "napari" and info["napari"]["stack_layer"] == stack.name
    assert info["angles_deg"] == pytest.approx(list(stack.metadata["angles_deg"]))
    assert SegmentParams.from_dict(info["params"]) == params
    lines = (out / "segments.csv").read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("segment,name,pixels,")  # unsupervised: empty names
    pixels = [int(line.split(",")[2]) for line in lines[1:]]
    assert sum(pixels) == labels.size and len(pixels) == result.n_segments

    # params.json loads back into the widget
    widget.preset.value = "recommended"
    assert widget.params() != params
    assert widget.load_params(out / "params.json")
    assert widget.params() == params


def test_export_after_a_scribble_run_writes_probabilities_and_uncertainty(
    viewer, open_sample, add_widget, qtbot, tmp_path
):
    open_sample("leaves")
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    widget = add_widget("Segment by material")
    widget.set_params(window=8, degree=4)
    scribbles = widget.new_scribbles_layer()
    strokes = np.zeros(truth.shape, dtype=np.int32)  # a dotted grid over every material
    strokes[2::4, 2::4] = truth[2::4, 2::4]
    scribbles.data = strokes
    run_and_wait(qtbot, widget)
    assert error_messages() == []

    assert widget.export_results(tmp_path / "new" / "folder")  # created
    wait_idle(qtbot, widget)
    out = tmp_path / "new" / "folder"
    assert set(os.listdir(out)) == FOLDER | {"probabilities.tif", "uncertainty.tif"}
    proba = tifffile.imread(out / "probabilities.tif")
    np.testing.assert_array_equal(proba, widget.probabilities.astype(np.float32))
    uncertainty = tifffile.imread(out / "uncertainty.tif")
    np.testing.assert_array_equal(uncertainty, widget.uncertainty)
    np.testing.assert_array_equal(uncertainty, widget.output("uncertainty").data)
    labels = tifffile.imread(out / "labels.tif")
    # one numbering: labels.tif holds the scribble values, as the segments layer shows
    np.testing.assert_array_equal(labels, widget.output("segments").data)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["labels_from"] == "scribbles"
    assert summary["scribble_classes"] == [int(c) for c in widget.classes]
    clf = summary["classifier"]
    assert clf["n_training_pixels"] == widget.classifier.n_training_pixels
    assert clf["n_features"] == len(widget.classifier.feature_names)
    assert list(clf["top_features"]) == list(widget.classifier.importances())[:5]
    info = json.loads((out / "params.json").read_text(encoding="utf-8"))
    assert info["napari"]["scribbles_layer"]["name"] == scribbles.name
    assert info["napari"]["classifier_file"] is None


def test_unwritable_folder_and_nothing_to_export_report_in_the_status_line(
    viewer, open_sample, add_widget, qtbot, tmp_path
):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    assert not widget.export_results(tmp_path / "early")
    assert widget.status.value.startswith("error: nothing to export")
    assert not (tmp_path / "early").exists()

    run_and_wait(qtbot, widget)
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert widget.export_results(blocker)
    wait_idle(qtbot, widget)
    assert widget.status.value.startswith(f"error: cannot write {blocker}")
    assert "Traceback" not in widget.status.value
    assert any(m.startswith(f"cannot write {blocker}") for m in error_messages())
    assert blocker.read_text() == "not a folder"

    # the stack layer removed: nothing left to export
    viewer.layers.remove("leaves")
    assert not widget.export_button.enabled
