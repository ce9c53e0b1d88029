"""The scribbles method tile by tile (issue 39): the tiled labels equal the whole
image's on a synthetic scene with ground truth, no seams along the tiles' cuts, the
tile size follows the memory limit, training reads the strokes' pixels only."""

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import ScribbleSession
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.classifier.tiled_features import (
    TiledFeatures,
    block_sums,
    region_sums,
)
from napari_polarseg.engine.classifier.tiled_prediction import scribble_tiles
from napari_polarseg.engine.features.pixel_features import PixelFeatureParams
from napari_polarseg.engine.features.superpixels import watershed_grid
from napari_polarseg.engine.limits import (
    KEPT_MAPS,
    estimate_scribble_bytes,
    feature_bytes_per_pixel,
    scribble_bytes_per_pixel,
)
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes

ANGLES = [0, 45, 90, 135]
SHAPE = (360, 420)
#: A limit far below the whole-image estimate of SHAPE: the image is tiled.
SMALL = 40e6


@pytest.fixture(scope="module")
def scene():
    scene = make_scene("leaves", shape=SHAPE, angles_deg=ANGLES)
    return scene, scribble_strokes(scene.labels, seed=0)


def _run(scene, limit, walk=0.03, features=None):
    s = ScribbleSession(
        scene[0].stack,
        ANGLES,
        classifier_params=ClassifierParams(region_walk=walk),
        features_params=features,
    )
    s.segmenter.max_bytes = limit
    labels = s.update(scene[1])
    return s, labels


@pytest.mark.parametrize("walk", [0.03, 0.0])
def test_tiled_labels_equal_whole_image_labels(scene, walk):
    whole, labels = _run(scene, None, walk)
    tiled, tiled_labels = _run(scene, SMALL, walk)
    assert not isinstance(whole.cached_features, TiledFeatures)
    feats = tiled.cached_features
    assert isinstance(feats, TiledFeatures) and len(feats.grid) > 4
    assert feats.names == whole.cached_features.names
    assert adjusted_rand_score(labels.ravel(), tiled_labels.ravel()) >= 0.98
    assert np.mean(labels == tiled_labels) > 0.995
    # both as good against the ground truth
    truth = scene[0].labels.ravel()
    ari = [adjusted_rand_score(truth, x.ravel()) for x in (labels, tiled_labels)]
    assert abs(ari[0] - ari[1]) < 0.01


def test_training_reads_the_strokes_pixels_only(scene):
    whole, _ = _run(scene, None)
    tiled, _ = _run(scene, SMALL)
    index = np.flatnonzero(scene[1].ravel() > 0)[::37]
    rows = tiled.cached_features.take(index)
    np.testing.assert_allclose(rows, whole.cached_features.take(index), rtol=1e-4, atol=1e-5)
    assert tiled.classifier.n_training_pixels == whole.classifier.n_training_pixels


