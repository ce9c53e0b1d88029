"""Superpixels clustered on the valid pixels (``valid_superpixels``, the base of the
default ``surface_superpixels``), and the number of materials found by itself
(``n_segments = 0``, :func:`estimate_k`)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import PolarsegError, Scene, SegmentParams
from napari_polarseg.engine.methods import valid_superpixels
from napari_polarseg.engine.params import AUTO as DEFAULT
from napari_polarseg.engine.unsupervised.choose_k import choice_text, estimate_k

ANGLES = np.deg2rad([0.0, 45.0, 90.0, 135.0])
LEVEL = (1.0, 0.55, 1.5, 0.8)
RHO = (0.03, 0.12, 0.25, 0.4)


def banded_stack(k: int, shape=(96, 128), seed: int = 0):
    """(stack (4, H, W) uint16, truth): k vertical bands of materials that differ in
    intensity level and ρ under one smooth shading, 1 % intensity and 5 % ρ noise."""
    rng = np.random.default_rng(seed)
    h, w = shape
    rows, cols = np.mgrid[0:h, 0:w]
    truth = np.minimum(cols * k // w, k - 1)
    shading = 0.6 + 0.3 * np.sin(rows / h * np.pi)
    intensity = shading * np.asarray(LEVEL)[truth] * (1 + 0.01 * rng.standard_normal(shape))
    dop = np.asarray(RHO)[truth] * (1 + 0.05 * rng.standard_normal(shape))
    phase = np.arctan2(rows - h / 2, cols - w / 2) % np.pi
    stack = 0.5 * intensity * (1 + dop * np.cos(2 * ANGLES[:, None, None] - 2 * phase))
    return np.round(stack * 2000).astype(np.uint16), truth


#: The default preset with this method.
AUTO = DEFAULT.replace(method=valid_superpixels.ValidSuperpixels.name)


def test_auto_preset_method_builds_on_this_one():
    from napari_polarseg.engine.methods.registry import get_method

    assert isinstance(get_method(DEFAULT.method), valid_superpixels.ValidSuperpixels)


@pytest.mark.parametrize("k", [2, 3, 4])
def test_planted_materials_recovered_with_k_given_and_found(k):
    stack, truth = banded_stack(k)
    scene = Scene(stack, ANGLES)
    given = scene.segment(AUTO.replace(n_segments=k))
    # k + 1 clustered then merged: a few superpixels on a band border may go astray
    assert adjusted_rand_score(truth.ravel(), given.labels.ravel()) > 0.95
    found = scene.segment(AUTO.replace(n_segments=0))
    record = found.method_record
    assert record["k_found"] is True and record["k"] == k
    assert 0.0 < record["k_confidence"] <= 1.0
    assert set(record["k_scores"]) == {"2", "3", "4", "5", "6"}
    np.testing.assert_array_equal(found.labels, given.labels)
    assert given.method_record["k_found"] is False and given.method_record["k"] == k
    # said in words: the k chosen, the range, its silhouette and the runner-up's
    text = choice_text(record)
    assert text.startswith(f"{k} segments found by itself (k in 2–6, by the silhouette")
    assert f"{record['k_scores'][str(k)]:.2f}" in text
    assert choice_text(given.method_record) == ""


def test_plugin_status_line_says_the_k_found():
    """The Segment widget's status line (made without Qt) leads with the k found and
    its silhouettes instead of the bare count."""
    from napari_polarseg.widgets.session.results import shown_result

    stack, _ = banded_stack(3)
    found = Scene(stack, ANGLES).segment(AUTO.replace(n_segments=0))
    status = shown_result(found, np.rad2deg(ANGLES)).status(0.5)
    assert status.startswith(choice_text(found.method_record) + " · ")
    given = Scene(stack, ANGLES).segment(AUTO.replace(n_segments=3))
    assert shown_result(given, np.rad2deg(ANGLES)).status(0.5).startswith("3 segments · ")


def test_choice_text_says_how_sure():
    """Clearly ahead, a close call, and a k chosen by the tolerance over a better one."""
    record = {"k_found": True, "k": 3, "k_scores": {"2": 0.40, "3": 0.80, "4": 0.50}}
    assert choice_text(record) == (
        "3 segments found by itself (k in 2–4, by the silhouette 0.80; next k = 4 at "
        "0.50, 38% ahead)"
    )
    record["k_scores"]["4"] = 0.79
    assert choice_text(record).endswith("next k = 4 at 0.79, a close call)")
    record.update(k=2, k_scores={"2": 0.70, "3": 0.75}, k_tolerance=0.1)
    assert choice_text(record) == (
        "2 segments found by itself (k in 2–3, by the silhouette: the fewest within 10% "
        "of the best, 0.70 against 0.75 for k = 3; a close call)"
    )


@pytest.mark.parametrize("k", [2, 3, 4])
def test_estimate_k_finds_planted_clusters(k):
    rng = np.random.default_rng(k)
    centres = 8.0 * np.eye(k, 4)
    x = np.concatenate([c + rng.normal(0, 1, (150, 4)) for c in centres])
    weights = rng.uniform(50, 150, x.shape[0])
    found, confidence, scores = estimate_k(x, weights, range(2, 7))
    assert found == k and 0 < confidence <= 1
    assert max(scores, key=scores.get) == k and set(scores) == {2, 3, 4, 5, 6}


def test_estimate_k_with_too_few_nodes_says_one():
    assert estimate_k(np.zeros((2, 3)), None, range(2, 7)) == (1, 0.0, {})


def test_saturated_pixels_take_no_segment_of_their_own():
    """A saturated patch inside one material: the superpixel method gives it a segment,
    this one labels it from the nearest valid pixels and finds the two materials."""
    stack, truth = banded_stack(2)
    stack[:, 20:80, 5:55] = np.iinfo(np.uint16).max
    params = AUTO.replace(n_segments=2)
    labels = Scene(stack, ANGLES).segment(params).labels
    assert adjusted_rand_score(truth.ravel(), labels.ravel()) > 0.95
    old = Scene(stack, ANGLES).segment(params.replace(method="superpixels")).labels
    assert adjusted_rand_score(truth.ravel(), old.ravel()) < 0.9


def test_reruns_only_for_what_it_reads(monkeypatch):
    calls = []
    prepare = valid_superpixels.prepare_regions

    def counted(*args, **kwargs):
        calls.append(1)
        return prepare(*args, **kwargs)

    monkeypatch.setattr(valid_superpixels, "prepare_regions", counted)
    stack, _ = banded_stack(3)
    scene = Scene(stack, ANGLES)
    first = scene.segment(AUTO.replace(n_segments=3))
    for change in ({"scale": 5.0}, {"window": 8}, {"refractive_index": 1.7}):
        again = scene.segment(AUTO.replace(n_segments=3, **change))
        np.testing.assert_array_equal(again.labels, first.labels)
    assert scene.method_calls == {"valid_superpixels": 1} and len(calls) == 1
    scene.segment(AUTO.replace(n_segments=0))
    scene.segment(AUTO.replace(n_segments=4))
    assert scene.method_calls == {"valid_superpixels": 3}
    assert len(calls) == 1  # another k reclusters the kept superpixels


def test_zero_segments_only_for_a_method_that_finds_k():
    AUTO.replace(n_segments=0).validate()
    for method in ("thesis", "superpixels"):
        with pytest.raises(PolarsegError, match="not offered"):
            SegmentParams(method=method, n_segments=0).validate()


def test_merge_closest_joins_the_nearest_centroids_by_area():
    from napari_polarseg.engine.unsupervised.merge import merge_closest

    z = np.array([[0.0], [0.2], [5.0], [5.1], [9.0]])
    weight = np.array([1.0, 3.0, 1.0, 1.0, 1.0])
    nodes = np.array([0, 1, 2, 2, 3])  # segment 0 ≈ 1, 2 between them and 3
    np.testing.assert_array_equal(merge_closest(z, weight, nodes, 3), [0, 0, 2, 3])
    np.testing.assert_array_equal(merge_closest(z, weight, nodes, 2), [0, 0, 2, 2])


def test_merge_undone_when_it_would_leave_one_segment_with_nearly_everything():
    """Two large materials of equal ρ (intensity 1.0 and 0.6) and a small patch (6 % of
    the pixels) of another ρ: k + 1 = 3 clusters are the three, and the closest pair
    is the two large materials, so merging would leave one segment with 94 % of the
    pixels; the merge is undone and k = 2 made directly split the two materials."""
    from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
    from napari_polarseg.engine.unsupervised.merge import (
        GUARD_SHARE,
        largest_share,
        merge_closest,
        merged_clustering,
    )
    from napari_polarseg.engine.unsupervised.segmenter import cluster_regions, prepare_regions

    rng = np.random.default_rng(0)
    h, w = 96, 128
    rows, cols = np.mgrid[0:h, 0:w]
    truth = (cols >= 0.6 * w).astype(int)
    patch = (np.abs(rows - 24) < 14) & (np.abs(cols - 24) < 14)
    level = np.where(patch, 0.8, np.where(truth == 0, 1.0, 0.6))
    rho = np.where(patch, 0.12, 0.05)
    intensity = (0.6 + 0.3 * np.sin(rows / h * np.pi)) * level
    intensity *= 1 + 0.01 * rng.standard_normal((h, w))
    dop = rho * (1 + 0.05 * rng.standard_normal((h, w)))
    model = prepare_regions(intensity, dop, np.zeros((h, w)), SurfaceSuperpixels().params)
    three = cluster_regions(model, 3).node_labels
    merged = merge_closest(model.z, model.weight, three, 2)[three]
    assert largest_share(merged, model.weight) >= GUARD_SHARE  # what the guard is for
    labels = merged_clustering(model, 2).labels
    assert np.bincount(labels.ravel()).max() / labels.size < GUARD_SHARE
    assert adjusted_rand_score(truth[~patch], labels[~patch]) > 0.9


def test_weakest_border_merges_across_the_faint_border_not_the_nearest_centroids():
    """Three segments of one superpixel each: 0 and 1 meet along a long border with no
    edge (mean weight 0.9, one surface cut along its shading), 1 and 2 along an edge
    (mean 0.1) though their features are the closest; a short border 0–2 (0.1). Far
    apart in features (a bruise on its fruit), a faint border is not enough. Each node
    stands for a region of many superpixels: the diagonal is the border inside it."""
    from types import SimpleNamespace

    import scipy.sparse as sps

    from napari_polarseg.engine.unsupervised.merge import closest_centroids, weakest_border

    lengths = sps.csr_matrix(np.array([[100, 10, 2], [10, 100, 10], [2, 10, 100]], float))
    weights = sps.csr_matrix(np.array([[0, 9, 0.2], [9, 0, 1], [0.2, 1, 0]], float))
    z = np.array([[0.0], [0.6], [0.9]])  # whitened: within one standard deviation
    model = SimpleNamespace(z=z, weight=np.ones(3), adjacency=lengths, borders=weights)
    nodes = np.arange(3)
    np.testing.assert_array_equal(weakest_border(model, nodes, 2), [0, 0, 2])
    np.testing.assert_array_equal(closest_centroids(model, nodes, 2), [0, 1, 1])
    np.testing.assert_array_equal(weakest_border(model, nodes, 1), [0, 0, 0])
    # 0 three standard deviations away: (0.9 / 10) < (0.1 / 1.09), the edge is crossed
    far = SimpleNamespace(
        z=np.array([[-3.0], [0.0], [0.1]]), weight=np.ones(3), adjacency=lengths, borders=weights
    )
    np.testing.assert_array_equal(weakest_border(far, nodes, 2), [0, 1, 1])
    # segments that share no border: the closest centroids decide
    none = sps.csr_matrix((3, 3))
    apart = SimpleNamespace(z=z, weight=np.ones(3), adjacency=none, borders=none)
    np.testing.assert_array_equal(weakest_border(apart, nodes, 2), [0, 1, 1])
    # segments of several superpixels: their borders are summed; segment 0 = superpixels
    # 0 and 1, 1 = 2, 2 = 3: 0–1 weight 5 over length 6, 0–2 1 over 12, 1–2 1 over 10
    many = SimpleNamespace(
        z=np.array([[0.0], [0.0], [0.5], [0.8]]),
        weight=np.ones(4),
        adjacency=sps.csr_matrix(
            np.array([[0, 4, 6, 0], [4, 0, 0, 12], [6, 0, 0, 10], [0, 12, 10, 0]], float)
        ),
        borders=sps.csr_matrix(
            np.array([[0, 4, 5, 0], [4, 0, 0, 1], [5, 0, 0, 1], [0, 1, 1, 0]], float)
        ),
    )
    np.testing.assert_array_equal(weakest_border(many, np.array([0, 0, 1, 2]), 2), [0, 0, 2])


def test_weakest_border_merges_a_scatter_of_superpixels_first():
    """Two sheets (segments 0 and 1, cohesive) and a scatter of superpixels straddling
    their edges (segment 2: superpixels 2 and 3 apart, all their border with the sheets),
    every border an edge. The sheets' border is the least strong of the edges, so
    without the cohesion rule they would be joined; the scatter goes to a sheet instead.
    Once the scatter is cohesive (its superpixels share most of their border), the
    weakest border decides again."""
    from types import SimpleNamespace

    import scipy.sparse as sps

    from napari_polarseg.engine.unsupervised.merge import (
        COHESION_FLOOR,
        cohesion,
        weakest_border,
    )

    def model(inside: float) -> SimpleNamespace:
        lengths = np.array(
            [[200, 40, 10, 10], [40, 200, 10, 10], [10, 10, 0, inside], [10, 10, inside, 0]],
            float,
        )
        weights = 1e-3 * lengths  # every border an edge
        weights[0, 1] = weights[1, 0] = 4e-3 * 40  # the sheets' edge the least strong
        return SimpleNamespace(
            z=np.array([[0.0], [3.0], [1.6], [1.6]]),
            weight=np.array([1000.0, 1000.0, 20.0, 20.0]),
            adjacency=sps.csr_matrix(lengths),
            borders=sps.csr_matrix(weights),
        )

    nodes = np.array([0, 1, 2, 2])
    member = np.eye(3)[nodes]
    summed = member.T @ model(0.0).adjacency.toarray() @ member
    assert cohesion(summed)[2] == 0.0 and cohesion(summed)[0] > COHESION_FLOOR
    assert weakest_border(model(0.0), nodes, 2)[2] in (0, 1)  # the scatter joins a sheet
    np.testing.assert_array_equal(weakest_border(model(100.0), nodes, 2), [0, 0, 2])


def test_extra_segments_is_the_clusters_merged_away(monkeypatch):
    """``extra_segments`` clusters beyond k are clustered, then merged away: the method
    hands its own to the merge; with 0 the labels are the k clusters themselves, and
    k + 1 (the default) and k + 2 still find the planted bands."""
    from napari_polarseg.engine.unsupervised.segmenter import cluster_regions, prepare_regions

    stack, truth = banded_stack(3)
    pol = Scene(stack, ANGLES).pipeline.get("polarisation")
    method = valid_superpixels.ValidSuperpixels()
    models = [prepare_regions(pol.intensity, pol.dop, pol.phase, method.params)]
    direct = cluster_regions(models[0], 3)
    asked = []
    merged = valid_superpixels.merged_clustering

    def spy(model, k, extra, merge):
        asked.append(extra)
        return merged(model, k, extra, merge)

    monkeypatch.setattr(valid_superpixels, "merged_clustering", spy)
    assert method.extra_segments == 1
    for extra in (0, 1, 2):
        method.extra_segments = extra
        result = method.labels(models, 3)
        assert len(np.unique(result.labels)) == 3
        assert adjusted_rand_score(truth.ravel(), result.labels.ravel()) > 0.95
        if extra == 0:
            np.testing.assert_array_equal(result.node_labels, direct.node_labels)
    assert asked == [0, 1, 2]
