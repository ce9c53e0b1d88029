"""Partial results of a method's run (issue 38): the pixel classifier hands its coarse
preview and then its final labels over from inside ``Scene.segment``, on the scene's
kept scribble session, which the plugin's worker forwards to the GUI thread."""

from __future__ import annotations

import numpy as np
import pytest

from napari_polarseg.engine import Pipeline, Scene, validity_mask
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.errors import Cancelled, ClassifierInputError
from napari_polarseg.engine.methods import MethodOutput, MethodRun
from napari_polarseg.engine.methods.pixel_classification import scribble_session
from napari_polarseg.engine.params import AUTO
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes

ANGLES_DEG = [0, 45, 90, 135]


@pytest.fixture(scope="module")
def leaves():
    scene = make_scene("leaves", shape=(96, 104), angles_deg=ANGLES_DEG)
    return scene.stack, np.deg2rad(ANGLES_DEG), scribble_strokes(scene.labels, seed=0)


def test_method_run_hands_partials_to_its_receiver_and_checks_for_a_stop():
    out = MethodOutput(np.zeros((2, 2), int))
    run = MethodRun(["a"])
    assert not run.wants_partials
    run.partial(out)  # nobody listens: nothing happens
    got: list = []
    run.on_partial = lambda o, final: got.append((o, final))
    run.partial(out)
    run.partial(out, final=True)
    assert run.wants_partials and got == [(out, False), (out, True)]
    stopped = MethodRun(["a"], cancel=lambda: True, on_partial=lambda o, f: got.append(o))
    with pytest.raises(Cancelled):
        stopped.partial(out)
    assert len(got) == 2


def test_the_classifier_hands_over_its_preview_then_its_final_labels(leaves):
    stack, angles, strokes = leaves
    scene = Scene(stack, angles)
    got: list = []
    result = scene.segment(
        AUTO,
        {"scribbles": strokes},
        maps=True,
        reconstruction=True,
        on_partial=lambda *a: got.append(a),
    )
    assert [final for _, _, final in got] == [False, True]
    (preview, preview_out, _), (final, final_out, _) = got
    assert preview.method == final.method == result.method == "classifier"
    # without the maps, which are computed after the final labels are handed over
    assert preview.features is None and final.reconstruction_error is None
    assert result.features is not None and result.reconstruction_error is not None
    np.testing.assert_array_equal(final.labels, result.labels)
    assert final_out is scene.method_output(AUTO, {"scribbles": strokes})  # the kept output
    assert "preview" in preview_out.extra["seconds"]
    # the preview: the labels of the coarser grid, whose pixels alone were predicted
    before, after = preview_out.extra["prediction"], final_out.extra["prediction"]
    np.testing.assert_array_equal(preview.labels, before.labels)
    assert before.n_predicted < after.n_predicted
    # the labels are the engine's pixel segmentation of the same strokes
    mask = validity_mask(stack)
    reference = PixelSegmenter(Pipeline(stack, angles, AUTO, mask=mask)).segment(strokes)
    np.testing.assert_array_equal(result.labels, reference.result.labels)


def test_a_new_stroke_reuses_the_scenes_session_and_its_features(leaves):
    stack, angles, strokes = leaves
    scene = Scene(stack, angles)
    session = scribble_session(scene)
    session.segment_params = AUTO
    session.features()  # computed ahead of the first strokes, as the plugin does
    got: list = []
    first = scene.segment(AUTO, {"scribbles": strokes}, on_partial=lambda *a: got.append(a[2]))
    assert "features" not in first.recomputed and "classifier" in first.recomputed
    more = strokes.copy()
    more[:4, :20] = 1
    second = scene.segment(AUTO, {"scribbles": more}, on_partial=lambda *a: got.append(a[2]))
    assert scribble_session(scene) is session and session.feature_runs == 1
    assert scene.method_calls["classifier"] == 2 and not np.array_equal(first.labels, second.labels)
    # no maps asked for: nothing is left after the classifier, so no final partial
    assert got == [False, False]


def test_without_a_receiver_no_preview_is_computed(leaves):
    stack, angles, strokes = leaves
    scene = Scene(stack, angles)
    scene.segment(AUTO, {"scribbles": strokes})
    assert "preview" not in scene.method_output(AUTO, {"scribbles": strokes}).extra["seconds"]


def test_strokes_that_cannot_train_raise_the_classifiers_input_error(leaves):
    stack, angles, strokes = leaves
    one = np.where(strokes == strokes.max(), strokes, 0)
    with pytest.raises(ClassifierInputError, match="at least 2 materials"):
        Scene(stack, angles).segment(AUTO, {"scribbles": one})


def test_a_stop_during_the_preview_cancels_the_run(leaves):
    stack, angles, strokes = leaves
    scene = Scene(stack, angles)
    stop = {"now": False}

    def receive(result, out, final):
        stop["now"] = True  # e.g. a new stroke while the preview is shown

    with pytest.raises(Cancelled):
        scene.segment(AUTO, {"scribbles": strokes}, cancel=lambda: stop["now"], on_partial=receive)
    assert "classifier" not in scene.method_calls
