"""The pixel classifier in "Segment by material": live retraining while painting,
probability and uncertainty layers, classifier files, feature importances in the plots."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from _gui_helpers import Gate, click, error_messages, run_and_wait, wait_idle
from napari.layers import Image
from napari.utils.notifications import notification_manager

import napari_polarseg.engine.classifier.scribble_session as scribble_session_module
from napari_polarseg.classifier_file import SUFFIX, load_pixel_classifier
from napari_polarseg.engine import Pipeline, validity_mask
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.errors import Cancelled
from napari_polarseg.engine.synthetic.scenes import scribble_strokes
from napari_polarseg.widgets._layers import source_key
from napari_polarseg.widgets.plots import TOP_FEATURES
from napari_polarseg.widgets.segment import CUT_ONLY
from napari_polarseg.widgets.segment_files import ClassifierFiles

pytestmark = pytest.mark.gui

#: Fast parameters (the synthetic samples are 120 x 130 pixels).
FAST = {"window": 10, "degree": 4, "n_segments": 3}


def engine_segmentation(stack, params, scribbles=None, classifier=None):
    """The engine's pixel segmentation of the same input, without the plugin (the
    pipeline gets the mask the widget's pipeline store builds)."""
    data = np.asarray(stack.data)
    angles = np.deg2rad(stack.metadata["angles_deg"])
    mask = validity_mask(data, saturation="auto", dark_level=0)
    pipe = Pipeline(data, angles, params, mask=mask)
    return PixelSegmenter(pipe).segment(scribbles, classifier)


def shown_labels(segmentation) -> np.ndarray:
    """What the segments layer shows for an engine segmentation: the scribble values."""
    prediction = segmentation.prediction
    return np.asarray(prediction.classes, dtype=np.int32)[prediction.labels]


def painted(viewer, widget):
    """The leaves sample's truth, an empty scribbles layer and the strokes of seed 0."""
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    scribbles = widget.new_scribbles_layer()
    return truth, scribbles, scribble_strokes(truth - 1, seed=0)


