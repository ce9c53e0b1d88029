"""The default method (preset auto): valid superpixels with the node features diffused
over whole surfaces (``surface_superpixels``), and the number of materials it finds by
itself (``n_segments = 0``) on planted 2-, 3- and 4-material images."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score
from test_valid_superpixels import ANGLES, banded_stack

from napari_polarseg.engine import Scene
from napari_polarseg.engine.methods import surface_superpixels, valid_superpixels
from napari_polarseg.engine.methods.registry import get_method
from napari_polarseg.engine.methods.valid_superpixels import ValidSuperpixels
from napari_polarseg.engine.params import AUTO
from napari_polarseg.engine.unsupervised.choose_k import estimate_k
from napari_polarseg.engine.unsupervised.params import UnsupervisedParams
from napari_polarseg.engine.unsupervised.texture import TEXTURE_FEATURES


def test_auto_preset_is_this_method_with_the_wider_diffusion():
    assert AUTO.method == surface_superpixels.SurfaceSuperpixels.name
    method = get_method(AUTO.method)
    assert isinstance(method, ValidSuperpixels) and method.finds_k
    base = UnsupervisedParams()
    assert method.params == base.replace(
        diffusion_range=surface_superpixels.REACH,
        diffusion_tau=surface_superpixels.BORDER_SCALE,
        border_gate=surface_superpixels.BORDER_GATE,
        texture=TEXTURE_FEATURES,
        texture_weight=surface_superpixels.TEXTURE_WEIGHT,
    )
    # it reaches further and crosses fainter borders than the valid-superpixel method
    assert method.params.diffusion_range > base.diffusion_range
    assert method.params.diffusion_tau > base.diffusion_tau


@pytest.mark.parametrize("method", ["surface_superpixels", "superpixel_consensus"])
@pytest.mark.parametrize("k", [2, 3, 4])
def test_planted_materials_recovered_with_k_given_and_found(k, method):
    """This method and the consensus of it over superpixel sizes."""
    stack, truth = banded_stack(k)
    scene = Scene(stack, ANGLES)
    given = scene.segment(AUTO.replace(method=method, n_segments=k))
    assert adjusted_rand_score(truth.ravel(), given.labels.ravel()) > 0.95
    assert not given.summary()["degenerate"]
    found = scene.segment(AUTO.replace(method=method, n_segments=0))
    record = found.method_record
    assert record["k_found"] is True and record["k"] == k
    assert 0.0 < record["k_confidence"] <= 1.0
    np.testing.assert_array_equal(found.labels, given.labels)


def test_kept_apart_from_the_valid_superpixel_method(monkeypatch):
    """Both methods on one scene: each keeps its own superpixel model, so switching
    back neither reruns the method nor draws the superpixels again."""
    calls = []
    prepare = valid_superpixels.prepare_regions

    def counted(*args, **kwargs):
        calls.append(args[3])  # the method's UnsupervisedParams
        return prepare(*args, **kwargs)

    monkeypatch.setattr(valid_superpixels, "prepare_regions", counted)
    stack, truth = banded_stack(3)
    scene = Scene(stack, ANGLES)
    wide = scene.segment(AUTO.replace(n_segments=3))
    scene.segment(AUTO.replace(method="valid_superpixels", n_segments=3))
    again = scene.segment(AUTO.replace(n_segments=3))
    assert scene.method_calls == {"surface_superpixels": 1, "valid_superpixels": 1}
    assert len(calls) == 2 and calls[0] != calls[1]
    np.testing.assert_array_equal(again.labels, wide.labels)


def _two_close_and_one_far(gap: float) -> np.ndarray:
    """Three blobs (σ 0.5) in the plane: one at the origin, two at (10, 0) and
    (10, ``gap``)."""
    rng = np.random.default_rng(0)
    centres = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, gap]])
    return np.concatenate([c + rng.normal(0, 0.5, (200, 2)) for c in centres])


def test_k_tolerance_prefers_fewer_clusters_that_score_nearly_as_well():
    # the two close blobs: 3 clusters score a little better than 2 (0.83 against 0.80)
    x = _two_close_and_one_far(4.0)
    best, _, scores = estimate_k(x, None, range(2, 7))
    assert best == 3 and scores[2] > 0.9 * scores[3]
    k, confidence, _ = estimate_k(x, None, range(2, 7), tolerance=surface_superpixels.K_TOLERANCE)
    assert k == 2 and confidence == 0.0  # another k scores better: no confidence
    # well apart, 3 wins whatever the tolerance, with its margin as the confidence
    x = _two_close_and_one_far(8.0)
    k, confidence, scores = estimate_k(x, None, range(2, 7), tolerance=0.1)
    runner_up = max(v for j, v in scores.items() if j != 3)
    assert k == 3 and confidence == pytest.approx((scores[3] - runner_up) / scores[3])