def test_no_more_label_changes_along_tile_cuts(scene):
    tiled, labels = _run(scene, SMALL)
    grid = tiled.cached_features.grid
    change = np.zeros(SHAPE, dtype=bool)
    change[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    change[1:] |= labels[1:] != labels[:-1]
    truth = scene[0].labels
    true_change = np.zeros(SHAPE, dtype=bool)
    true_change[:, 1:] |= truth[:, 1:] != truth[:, :-1]
    true_change[1:] |= truth[1:] != truth[:-1]
    cuts = grid.borders()
    # label changes not explained by a true border: as rare on the cuts as elsewhere
    spurious = change & ~true_change
    on_cuts, elsewhere = spurious[cuts].mean(), spurious[~cuts].mean()
    assert on_cuts <= elsewhere + 0.01


def test_tile_size_follows_the_memory_limit(scene):
    shape, params = (4000, 6000), PixelFeatureParams()
    work, fixed = scribble_bytes_per_pixel(params, tiled=True)
    grids = [scribble_tiles(shape, params, 136, 4, limit=g * 2**30) for g in (6, 12)]
    assert grids[0].core < grids[1].core
    for grid, g in zip(grids, (6, 12), strict=True):
        full = shape[0] * shape[1] * (fixed + 8 * KEPT_MAPS)
        assert full + grid.largest_outer * work <= g * 2**30  # within the limit
    # below the threshold nothing is tiled, above it the image is
    big = 2 * estimate_scribble_bytes(SHAPE)
    s, _ = _run(scene, big)
    assert not isinstance(s.cached_features, TiledFeatures)
    assert scribble_tiles(SHAPE, params, 136, 4, limit=big) is None


def test_memory_estimates_follow_the_features():
    one = feature_bytes_per_pixel(PixelFeatureParams(scales=(1.0,)), threads=1)
    five = feature_bytes_per_pixel(PixelFeatureParams(), threads=1)
    assert 0 < one < five
    assert feature_bytes_per_pixel(PixelFeatureParams(), channels=4) > five
    assert estimate_scribble_bytes((2000, 2000)) == 4 * estimate_scribble_bytes((1000, 1000))


def test_fine_scales_on_the_window_equal_the_whole_box(scene):
    """A tile's features made for its window (the σ ≤ 4 scales on the window grown by
    their reach, the coarser ones cut from the whole box) are the whole box's there,
    to the bit."""
    from napari_polarseg.engine.classifier.tiled_features import box_features

    tiled, _ = _run(scene, SMALL)
    feats = tiled.cached_features
    for tile in list(feats.grid)[:6]:
        window = tile.grown(24, feats.shape)
        inner = feats.fine_box(window, tile.outer)
        assert inner != (slice(0, tile.outer_shape[0]), slice(0, tile.outer_shape[1]))
        whole_box = box_features(*feats.box_inputs(tile.outer))
        made = box_features(*feats.box_inputs(tile.outer, inner))
        assert made.names == whole_box.names and made.shape != whole_box.shape
        r0, c0 = window[0].start - tile.outer[0].start, window[1].start - tile.outer[1].start
        rows, cols = np.mgrid[window[0], window[1]]
        rows, cols = rows.ravel() - tile.outer[0].start, cols.ravel() - tile.outer[1].start
        expected = whole_box.take(rows * tile.outer_shape[1] + cols)
        width = inner[1].stop - inner[1].start
        got = made.take((rows - inner[0].start) * width + cols - inner[1].start)
        assert r0 >= inner[0].start and c0 >= inner[1].start
        np.testing.assert_array_equal(got, expected)


def test_the_watershed_grid_keeps_64_cells_a_region():
    """The coarsest power-of-two grid on which a region spans 64 cells."""
    assert [watershed_grid(a) for a in (64, 255, 256, 417, 1023, 1024, 4096)] == [
        1, 1, 2, 2, 2, 4, 8,
    ]  # fmt: skip


def test_tiled_labels_equal_whole_image_labels_on_the_4x_watershed_grid(scene):
    """Regions of 1024 px (the automatic area from 3.07 MP): superpixels drawn on the 4×
    coarser grid, constant on its 4 × 4 blocks, the region means summed by those
    blocks; tiled and whole image agree and score alike against the truth."""
    features = PixelFeatureParams(region_area=1024)
    whole, labels = _run(scene, None, features=features)
    tiled, tiled_labels = _run(scene, SMALL, features=features)
    feats = tiled.cached_features
    assert isinstance(feats, TiledFeatures) and feats.region_block == 4
    blocks = feats.regions[::4, ::4]
    np.testing.assert_array_equal(np.repeat(np.repeat(blocks, 4, 0), 4, 1), feats.regions)
    assert np.mean(labels == tiled_labels) > 0.995
    truth = scene[0].labels.ravel()
    ari = [adjusted_rand_score(truth, x.ravel()) for x in (labels, tiled_labels)]
    assert abs(ari[0] - ari[1]) < 0.01


def test_region_sums_by_blocks_equal_the_pixels_sums():
    """Superpixels constant on 2 × 2 blocks (the watershed's coarser grid): each
    feature summed block by block first gives the pixels' sums per superpixel (to
    float32 rounding); odd sides fall back to the pixels."""
    a = np.arange(24, dtype=np.float32).reshape(4, 6)
    np.testing.assert_array_equal(block_sums(a, 2), a.reshape(2, 2, 3, 2).sum(axis=(1, 3)))
    rng = np.random.default_rng(2)
    h, w = 64, 80
    coarse = rng.integers(0, 40, (h // 2, w // 2)) * 3  # ids with gaps
    core = np.repeat(np.repeat(coarse, 2, axis=0), 2, axis=1)
    maps = [(rng.random((h, w)) + 0.5, rng.random((h, w)) * 0.3, rng.random((h, w)) * 3)]
    params = PixelFeatureParams(scales=(1.0, 2.0), groups=("intensity", "polarisation"))
    inner = (slice(0, h), slice(0, w))
    ids1, (sums1,) = region_sums(maps, inner, core, params, [0.0], 1)
    ids2, (sums2,) = region_sums(maps, inner, core, params, [0.0], 2)
    np.testing.assert_array_equal(ids1, np.unique(core))
    np.testing.assert_array_equal(ids1, ids2)
    np.testing.assert_allclose(sums2, sums1, rtol=1e-5, atol=1e-4)
    odd = ([tuple(m[: h - 1] for m in maps[0])], (slice(0, h - 1), slice(0, w)), core[: h - 1])
    ids3, (sums3,) = region_sums(*odd, params, [0.0], 2)
    ids4, (sums4,) = region_sums(*odd, params, [0.0], 1)
    np.testing.assert_array_equal(ids3, np.unique(core[: h - 1]))
    np.testing.assert_array_equal(ids3, ids4)
    np.testing.assert_array_equal(sums3, sums4)  # the pixels' own sums
