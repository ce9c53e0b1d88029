"""The scribbles method beyond its memory limit (issue 39): its edge map, superpixels,
nodes and class planes in temporary files, made band by band, and the same values to
the bit as in memory; the memory estimate counts them on disk."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from napari_polarseg.engine import PRESETS, Scene, disk_arrays
from napari_polarseg.engine.classifier import region_walk
from napari_polarseg.engine.classifier.classifier_settings import ClassifierSettings
from napari_polarseg.engine.classifier.pixel_classifier import check_scribbles
from napari_polarseg.engine.classifier.tiled_features import TiledFeatures
from napari_polarseg.engine.features import banded_edges, pixel_features
from napari_polarseg.engine.features.pixel_features import (
    PixelFeatureParams,
    log_intensity_centre,
)
from napari_polarseg.engine.features.superpixels import (
    polarisation_superpixels,
    superpixel_edges,
)
from napari_polarseg.engine.limits import RUNTIME_BYTES
from napari_polarseg.engine.methods.pixel_classification import scribble_session
from napari_polarseg.engine.params import SegmentParams
from napari_polarseg.engine.run_memory import estimate_pipeline_bytes
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes
from napari_polarseg.engine.unsupervised.region_diffusion import border_strength

ANGLES = [0, 45, 90, 135]
#: 24 MP and 100 MP camera frames of 4 angles (N, H, W).
FRAMES = ((4, 4096, 6120), (4, 8160, 12240))


def _maps(shape: tuple[int, int], seed: int = 0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    intensity = ndimage.gaussian_filter(np.exp(rng.normal(size=shape)), 2) + 0.05
    return intensity, rng.random(shape), rng.random(shape) * np.pi


@pytest.mark.parametrize("band", [None, 40 * 7])
def test_the_banded_edge_map_and_superpixels_are_the_whole_images(monkeypatch, band):
    if band is not None:  # bands of 24 rows (the least): many of them
        monkeypatch.setattr(banded_edges, "BAND_PIXELS", band)
    maps = _maps((301, 40))
    whole = superpixel_edges(*maps)
    banded = banded_edges.banded_superpixel_edges(*maps)
    np.testing.assert_array_equal(banded, whole)
    no_polarisation = banded_edges.banded_superpixel_edges(*maps, 0.0)
    np.testing.assert_array_equal(no_polarisation, superpixel_edges(*maps, 0.0))
    for grid in (2, 3, 4):
        regions = banded_edges.banded_superpixels(whole, 150, grid)
        expected = polarisation_superpixels(*maps, 150, edges=whole, grid=grid)
        assert regions.dtype == expected.dtype == np.int32
        np.testing.assert_array_equal(regions, expected)


def test_the_banded_borders_are_the_whole_images(monkeypatch):
    maps = _maps((301, 57), seed=2)
    edges = superpixel_edges(*maps)
    regions = polarisation_superpixels(*maps, 40, edges=edges)
    whole = border_strength(regions, edges, region_walk.EDGE_PAIR)
    for rows in (7, 512):  # many bands, one band
        monkeypatch.setattr(region_walk, "NODE_BAND_ROWS", rows)
        banded = region_walk.banded_border_strength(regions, edges)
        for a, b in zip(whole, banded, strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
    counts = banded_edges.band_counts(regions)
    np.testing.assert_array_equal(counts, np.bincount(regions.ravel()))


def test_the_log_centre_of_an_image_is_its_features(monkeypatch):
    """The centre a tiled run reads off the intensity (only the sampled pixels) is the
    one the whole image's features take: the median of log Î, of every k-th pixel in
    raster order on images above the sample size."""
    rng = np.random.default_rng(5)
    intensity = np.exp(rng.normal(size=(120, 31)) * 3)
    intensity[0, :3] = (np.nan, np.inf, -1.0)
    clean = np.where(np.isfinite(intensity), intensity, 0).astype(np.float32)
    log_i = np.log(np.maximum(clean, pixel_features.EPS_INTENSITY))
    assert log_intensity_centre(intensity) == np.float32(np.median(log_i))
    monkeypatch.setattr(pixel_features, "LOG_CENTRE_SAMPLES", 1000)  # every 4th pixel
    assert pixel_features.centre_sample_step(intensity.size) == 4
    sampled = np.float32(np.median(log_i.ravel()[::4]))
    assert log_intensity_centre(intensity) == sampled != np.float32(np.median(log_i))
    assert pixel_features.log_centre_of_logs(log_i) == sampled
    # so a tile's features centred on it are the whole image's
    maps = (clean, rng.random(clean.shape, dtype=np.float32), rng.random(clean.shape) * 3)
    params = PixelFeatureParams(scales=(1.0,), groups=("intensity", "invariant"))
    whole = pixel_features.pixel_features(*maps, params)
    centred = pixel_features.pixel_features(*maps, params, log_centre=sampled)
    np.testing.assert_array_equal(whole.blocks[0].values, centred.blocks[0].values)


def test_the_exact_median_is_numpys(monkeypatch):
    rng = np.random.default_rng(1)
    values = [
        rng.normal(size=(201, 9)),
        rng.normal(size=(200, 9)),
        np.round(rng.random((64, 7)), 1),
    ]
    monkeypatch.setattr(banded_edges, "GATHER", 5)  # every digit counted
    for v in values:
        assert banded_edges.exact_median(v) == np.median(v)
        for k in (0, 17, v.size // 2, v.size - 1):
            assert banded_edges.kth_smallest(v, k) == np.partition(v.ravel(), k)[k]
    single = rng.normal(size=(99, 4)).astype(np.float32)
    assert banded_edges.exact_median(single) == np.median(single)
    assert banded_edges.exact_median(single).dtype == np.float32
    assert banded_edges.exact_median(np.zeros((30, 30))) == 0.0  # every bit the same
    # the two middle ranks on different top digits (signs), and ranks apart
    split = np.repeat([-1.0, 1.0], 50).reshape(10, 10)
    assert banded_edges.exact_median(split) == np.median(split) == 0.0
    for v in values:
        ks = (0, 17, v.size - 1)
        assert banded_edges.smallest_at(v, ks) == list(np.partition(v.ravel(), ks)[list(ks)])
    values[0][5, 5] = np.nan
    assert np.isnan(banded_edges.exact_median(values[0]))


def test_training_reads_integer_scribbles_without_a_copy():
    strokes = np.zeros((20, 30), dtype=np.int32)
    assert check_scribbles(strokes, convert=False) is strokes
    assert check_scribbles(strokes).dtype == np.int64
    assert check_scribbles(np.zeros((20, 30), np.uint64), convert=False).dtype == np.int64


SHAPE = (240, 300)
#: The work limit of the run below, bytes: its full-size arrays (72 bytes a pixel) over
#: half of it, the whole-image features far above it (tiled).
WORK = 6 * 2**20


def _scribbles_run() -> tuple[Scene, object]:
    synthetic = make_scene("leaves", shape=SHAPE, angles_deg=ANGLES)
    strokes = scribble_strokes(synthetic.labels, seed=0)
    stack = synthetic.stack
    limit = stack.nbytes + stack.size + RUNTIME_BYTES + WORK  # the stack, its flags
    # superpixels of 300 px: the features' regions are drawn on the coarser grid
    settings = ClassifierSettings(features=PixelFeatureParams(region_area=300))
    scene = Scene(stack, np.deg2rad(ANGLES), max_bytes=limit)
    inputs = {"scribbles": strokes, "settings": settings}
    result = scene.segment(SegmentParams(), inputs, maps=False, reconstruction=False)
    return scene, result


def test_a_scribbles_run_beyond_its_limit_works_on_disk_with_the_same_labels(monkeypatch, tmp_path):
    monkeypatch.setenv(disk_arrays.SCRATCH_ENV, str(tmp_path))
    scene, result = _scribbles_run()
    assert scene.work_limit() == WORK
    assert disk_arrays.on_disk_at(SHAPE[0] * SHAPE[1], WORK)
    session = scribble_session(scene)
    segmenter = session.segmenter
    assert isinstance(session.cached_features, TiledFeatures)
    kept = (
        segmenter.edges(),
        segmenter.superpixels(300),  # the features' (coarser grid)
        segmenter.graph().regions,  # the walk's (full grid)
        session.prediction.probabilities,
        session.prediction.labels,
        session.prediction.uncertainty,
        result.labels,
    )
    assert all(disk_arrays.is_on_disk(a) for a in kept)
    disk = [np.array(a) for a in kept]
    del scene, session, segmenter, kept
    # the same limit (the same tiles), every array in memory
    monkeypatch.setattr(disk_arrays, "DISK_SHARE", float("inf"))
    scene, result = _scribbles_run()
    session = scribble_session(scene)
    memory = (
        session.segmenter.edges(),
        session.segmenter.superpixels(300),
        session.segmenter.graph().regions,
        session.prediction.probabilities,
        session.prediction.labels,
        session.prediction.uncertainty,
        result.labels,
    )
    assert not any(disk_arrays.is_on_disk(a) for a in memory)
    for a, b in zip(disk, memory, strict=True):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    assert len(np.unique(result.labels)) >= 2


@pytest.mark.parametrize("frame", FRAMES)
def test_the_scribbles_estimate_counts_the_arrays_on_disk(monkeypatch, frame):
    two = 2 * 2**30
    kinds = {"itemsize": 1, "scribbles": True}
    auto = PRESETS["auto"]
    on_disk = estimate_pipeline_bytes(frame, auto, limit=two, **kinds)
    assert on_disk <= two
    monkeypatch.setattr(disk_arrays, "DISK_SHARE", float("inf"))  # the same run in memory
    assert estimate_pipeline_bytes(frame, auto, limit=two, **kinds) > 2 * on_disk


def test_the_watershed_in_bands_claims_the_pixels_as_one_watershed(monkeypatch):
    from skimage.segmentation import watershed
    from skimage.util import regular_seeds

    from napari_polarseg.engine.features.superpixels import COMPACTNESS

    maps = _maps((600, 300), seed=3)
    edges = banded_edges.block_means(superpixel_edges(*maps), 2)
    seeds = regular_seeds(edges.shape, edges.size // 64, dtype=np.int32)
    whole = watershed(edges, markers=seeds, compactness=2 * COMPACTNESS)
    monkeypatch.setattr(banded_edges, "WATERSHED_BAND_ROWS", 90)  # three bands
    monkeypatch.setattr(banded_edges, "WATERSHED_OVERLAP", 32)
    bands = banded_edges.banded_watershed(edges, seeds, 2 * COMPACTNESS)
    assert bands.dtype == np.int32 and bands.shape == whole.shape
    assert np.mean(bands == whole) > 0.999
