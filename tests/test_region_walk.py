"""The random walk with priors over the superpixel graph (issue 23: one stroke labels its
surface): the walk's identities on small graphs, and what it gives on a real frame and
costs on a border that is no edge."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sps
from scipy import ndimage
from sklearn.metrics import adjusted_rand_score

from napari_polarseg import io as pio
from napari_polarseg.engine import Pipeline, ScribbleSession
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.classifier.region_walk import (
    node_prediction,
    node_seeds,
    region_graph,
    walk,
)
from napari_polarseg.engine.features.superpixels import polarisation_superpixels, superpixel_edges
from napari_polarseg.truth import TRUTH_DIR, read_truth_file, real_frame_path

REAL_DIR = (
    Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "polanalyser"
).resolve()


def path_graph(n: int) -> sps.csr_matrix:
    """Unit weights between node i and i + 1."""
    off = np.ones(n - 1)
    return sps.csr_matrix(sps.diags([off, off], [-1, 1]))


def test_seeded_nodes_keep_their_class_and_rows_sum_to_one():
    rng = np.random.default_rng(0)
    prior = rng.dirichlet(np.ones(3), size=8)
    seeds = np.array([0, -1, -1, 2, -1, -1, -1, 1])
    x = walk(path_graph(8), prior, seeds, 0.1)
    assert np.allclose(x.sum(axis=1), 1)
    assert np.array_equal(x[[0, 3, 7]].argmax(axis=1), [0, 2, 1])
    assert np.allclose(x[[0, 3, 7]].max(axis=1), 1)


def test_without_a_prior_the_walk_is_the_harmonic_interpolation():
    """γ → 0 on a path with seeds at both ends: x_0 falls linearly from 1 to 0 (the
    discrete harmonic function of the path's Laplacian)."""
    n = 11
    seeds = np.full(n, -1)
    seeds[0], seeds[-1] = 0, 1
    x = walk(path_graph(n), np.full((n, 2), 0.5), seeds, 1e-9)
    assert np.allclose(x[:, 0], np.linspace(1, 0, n), atol=1e-6)


def test_a_heavy_prior_returns_the_classifier_and_no_seeds_smooth_it():
    rng = np.random.default_rng(1)
    prior = rng.dirichlet(np.ones(2), size=6)
    none = np.full(6, -1)
    assert np.allclose(walk(path_graph(6), prior, none, 1e6), prior, atol=1e-5)
    smoothed = walk(path_graph(6), prior, none, 0.01)
    # little prior weight: every node near the graph's mean of the prior
    assert np.ptp(smoothed[:, 0]) < 0.25 * np.ptp(prior[:, 0])
    assert np.allclose(smoothed.mean(axis=0), prior.mean(axis=0), atol=0.05)


def test_seeds_are_the_majority_of_a_nodes_scribbles():
    nodes = np.array([[0, 0, 1, 1], [0, 0, 1, 1]])
    scribbles = np.array([[5, 5, 0, 0], [7, 0, 0, 9]])  # 9: no such class, ignored
    seeds = node_seeds(nodes, scribbles, np.array([5, 7]))
    assert seeds.tolist() == [0, -1]


def test_superpixels_split_by_the_classifier_labels_are_separate_nodes():
    rng = np.random.default_rng(2)
    i = 100 + rng.normal(0, 1, (40, 40))
    maps = (i, np.full_like(i, 0.1), np.zeros_like(i))
    edges = superpixel_edges(*maps)
    graph = region_graph(polarisation_superpixels(*maps, 100, edges=edges), edges)
    labels = np.zeros((40, 40), dtype=np.int64)
    labels[:, 20:] = 1
    nodes = graph.nodes(labels, 2)
    # no node holds pixels of both labels, and every superpixel lies in its nodes
    for node in np.unique(nodes):
        assert np.unique(labels[nodes == node]).size == 1
        assert np.unique(graph.regions[nodes == node]).size == 1
    adjacency = graph.adjacency(nodes)
    assert adjacency.shape == (nodes.max() + 1,) * 2
    assert (adjacency - adjacency.T).nnz == 0


def texture_scene():
    """Two fields of 10-px domes that differ only in their shading law (tests/test_cli.py's
    scene): the material border at column 30 is no intensity or polarisation edge."""
    from test_cli import ANGLES, _strokes, two_material_scene

    stack, truth, _ = two_material_scene()
    return stack, np.deg2rad(ANGLES), truth, _strokes()


def test_the_walk_stays_close_to_the_classifier_on_a_border_that_is_no_edge():
    """Measured: ARI 0.913 for the classifier alone, 0.929 with the walk (γ 0.03); with
    region features on intensity-only superpixels they were 0.957 and 0.947. The walk
    finds this border only where the classifier's labels split the superpixels."""
    stack, angles, truth, strokes = texture_scene()
    scores = {}
    for gamma in (0.0, 0.03):
        session = ScribbleSession(
            stack, np.rad2deg(angles), classifier_params=ClassifierParams(region_walk=gamma)
        )
        scores[gamma] = adjusted_rand_score(truth.ravel(), session.update(strokes).ravel())
    assert scores[0.0] > 0.9
    assert scores[0.03] > 0.9
    assert abs(scores[0.03] - scores[0.0]) < 0.03


def deepest_discs(truth: np.ndarray, radius: int) -> np.ndarray:
    """One disc per class at the maximum of its distance transform (the robot user's
    first strokes, benchmarks/robot_user.py)."""
    scribbles = np.zeros(truth.shape, dtype=np.int32)
    yy, xx = np.indices(truth.shape)
    for value in np.unique(truth[truth > 0]):
        depth = ndimage.distance_transform_edt(np.pad(truth == value, 1))[1:-1, 1:-1]
        r, c = np.unravel_index(int(np.argmax(depth)), truth.shape)
        disc = ((yy - r) ** 2 + (xx - c) ** 2 <= radius**2) & (truth == value)
        scribbles[disc] = value
    return scribbles


@pytest.mark.skipif(not REAL_DIR.is_dir(), reason="real frames not found beside the repository")
def test_one_disc_per_material_labels_the_fruits():
    """The real fruits frame (apple, orange, banana on white paper): with one disc per
    material the classifier alone labels by shading (measured ARI 0.29); the walk
    spreads each disc over its fruit (measured 0.69)."""
    truth_file = read_truth_file(TRUTH_DIR / "fruits_IMX250MZR.json")
    data = pio.read_stack(real_frame_path(truth_file, REAL_DIR), mosaic=truth_file.mosaic)
    truth = truth_file.truth
    scribbles = deepest_discs(truth, min(truth.shape) // 80)
    pipe = Pipeline(data.stack, np.asarray(data.angles_rad))
    session = ScribbleSession.on_pipeline(pipe)
    where = truth > 0
    scores = {}
    for gamma in (0.0, 0.03):
        session.classifier_params = ClassifierParams(region_walk=gamma)
        labels = session.update(scribbles)
        scores[gamma] = adjusted_rand_score(truth[where], labels[where])
    assert session.feature_runs == 1
    assert scores[0.03] > 0.6
    assert scores[0.03] > scores[0.0] + 0.2


def test_a_node_without_a_prior_takes_its_neighbours_answer():
    prior = np.array([[1.0, 0.0], [1.0, 0.0], [0.5, 0.5], [0.0, 1.0], [0.0, 1.0]])
    weight = np.array([1.0, 1.0, 0.0, 1.0, 1.0])  # node 2: no grid sample
    x = walk(path_graph(5), prior, np.full(5, -1), weight)
    assert np.allclose(x[2], [0.5, 0.5]) and x[0, 0] > 0.5 and x[4, 1] > 0.5
    lonely = walk(sps.csr_matrix((1, 1)), np.array([[0.2, 0.8]]), np.array([-1]), 0.0)
    assert np.allclose(lonely, [[0.2, 0.8]])  # no neighbours, no prior weight: no 0 pivot


def test_the_preview_shows_nearly_the_final_labels():
    """The preview (the walk over whole superpixels from the 8 px grid) is what the
    plugin shows first; the final labels split the superpixels at the classifier's
    borders."""
    from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes

    scene = make_scene("fruit", shape=(120, 130), angles_deg=[0, 45, 90, 135])
    session = ScribbleSession(scene.stack, [0, 45, 90, 135])
    session.train(scribble_strokes(scene.labels, seed=0))
    preview = session.preview().labels.copy()
    final = session.refine().labels
    assert preview.shape == final.shape and np.mean(preview == final) > 0.9
    assert session.n_predicted > 0


def test_node_prediction_looks_every_band_up():
    """Every pixel takes its node's probabilities, most probable class and margin
    uncertainty, looked up band by band on the cores (1300 rows: several bands)."""
    rng = np.random.default_rng(7)
    x = rng.dirichlet(np.ones(3), size=500)
    nodes = rng.integers(0, 500, (1300, 90)).astype(np.int32)
    classes = np.array([2, 5, 9])
    out = node_prediction(x, nodes, classes, 17)
    np.testing.assert_array_equal(out.probabilities, x.T.astype(np.float32)[:, nodes])
    np.testing.assert_array_equal(out.labels, np.argmax(x, axis=1)[nodes])
    top = np.sort(x, axis=1)
    np.testing.assert_allclose(out.uncertainty, (1 - (top[:, -1] - top[:, -2]))[nodes], rtol=1e-6)
    assert out.n_predicted == 17