def test_painting_retrains_live_on_the_kept_features(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    truth, scribbles, strokes = painted(viewer, widget)
    h, w = truth.shape
    widget.live.value = True
    wait_idle(qtbot, widget)
    # nothing painted yet: a message, no run; with live update on, an empty segments
    # layer waits for the first labels (napari adds a Labels layer in ~0.3 s)
    waiting = widget.output("segments")
    assert waiting is not None and not np.asarray(waiting.data).any()
    assert "paint at least 2 materials" in widget.status.value

    # the strokes of two materials, then of the third: each paint is one rerun
    scribbles.data = np.where(strokes <= 2, strokes, 0).astype(np.int32)
    assert widget._waiting()  # debounced like a changed value
    wait_idle(qtbot, widget)
    assert error_messages() == []
    segments = widget.output("segments")
    params = widget.params()
    first = engine_segmentation(stack, params, scribbles=np.asarray(scribbles.data))
    np.testing.assert_array_equal(segments.data, shown_labels(first))
    assert set(np.unique(segments.data)) == {1, 2}
    assert widget.classes.tolist() == [1, 2]
    assert "2 materials from scribbles (labels 1, 2)" in widget.status.value
    assert f"{first.classifier.n_training_pixels} training pixels" in widget.status.value
    # the object size the feature scales followed, as the engine's classifier kept them
    scales = ", ".join(f"{s:g}" for s in first.classifier.feature_params.scales)
    assert f"(estimated from the scene): feature scales σ = {scales} px" in widget.status.value
    pipe = widget.pipeline
    segmenter = widget.store.segmenter(source_key(stack))
    features = segmenter.cached_features
    assert features is not None and features.shape == (h, w)
    run_id, harmonics = widget._slot.run_id, pipe.calls["harmonics"]

    scribbles.data = strokes  # a second paint: the third material
    wait_idle(qtbot, widget)
    assert widget._slot.run_id == run_id + 1
    second = engine_segmentation(stack, params, scribbles=strokes)
    assert widget.output("segments") is segments  # updated in place
    np.testing.assert_array_equal(segments.data, shown_labels(second))
    assert set(np.unique(segments.data)) == {1, 2, 3}
    # retrained on the same feature stack: neither the features nor the pipeline's
    # stages were computed again
    assert widget.store.segmenter(source_key(stack)) is segmenter
    assert segmenter.cached_features is features
    assert widget.pipeline is pipe and pipe.calls["harmonics"] == harmonics
    result = widget.shown_result(stack)
    # the scene's run of the classifier method: its stages "features" and "classifier"
    assert result.method == "classifier" and "features" not in result.recomputed
    assert "classifier" in result.recomputed and "harmonics" not in result.recomputed

    # a brush stroke (the paint event) also retrains
    scribbles.brush_size = 3
    rows, cols = np.nonzero(strokes == 1)
    scribbles.paint((int(rows[0]), int(cols[0])), 2)
    wait_idle(qtbot, widget)
    assert widget._slot.run_id == run_id + 2
    third = engine_segmentation(stack, params, scribbles=np.asarray(scribbles.data))
    np.testing.assert_array_equal(segments.data, shown_labels(third))

    # probabilities and uncertainty: hidden images below the segments, in [0, 1]
    prob, unc = widget.output("probability"), widget.output("uncertainty")
    assert isinstance(unc, Image) and unc.name == f"uncertainty ({stack.name})" and not unc.visible
    assert isinstance(prob, Image) and not prob.visible
    assert unc.data.shape == (h, w) and unc.data.dtype == np.float32
    assert 0.0 <= float(unc.data.min()) and float(unc.data.max()) <= 1.0
    assert tuple(unc.contrast_limits) == (0.0, 1.0)
    np.testing.assert_allclose(unc.data, third.prediction.uncertainty, atol=1e-6)
    np.testing.assert_allclose(widget.uncertainty, third.prediction.uncertainty, atol=1e-6)
    np.testing.assert_allclose(prob.data, third.prediction.probabilities.max(axis=0), atol=1e-6)
    layers = viewer.layers
    assert layers.index(prob) < layers.index(segments) and layers.index(unc) < layers.index(
        segments
    )
    meta = segments.metadata["polarseg_summary"]["classifier"]
    assert meta["labels_from"] == "scribbles" and meta["classes"] == [1, 2, 3]
    assert meta["mean_uncertainty"] == pytest.approx(float(unc.data.mean()), abs=1e-6)

    # back to unsupervised: the classifier's layers go
    widget.scribbles_layer.value = None
    wait_idle(qtbot, widget)
    assert widget.output("uncertainty") is None and widget.output("probability") is None
    assert widget.uncertainty is None and widget.classifier is None
    assert error_messages() == []


def test_a_new_stroke_cancels_the_running_prediction(
    viewer, open_sample, add_widget, qtbot, monkeypatch
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    _, scribbles, strokes = painted(viewer, widget)
    ends: list[str] = []
    # the grid's prediction, the first of a stroke's (the preview)
    original = scribble_session_module.grid_probabilities

    def recording(*args, **kwargs):
        try:
            out = original(*args, **kwargs)
        except Cancelled:
            ends.append("cancelled")
            raise
        ends.append("done")
        return out

    monkeypatch.setattr(scribble_session_module, "grid_probabilities", recording)
    gate = Gate(monkeypatch, scribble_session_module, "grid_probabilities")
    widget.live.value = True
    gate.arm()
    scribbles.data = np.where(strokes <= 2, strokes, 0).astype(np.int32)
    qtbot.waitUntil(gate.entered.is_set, timeout=60_000)  # the prediction has started
    scribbles.data = strokes  # a new stroke while it runs
    qtbot.wait(400)  # the debounce: the newer request asks the running one to stop
    gate.release.set()
    wait_idle(qtbot, widget)
    # the first prediction stopped at its first chunk; only the newest result is shown
    assert ends == ["cancelled", "done"]
    assert error_messages() == [] and not widget.status.value.startswith("error")
    expected = engine_segmentation(stack, widget.params(), scribbles=strokes)
    np.testing.assert_array_equal(widget.output("segments").data, shown_labels(expected))

    # Cancel during a prediction: "cancelled", no error, the segments stay
    before = widget.output("segments").data.copy()
    gate.arm()
    scribbles.data = np.where(strokes == 3, 0, strokes).astype(np.int32)
    qtbot.waitUntil(gate.entered.is_set, timeout=60_000)
    qtbot.waitUntil(lambda: widget.cancel_button.enabled, timeout=10_000)
    click(qtbot, widget.cancel_button)
    gate.release.set()
    wait_idle(qtbot, widget)
    assert ends[-1] == "cancelled" and widget.status.value == "cancelled"
    assert error_messages() == []
    np.testing.assert_array_equal(widget.output("segments").data, before)


def test_save_and_load_classifier_round_trip(
    viewer, open_sample, add_widget, qtbot, tmp_path, monkeypatch
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    assert not widget.save_classifier_button.enabled  # nothing trained yet
    assert not widget.save_classifier(tmp_path / "early")
    assert widget.status.value.startswith("error: no classifier to save")
    assert error_messages() == [widget.status.value.removeprefix("error: ")]
    notification_manager.records.clear()
    _, scribbles, strokes = painted(viewer, widget)
    scribbles.data = strokes
    run_and_wait(qtbot, widget)
    trained_labels = widget.output("segments").data.copy()
    trained = widget.classifier
    assert trained is not None and widget.save_classifier_button.enabled

    # Save classifier… (the dialog patched as in test_params_json): the suffix is added
    answers: list = [str(tmp_path / "leaves")]
    monkeypatch.setattr(ClassifierFiles, "ask_path", lambda self, save: answers.pop(0))
    click(qtbot, widget.save_classifier_button)
    wait_idle(qtbot, widget)
    path = tmp_path / f"leaves{SUFFIX}"
    assert widget.status.value == f"saved the classifier to {path}"
    assert load_pixel_classifier(path).feature_names == trained.feature_names

    # something else on screen: the unsupervised cut
    widget.scribbles_layer.value = None
    run_and_wait(qtbot, widget)
    assert widget.classifier is None and not widget.save_classifier_button.enabled
    assert not np.array_equal(widget.output("segments").data, trained_labels)

    # Load classifier…: applied at once, not retrained, nearly the same labels (the
    # region walk of training also started from the strokes)
    answers.append(None)  # cancelled dialog: nothing happens
    click(qtbot, widget.load_classifier_button)
    assert widget.loaded is None
    answers.append(str(path))
    click(qtbot, widget.load_classifier_button)
    wait_idle(qtbot, widget)
    assert error_messages() == []
    assert widget.loaded is not None and widget.classifier is widget.loaded.classifier
    assert np.mean(widget.output("segments").data == trained_labels) > 0.95
    loaded_labels = widget.output("segments").data.copy()
    assert f"3 materials from the classifier leaves{SUFFIX}" in widget.status.value
    assert "training pixels" not in widget.status.value
    segments = widget.output("segments")
    assert segments.metadata["polarseg_inputs"]["classifier"] == str(path)
    assert segments.metadata["polarseg_summary"]["classifier"]["labels_from"] == "classifier"
    assert widget.output("uncertainty") is not None
    assert not any(getattr(widget, name).enabled for name in CUT_ONLY)
    assert widget.clear_classifier_button.enabled

    # Export results… says where the labels came from
    assert widget.export_results(tmp_path / "export")
    wait_idle(qtbot, widget)
    summary = json.loads((tmp_path / "export" / "summary.json").read_text(encoding="utf-8"))
    info = json.loads((tmp_path / "export" / "params.json").read_text(encoding="utf-8"))
    assert summary["labels_from"] == "classifier" and summary["scribble_classes"] == [1, 2, 3]
    assert info["napari"]["classifier_file"] == str(path)
    uncertainty = tifffile.imread(tmp_path / "export" / "uncertainty.tif")
    np.testing.assert_array_equal(uncertainty, widget.output("uncertainty").data)

    # the plots dock recomputes it from the file the segments record (nothing cached)
    plots = add_widget("Polarisation plots")
    widget._forget(set())
    click(qtbot, plots.run_button)
    assert plots.busy
    wait_idle(qtbot, plots)
    assert error_messages() == []
    np.testing.assert_array_equal(plots.result.labels + 1, loaded_labels)
    assert plots.classifier.feature_names == trained.feature_names
    run_and_wait(qtbot, widget)  # shown again by the Segment widget

    # on another stack (chosen now): the loaded classifier, as the engine applies it
    other = open_sample("camouflage")
    widget.stack_layer.value = other
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    loaded = widget.loaded.classifier
    expected = engine_segmentation(other, widget.params(), classifier=loaded)
    np.testing.assert_array_equal(widget.output("segments").data, shown_labels(expected))

    # painting again (here: new strokes on the first stack) trains on the strokes
    widget.stack_layer.value = stack
    widget.scribbles_layer.value = scribbles
    scribbles.data = np.where(strokes == 3, 0, strokes).astype(np.int32)
    run_and_wait(qtbot, widget)
    assert widget.loaded is None and not widget.clear_classifier_button.enabled
    assert "2 materials from scribbles" in widget.status.value

    # Clear: back to training on the strokes (here unchanged since the load)
    assert widget.load_classifier(path)
    wait_idle(qtbot, widget)
    assert widget.loaded is not None
    np.testing.assert_array_equal(widget.output("segments").data, loaded_labels)
    click(qtbot, widget.clear_classifier_button)
    assert widget.loaded is None and widget.status.value.startswith("the classifier")
    run_and_wait(qtbot, widget)
    assert "2 materials from scribbles" in widget.status.value
    assert error_messages() == []


def test_a_tampered_classifier_file_changes_nothing(
    viewer, open_sample, add_widget, qtbot, tmp_path
):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    _, scribbles, strokes = painted(viewer, widget)
    scribbles.data = strokes
    run_and_wait(qtbot, widget)
    path = tmp_path / f"good{SUFFIX}"
    assert widget.save_classifier(path)
    wait_idle(qtbot, widget)
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0x01  # one flipped byte inside the model payload
    bad = tmp_path / f"bad{SUFFIX}"
    bad.write_bytes(bytes(raw))
    layers = {layer.name: np.array(layer.data, copy=True) for layer in viewer.layers}
    run_id, classifier = widget._slot.run_id, widget.classifier

    assert widget.load_classifier(bad)
    wait_idle(qtbot, widget)
    status = widget.status.value
    assert status.startswith(f"error: {bad}: ") and "\n" not in status, status
    assert error_messages() == [status.removeprefix("error: ")]
    assert widget.loaded is None and widget.classifier is classifier
    assert widget._slot.run_id == run_id  # nothing ran
    assert {layer.name for layer in viewer.layers} == set(layers)
    for layer in viewer.layers:
        np.testing.assert_array_equal(layer.data, layers[layer.name])


def test_feature_importances_in_the_plots_dock(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(**FAST)
    plots = add_widget("Polarisation plots")
    plots.plot.value = "importances"
    assert plots.classifier is None
    assert "no pixel classifier" in plots.figure.texts[0].get_text()

    def bars() -> tuple[list[str], list[float]]:
        (ax,) = plots.figure.axes
        names = [t.get_text() for t in ax.get_yticklabels()]
        return names, [p.get_width() for p in ax.patches]

    _, scribbles, strokes = painted(viewer, widget)
    widget.live.value = True
    scribbles.data = np.where(strokes <= 2, strokes, 0).astype(np.int32)
    wait_idle(qtbot, widget)
    first = widget.classifier
    assert plots.classifier is first  # handed over without pressing anything
    names, widths = bars()
    top = list(first.importances().items())[:TOP_FEATURES]
    assert len(names) == min(TOP_FEATURES, len(first.feature_names)) == len(top)
    assert names == [name for name, _ in top]
    np.testing.assert_allclose(widths, [value for _, value in top])

    scribbles.data = strokes  # retrained: the chart follows
    wait_idle(qtbot, widget)
    assert plots.classifier is widget.classifier is not first
    names, widths = bars()
    top = list(widget.classifier.importances().items())[:TOP_FEATURES]
    assert names == [name for name, _ in top]
    np.testing.assert_allclose(widths, [value for _, value in top])

    # Load segmentation picks the classifier up too (e.g. after choosing the stack again)
    plots.classifier = None
    click(qtbot, plots.run_button)
    assert plots.classifier is widget.classifier
    assert plots.result is widget.shown_result(stack)
    assert error_messages() == []
