"""The classifier settings in the Segment dock's advanced section (issue 23, item 4):
feature groups, scales, model, trees and the region walk reach the classifier the strokes train."""

from __future__ import annotations

import numpy as np
import pytest
from _gui_helpers import error_messages, run_and_wait

from napari_polarseg.engine.classifier.classifier_settings import setting_help
from napari_polarseg.engine.synthetic.scenes import scribble_strokes

pytestmark = pytest.mark.gui


def test_classifier_settings_train_the_classifier(viewer, open_sample, add_widget, qtbot):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    widget.set_params(window=10, degree=4)
    controls = widget.classifier_controls
    assert controls.parent is not None and controls in widget.advanced  # the advanced section
    assert controls.trees.tooltip == setting_help("n_estimators")  # described once
    truth = np.asarray(viewer.layers["leaves ground truth"].data)
    scribbles = widget.new_scribbles_layer()
    scribbles.data = scribble_strokes(truth - 1, seed=0)
    controls.groups.value = ["intensity", "polarisation"]
    controls.scales.value = "1, 3"
    controls.model.value = "random_forest"
    controls.trees.value = 7
    controls.walk.value = 0.0  # the classifier alone, no region walk
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    clf = widget.classifier
    assert clf.params.model == "random_forest" and clf.params.n_estimators == 7
    assert len(clf.model.estimators_) == 7
    assert clf.params.region_walk == 0.0 and controls.walk.tooltip == setting_help("region_walk")
    assert clf.feature_params.groups == ("intensity", "polarisation")
    assert clf.feature_params.scales == (1.0, 3.0)
    assert not any(n.startswith("region:") for n in clf.feature_names)
    # a bad value: said in the status line, nothing runs
    controls.scales.value = "1, big"
    widget.run()
    assert "scales must be numbers" in widget.status.value and not widget.busy
