"""The plugin's scribble mode without Qt (issue 38): one worker job, ``segment_job``, runs
the pixel classifier through the stack's Scene; its preview and final labels come as
partial results, its features are the scene's session's, kept between strokes."""

from __future__ import annotations

import numpy as np
import pytest
from job_helpers import drive

from napari_polarseg.engine import Pipeline, Scene, validity_mask
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.methods.pixel_classification import scribble_session
from napari_polarseg.engine.params import AUTO
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes
from napari_polarseg.widgets.session import (
    ClassifierOutput,
    PipelineStore,
    features_job,
    segment_request,
)

ANGLES_DEG = [0, 45, 90, 135]


@pytest.fixture(scope="module")
def leaves():
    scene = make_scene("leaves", shape=(96, 104), angles_deg=ANGLES_DEG)
    return scene.stack, np.deg2rad(ANGLES_DEG), scribble_strokes(scene.labels, seed=0)


def run_strokes(store, stack, angles, strokes):
    """One scribble run as the Segment widget submits it: its job's yields, result,
    reports, partial results and the total it was submitted with."""
    request = segment_request(store, "k", stack, angles, AUTO, None, None, strokes)
    reports: list = []
    partials: list = []
    items, out = drive(
        request.job(*request.args, report=lambda *a: reports.append(a), partial=partials.append)
    )
    return items, out, reports, partials, request.total


def test_strokes_run_the_scenes_classifier_with_a_preview_first(leaves):
    stack, angles, strokes = leaves
    store = PipelineStore()
    _, n_features = drive(features_job(store, "k", stack, angles, AUTO))
    session = store.session("k")
    assert session is scribble_session(store.scene("k")) and session.feature_runs == 1
    assert n_features == session.cached_features.n_features

    items, out, reports, partials, total = run_strokes(store, stack, angles, strokes)
    assert items == []  # everything came through the callables
    assert isinstance(out, ClassifierOutput) and out.problem is None and out.trained
    # the preview, then the final labels while the thesis maps and error map are computed
    assert [p.preview for p in partials] == [True, False]
    assert all(p.result.features is None for p in partials)
    np.testing.assert_array_equal(partials[1].result.labels, out.result.labels)
    assert out.result.method == "classifier" and out.result.reconstruction_error is not None
    # the progress: the scene's own stages, as many as the request said
    names = [r[0] for r in reports]
    assert names[:4] == ["polarisation", "normals", "features", "classifier"]
    assert (
        {r[2] for r in reports}
        == {total}
        == {len(Scene.stages(AUTO, {"scribbles": strokes}, True, True))}
    )
    # the labels are the engine's, on the widgets' mask
    mask = validity_mask(stack, saturation="auto", dark_level=0)
    reference = PixelSegmenter(Pipeline(stack, angles, AUTO, mask=mask)).segment(strokes)
    np.testing.assert_array_equal(out.result.labels, reference.result.labels)
    assert out.classifier.n_training_pixels == reference.classifier.n_training_pixels

    # a second stroke: the kept features, only the preview before the (kept) maps
    more = strokes.copy()
    more[:4, :20] = 1
    _, again, _, partials, _ = run_strokes(store, stack, angles, more)
    assert store.session("k") is session and session.feature_runs == 1
    assert [p.preview for p in partials] == [True]
    assert "features" not in again.result.recomputed and "classifier" in again.result.recomputed


def test_strokes_of_one_material_give_the_problem_not_an_error(leaves):
    stack, angles, strokes = leaves
    one = np.where(strokes == 1, 1, 0)
    _, out, _, partials, _ = run_strokes(PipelineStore(), stack, angles, one)
    assert out.segmentation is None and partials == []
    assert out.trained and "at least 2 materials" in out.problem
