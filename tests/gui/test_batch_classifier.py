"""*Apply classifier* in the Batch dock (issue 23, item 4): a saved pixel classifier
labels every scene of the folder, as ``polarseg batch --classifier`` does."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from _gui_helpers import click

from napari_polarseg import batch
from napari_polarseg.classifier_file import load_pixel_classifier, save_pixel_classifier
from napari_polarseg.engine import Pipeline, SegmentParams
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes
from napari_polarseg.io import read_stack

pytestmark = pytest.mark.gui

SHAPE = (64, 72)
PARAMS = SegmentParams(window=8)


def _classifier(path):
    """A classifier trained on the leaves scene's strokes (painted 3, 6, …), its materials named."""
    scene = make_scene("leaves", shape=SHAPE, seed=0)
    strokes = scribble_strokes(scene.labels, seed=0, length=5) * 3  # values 3, 6, 9
    pipe = Pipeline(scene.stack, np.deg2rad(scene.angles_deg), PARAMS)
    clf = PixelSegmenter(pipe).segment(strokes, reconstruction=False).classifier
    clf = clf.named({3: "leaf", 6: "stem"})
    save_pixel_classifier(path, clf)
    return load_pixel_classifier(path)


def test_batch_dock_applies_a_saved_classifier_to_every_scene(viewer, add_widget, qtbot, tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    for seed, name in enumerate(("leaves", "fruit")):
        scene = make_scene(name, shape=SHAPE, seed=seed)
        np.savez(folder / f"{name}.npz", stack=scene.stack, angles=scene.angles_deg)
    clf_path = tmp_path / "mine.polarseg-clf"
    clf = _classifier(clf_path)
    out = tmp_path / "out"
    widget = add_widget("Batch over a folder")
    widget.folder.value = folder
    widget.out.value = out
    widget.scheduler.value = "inline"
    widget.source.value = "JSON file"
    params_file = tmp_path / "params.json"
    params_file.write_text(json.dumps(PARAMS.to_dict()))
    widget.params_file.value = params_file
    widget.classifier.value = clf_path
    click(qtbot, widget.run_button)
    assert widget.wait(120)
    assert widget.table.to_dict("list")["status"] == ["done", "done"], widget.status.value
    for name in ("fruit", "leaves"):
        scene_out = out / name
        assert batch.is_complete(scene_out)
        summary = json.loads((scene_out / "summary.json").read_text())
        assert summary["labels_from"] == "classifier"
        assert summary["materials"]["3"] == "leaf"
        # the same labels as the engine applying the same classifier, in its values
        data = read_stack(folder / f"{name}.npz")
        pipe = Pipeline(data.stack, np.deg2rad(data.angles_deg), PARAMS)
        expected = PixelSegmenter(pipe).segment(classifier=clf, reconstruction=False)
        values = np.asarray(clf.classes)[expected.prediction.labels]
        np.testing.assert_array_equal(tifffile.imread(scene_out / "labels.tif"), values)
        assert "leaf" in (scene_out / "segments.csv").read_text()

    # a file that is not a classifier: one message, no scene run
    bad = tmp_path / "bad.polarseg-clf"
    bad.write_bytes(b"not a zip")
    widget.classifier.value = bad
    widget.resume.value = False
    click(qtbot, widget.run_button)
    assert widget.wait(120)
    assert "bad.polarseg-clf" in widget.status.value
    widget.classifier.value = tmp_path / "missing.polarseg-clf"
    widget.run()
    assert widget.status.value.startswith("error") and "not a file" in widget.status.value
