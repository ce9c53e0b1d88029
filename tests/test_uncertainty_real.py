"""The scribble classifier's uncertainty points at its mistakes on real frames (issue 14).

On each hand-labelled real frame (``napari_polarseg/sample_data/truth``), the pixel
classifier is trained on the truth file's fixed strokes, as the plugin's scribble mode
does; its uncertainty 1 − (p1 − p2) must rank the wrongly labelled pixels of the truth
above the right ones (ROC AUC ≥ 0.75): "paint where it is unsure" then leads to its
errors. Skipped without the optional frames in ``../shared/data/polanalyser``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sklearn.metrics import roc_auc_score

from napari_polarseg import io as pio
from napari_polarseg.engine import Pipeline
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.truth import read_truth_file, real_frame_path, truth_files

REAL_DIR = (
    Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "polanalyser"
).resolve()
#: Issue 14's floor of the uncertainty's ROC AUC for "this pixel is wrong".
MIN_AUC = 0.75


@pytest.mark.skipif(
    not REAL_DIR.is_dir(),
    reason="real polarisation-camera frames not found in ../shared/data/polanalyser "
    "(beside the repository; docs/data.md, 'Optional real data')",
)
@pytest.mark.parametrize("path", truth_files(), ids=lambda p: p.stem)
def test_uncertainty_ranks_the_classifiers_mistakes_first(path):
    truth_file = read_truth_file(path)
    data = pio.read_stack(real_frame_path(truth_file, REAL_DIR), mosaic=list(truth_file.mosaic))
    pipe = Pipeline(data.stack, data.angles_rad)
    out = PixelSegmenter(pipe).segment(truth_file.strokes, reconstruction=False)
    pred = out.prediction
    where = truth_file.truth > 0
    labelled = np.asarray(pred.classes)[pred.labels][where]
    wrong = labelled != truth_file.truth[where]
    assert wrong.sum() < wrong.size
    if not wrong.any():  # e.g. polarizer: the film and the scene differ in ρ by 17x
        pytest.skip(f"{truth_file.frame}: no mistakes on the labelled pixels, none to rank")
    auc = roc_auc_score(wrong, pred.uncertainty[where])
    assert auc >= MIN_AUC, f"{truth_file.frame}: uncertainty AUC {auc:.3f} < {MIN_AUC}"
