"""Showing a classifier's output (issue 40, point 12): what the show computes from the
whole-image arrays is made in the worker (``ShownParts``) and gives what the GUI thread
computed before; renamed materials keep it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from job_helpers import drive

from napari_polarseg.engine.params import AUTO
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes
from napari_polarseg.widgets.session import (
    PipelineStore,
    named_output,
    segment_request,
    shown_result,
)
from napari_polarseg.widgets.session.classify import shown_parts

ANGLES_DEG = [0, 45, 90, 135]


@pytest.fixture(scope="module")
def outputs():
    scene = make_scene("leaves", shape=(96, 104), angles_deg=ANGLES_DEG)
    strokes = 10 * scribble_strokes(scene.labels, seed=0)
    angles = np.deg2rad(ANGLES_DEG)
    request = segment_request(PipelineStore(), "k", scene.stack, angles, AUTO, None, None, strokes)
    partials: list = []
    _, out = drive(request.job(*request.args, partial=partials.append))
    return [*partials, out]


def test_every_output_comes_with_its_parts(outputs):
    assert [o.preview for o in outputs] == [True, False, False]
    for out in outputs:
        assert out.parts is not None and out.parts.fits(out.result, out.prediction)


def test_the_parts_show_what_the_arrays_give(outputs):
    angles = np.array(ANGLES_DEG, dtype=float)
    for out in outputs:
        made = shown_result(out, angles, partial=True)
        again = shown_result(replace(out, parts=None), angles, partial=True)
        np.testing.assert_array_equal(made.labels, again.labels)
        np.testing.assert_array_equal(made.confidence, again.confidence)
        assert made.summary == again.summary and made.meta == again.meta
        assert made.labels.dtype == np.int32 and set(np.unique(made.labels)) <= {10, 20, 30, 40}
        probabilities = out.prediction.probabilities
        np.testing.assert_array_equal(made.confidence, probabilities.max(axis=0))
        # shown twice, the summary is not changed in place
        assert "classifier" not in out.parts.summary


def test_renamed_materials_keep_the_parts(outputs):
    out = outputs[-1]
    named = named_output(out, {10: "leaf"})
    assert named.parts is not None and named.parts.fits(named.result, named.prediction)
    assert named.parts.labels is out.parts.labels
    assert shown_parts(named.segmentation).summary == named.parts.summary
