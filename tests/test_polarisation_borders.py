"""``polarisation_borders``: the default's method with its borders weighed on the Stokes
edges alone keeps two plastics apart under a deep cast shadow, its border map is the
Stokes edge map, tile by tile as on the whole image, and the weight is checked."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import PRESETS, Scene
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features.superpixels import (
    border_channels,
    edge_gradients,
    edge_terms,
    superpixel_edges,
)
from napari_polarseg.engine.methods import get_method
from napari_polarseg.engine.methods.registry import BUILT_IN
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.engine.tiles import TileGrid
from napari_polarseg.engine.unsupervised.merge import merged_clustering, weakest_border
from napari_polarseg.engine.unsupervised.params import UnsupervisedParams
from napari_polarseg.engine.unsupervised.region_diffusion import gated_strength
from napari_polarseg.engine.unsupervised.segmenter import prepare_regions
from napari_polarseg.engine.unsupervised.tiled_regions import tile_halo, tiled_prepare_regions

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import cast_shadow  # noqa: E402


def test_registered_once_with_the_default_but_its_borders():
    assert [m for m, _ in BUILT_IN].count("polarisation_borders") == 1
    method = get_method("polarisation_borders")
    assert method.params == SurfaceSuperpixels().params.replace(border_intensity_weight=0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_deep_cast_shadow_is_not_a_material(seed):
    """The planted plastics (ρ 0.08 and 0.25) under bands of shadow that leave 30 % of
    the light: measured ARI 0.999–1.000 with the materials, 0.000–0.010 with the
    shadow (the default: 0.000–0.010 with the materials)."""
    name, stack, truth, shadow = next(
        (n, s, t, sh) for n, f, s, t, sh in cast_shadow.scenes([0.3]) if n == f"planted-{seed}"
    )
    scene = Scene(stack, cast_shadow.ANGLES)
    labels = scene.segment(PRESETS["auto"].replace(n_segments=2, method="polarisation_borders"))
    assert adjusted_rand_score(truth.ravel(), labels.labels.ravel()) > 0.95, name
    assert adjusted_rand_score(shadow.ravel(), labels.labels.ravel()) < 0.05, name


def test_the_border_map_is_the_stokes_edge_map_at_weight_zero():
    sc = make_scene("leaves", shape=(96, 120), seed=0)
    pol = Scene(sc.stack, sc.angles).polarisation(PRESETS["auto"])
    maps = (pol.intensity, pol.dop, pol.phase)
    log_i, stokes = edge_gradients(*maps, True)
    terms = edge_terms(maps, 0.5)
    # each term is its gradient over the gradient's median, the Stokes one weighed w
    np.testing.assert_allclose(terms[0], log_i / np.median(log_i), rtol=1e-12)
    np.testing.assert_allclose(terms[1], 0.5 * stokes / np.median(stokes), rtol=1e-12)
    # the watershed's map is exactly their sum, the one computation serving both
    np.testing.assert_array_equal(terms.sum(axis=0), superpixel_edges(*maps, 0.5))
    assert edge_terms(maps, 0.0).shape == (1, *log_i.shape)
    zero = border_channels(edge_terms(maps, 1.0), 0.0)
    np.testing.assert_allclose(zero[1], stokes / np.median(stokes), rtol=1e-6)
    assert not zero[0].any()
    both = superpixel_edges(*maps, 1.0)
    np.testing.assert_allclose(border_channels(edge_terms(maps), 1.0).sum(axis=0), both, rtol=1e-5)
    half = border_channels(edge_terms(maps), 0.5).sum(axis=0)
    # log Î alone (w = 0): the Stokes channel is zero
    assert not border_channels(edge_terms(maps, 0.0), 1.0)[1].any()
    assert np.all(half <= both + 1e-5) and np.any(half < both - 1e-3)


def test_tiled_borders_agree_with_the_whole_image():
    shape, core = (480, 600), 200
    s = make_scene("scattered_leaves", shape=shape, seed=5)
    pol = Scene(s.stack, s.angles).polarisation(PRESETS["auto"])
    params = get_method("polarisation_borders").params
    grid = TileGrid(shape, core, tile_halo(shape, params))
    maps = (pol.intensity, pol.dop, pol.phase)
    whole = prepare_regions(*maps, params)
    tiled = tiled_prepare_regions(*maps, params, None, grid)
    assert len(grid) == 9 and tiled.n == whole.n
    # the borders are the whole image's but near the cuts, and so are the features
    w, t = whole.borders.toarray(), tiled.borders.toarray()
    assert np.median(np.abs(t - w)[w > 0] / w[w > 0]) < 0.01
    assert np.median(np.abs(tiled.z - whole.z), axis=0).max() < 0.01 * whole.z.std(axis=0).min()
    a = merged_clustering(whole, 3, merge=weakest_border).labels
    b = merged_clustering(tiled, 3, merge=weakest_border).labels
    assert adjusted_rand_score(a.ravel(), b.ravel()) >= 0.98


@pytest.mark.parametrize(
    "change",
    [
        {"border_intensity_weight": -0.1},
        {"border_intensity_weight": 1.5},
        {"border_intensity_weight": float("nan")},
        {"border_intensity_weight": 0.0, "boundary": "intensity"},
    ],
)
def test_the_weight_is_checked(change):
    with pytest.raises(PolarsegError, match="border_intensity_weight"):
        UnsupervisedParams(**change)


def test_the_default_gates_its_intensity_borders_and_crosses_a_shadow():
    """The default's border gate (``border_gate`` 0.5): on the planted plastics under a
    shadow of 70 % of the light it keeps them apart (measured 0.999 on seeds 0–2; 0.720
    without the gate), as ``polarisation_borders`` does."""
    gated = SurfaceSuperpixels().params
    assert gated.border_gate > 0.0 and gated.border_intensity_weight == 1.0
    scores = []
    for name, _, stack, truth, _ in cast_shadow.scenes([0.7]):
        if name.startswith("planted"):
            scene = Scene(stack, cast_shadow.ANGLES)
            labels = scene.segment(PRESETS["auto"].replace(n_segments=2)).labels
            scores.append(adjusted_rand_score(truth.ravel(), labels.ravel()))
    assert min(scores) > 0.95


def test_the_gate_weighs_intensity_edges_by_the_polarisation_step():
    """e = p + c · i, c = 1 − exp(−(Δz / (K · median Δz))²): no polarisation step, no
    intensity border; a step of several medians, the whole intensity edge."""
    strength = np.array([[4.0, 1.0], [4.0, 1.0], [4.0, 1.0]])
    dz = np.array([0.0, 0.1, 1.0])  # median 0.1, K = 0.5: t = 0.05
    e = gated_strength(strength, dz, 0.5)
    np.testing.assert_allclose(e, [1.0, 1.0 + 4.0 * (1 - np.exp(-4.0)), 5.0])


def test_tiled_gated_borders_agree_with_the_whole_image():
    shape, core = (480, 600), 200
    s = make_scene("scattered_leaves", shape=shape, seed=5)
    pol = Scene(s.stack, s.angles).polarisation(PRESETS["auto"])
    params = SurfaceSuperpixels().params
    grid = TileGrid(shape, core, tile_halo(shape, params))
    maps = (pol.intensity, pol.dop, pol.phase)
    whole = prepare_regions(*maps, params)
    tiled = tiled_prepare_regions(*maps, params, None, grid)
    w, t = whole.borders.toarray(), tiled.borders.toarray()
    assert np.median(np.abs(t - w)[w > 0] / w[w > 0]) < 0.01
    ungated = prepare_regions(*maps, params.replace(border_gate=0.0)).borders.toarray()
    assert np.median(np.abs(ungated - w)[w > 0] / w[w > 0]) > 0.05  # the gate moves them
