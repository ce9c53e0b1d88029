"""Evaluation measures (thesis section 5.4) against hand-computed small cases."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine.analysis.evaluation import (
    STATISTICS_COLUMNS,
    adjusted_rand_index,
    block_accuracy,
    evaluate,
    segment_iou,
    segment_statistics,
)
from napari_polarseg.engine.errors import PolarsegError

# three materials: 0 top-left, 1 right half, 2 bottom-left
THREE = np.array(
    [
        [0, 0, 1, 1],
        [0, 0, 1, 1],
        [2, 2, 1, 1],
        [2, 2, 1, 1],
    ]
)
# two materials with one mixed 2 x 2 block (top right)
MIXED = np.array(
    [
        [0, 0, 0, 1],
        [0, 0, 1, 1],
        [0, 0, 1, 1],
        [0, 0, 1, 1],
    ]
)
HALVES = np.array([[0, 0, 1, 1]] * 4)


def test_permuted_label_ids_score_perfectly():
    labels = np.choose(THREE, [5, 7, 9])  # same partition, other ids
    assert adjusted_rand_index(THREE, labels) == pytest.approx(1.0)
    per, mean, matching = segment_iou(THREE, labels)
    assert per == {0: 1.0, 1: 1.0, 2: 1.0}
    assert mean == 1.0
    assert matching == {0: 5, 1: 7, 2: 9}
    assert block_accuracy(THREE, labels, 2) == (1.0, 1.0)


def test_adjusted_rand_index_hand_computed_zero_and_sklearn():
    # contingency [[2, 0], [1, 1]]: sum C(n_ij, 2) = 1 = expected index -> ARI 0
    assert adjusted_rand_index([[0, 0], [1, 1]], [[0, 0], [0, 1]]) == pytest.approx(0.0)
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, 3, (6, 7)), rng.integers(0, 4, (6, 7))
    assert adjusted_rand_index(a, b) == pytest.approx(adjusted_rand_score(a.ravel(), b.ravel()))


def test_mixed_block_is_wrong_in_the_worst_case_and_right_in_the_optimistic_case():
    labels = np.where(HALVES == 0, 3, 4)
    # blocks: TL pure 0 -> 3, TR mixed -> 4, BL pure 0 -> 3, BR pure 1 -> 4
    assert block_accuracy(MIXED, labels, 2) == (0.75, 1.0)
    per, mean, matching = segment_iou(MIXED, labels)
    # truth 0: 9 px, label 3: 8 px, overlap 8; truth 1: 7 px, label 4: 8 px, overlap 7
    assert per == pytest.approx({0: 8 / 9, 1: 7 / 8})
    assert mean == pytest.approx((8 / 9 + 7 / 8) / 2)
    assert matching == {0: 3, 1: 4}


def test_missing_segment_scores_zero_iou_and_its_blocks_wrong():
    per, mean, matching = segment_iou(THREE, HALVES)
    # IoU(1, right) = 1; top-left and bottom-left each 4/8 with the left half, which
    # only one of them can have
    assert matching[1] == 1
    assert sorted(per.values()) == pytest.approx([0.0, 0.5, 1.0])
    assert mean == pytest.approx(0.5)
    assert sorted(matching.values(), key=str) == [0, 1, None]
    # pure blocks: TL(0->0), TR(1->1), BL(2->0), BR(1->1): one of TL/BL is wrong
    assert block_accuracy(THREE, HALVES, 2) == (0.75, 0.75)


def test_block_majority_label_and_remainder_strips_are_ignored():
    labels = np.where(HALVES == 0, 0, 1)
    labels[0, 0] = 1  # TL block: 3 x label 0, 1 x label 1 -> majority 0
    labels[2:, :2] = [[1, 1], [1, 0]]  # BL block: majority 1 -> wrong
    assert block_accuracy(np.where(HALVES == 0, 0, 1), labels, 2) == (0.75, 0.75)
    # a 5 x 5 image with w = 2: the last row and column are not part of any block
    truth5 = np.pad(THREE, ((0, 1), (0, 1)), constant_values=8)
    labels5 = np.pad(np.choose(THREE, [5, 7, 9]), ((0, 1), (0, 1)), constant_values=2)
    assert block_accuracy(truth5, labels5, 2) == (1.0, 1.0)
    # a window of the whole 4 x 4 image: one mixed block
    assert block_accuracy(THREE, THREE, 4) == (0.0, 1.0)


def test_evaluate_bundles_every_measure():
    labels = np.where(HALVES == 0, 3, 4)
    result = evaluate(MIXED, labels, 2)
    assert result["adjusted_rand_index"] == pytest.approx(adjusted_rand_index(MIXED, labels))
    assert result["mean_iou"] == pytest.approx((8 / 9 + 7 / 8) / 2)
    assert result["block_accuracy_worst"] == 0.75
    assert result["block_accuracy_optimistic"] == 1.0
    assert result["n_true_segments"] == 2 and result["n_predicted_segments"] == 2


@pytest.mark.parametrize(
    "truth, labels, window, words",
    [
        (THREE, THREE[:3], 2, "ground truth is"),
        (THREE, THREE, 5, "larger than the image"),
        (THREE, THREE, 0, "positive integer"),
        (THREE, THREE + 0.5, 2, "integer labels"),
        (THREE[0], THREE[0], 1, "2-D"),
    ],
)
def test_bad_arguments_raise_polarseg_error(truth, labels, window, words):
    with pytest.raises(PolarsegError, match=words):
        evaluate(truth, labels, window)


def test_segment_statistics_means_and_circular_phase():
    labels = np.array([[0, 0, 1], [0, 0, 1]])
    intensity = np.array([[1.0, 3.0, 10.0], [5.0, 7.0, 20.0]])
    dop = np.full((2, 3), 0.1)
    zenith = np.full((2, 3), np.pi / 4)
    # segment 1: 170 and 10 degrees -> axial mean 0 (not 90)
    phase = np.deg2rad([[30.0, 30.0, 170.0], [30.0, 30.0, 10.0]])
    valid = np.ones((2, 3), bool)
    valid[1, 1] = False  # the 7 leaves segment 0's means
    features = np.array([[1.0, 2.0], [3.0, 4.0]])
    rows = segment_statistics(
        labels,
        intensity,
        dop,
        zenith,
        phase,
        valid=valid,
        block_labels=np.array([[0, 1]]),
        features=features,
    )
    assert [tuple(r) for r in rows] == [STATISTICS_COLUMNS] * 2
    s0, s1 = rows
    assert s0["pixels"] == 4 and s0["area_fraction"] == pytest.approx(4 / 6)
    assert s0["mean_intensity"] == pytest.approx(3.0)
    assert s1["mean_intensity"] == pytest.approx(15.0)
    assert s0["mean_dop"] == pytest.approx(0.1)
    assert s0["mean_zenith_deg"] == pytest.approx(45.0)
    assert s0["circular_mean_phase_deg"] == pytest.approx(30.0)
    assert min(s1["circular_mean_phase_deg"], 180 - s1["circular_mean_phase_deg"]) < 1e-9
    assert (s0["mean_pca_1"], s0["mean_pca_2"]) == (1.0, 2.0)
    assert (s1["mean_pca_1"], s1["mean_pca_2"]) == (3.0, 4.0)
    assert np.isnan(s1["mean_pca_3"])  # only 2 features
