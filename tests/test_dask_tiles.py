"""A large image's tiles on a Dask cluster (issue 39, point 3): the default method's tiled
labels from a 2-worker local cluster equal the single-process tiled labels exactly; the
tile map keeps the tiles' order and bounds what is in flight; ``polarseg segment --dask``
runs the tiles on the cluster.

The cluster: a ``LocalCluster`` of 2 single-threaded worker *processes* (the tiles'
arrays are pickled to them and the results back), started once for the module.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile

from napari_polarseg import cli
from napari_polarseg.batch.cluster import open_cluster, parse_scheduler
from napari_polarseg.engine import PRESETS, PolarsegError, Scene
from napari_polarseg.engine.limits import KEPT_MAPS
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.engine.tile_map import DEFAULT_MAP, DaskTileMap, current_tile_map, tiles_on
from napari_polarseg.engine.tiles import TileGrid
from napari_polarseg.engine.unsupervised.merge import merged_clustering, weakest_border
from napari_polarseg.engine.unsupervised.tiled_regions import (
    MAX_CORE,
    TILE_BYTES_PER_PIXEL,
    WHOLE_BYTES_PER_PIXEL,
    region_tiles,
    tile_halo,
    tiled_prepare_regions,
)

SHAPE = (480, 600)
CORE = 200


@pytest.fixture
def forced_tiles(monkeypatch):
    """The default method tiles any image into cores of at most 256 px, whatever the
    memory limit (its whole-image estimate made huge), so that a small scene is cut into
    six tiles and the pipeline's own memory check still passes."""
    from napari_polarseg.engine.unsupervised import tiled_regions

    monkeypatch.setattr(tiled_regions, "WHOLE_BYTES_PER_PIXEL", 10**6)
    monkeypatch.setattr(tiled_regions, "MAX_CORE", 256)


@pytest.fixture(scope="module")
def cluster():
    found = open_cluster(None, 2, "1GiB", timeout=60)
    yield found
    found.close()


@pytest.fixture(scope="module")
def scene():
    return make_scene("scattered_leaves", shape=SHAPE, seed=4)


@pytest.fixture(scope="module")
def pol(scene):
    return Scene(scene.stack, scene.angles).polarisation(PRESETS["auto"])


def _tiled_labels(pol, valid) -> tuple[np.ndarray, object]:
    params = SurfaceSuperpixels().params
    grid = TileGrid(SHAPE, CORE, tile_halo(SHAPE, params))
    maps = (pol.intensity, pol.dop, pol.phase)
    model = tiled_prepare_regions(*maps, params, valid, grid)
    return merged_clustering(model, 3, merge=weakest_border).labels, model


def _hole() -> np.ndarray:
    valid = np.ones(SHAPE, dtype=bool)
    valid[100:180, 150:330] = False  # across a cut, as a saturated patch
    return valid


@pytest.mark.parametrize("valid", [None, "hole"])
def test_cluster_labels_equal_single_process(cluster, pol, valid):
    valid = _hole() if valid == "hole" else None
    here, model_here = _tiled_labels(pol, valid)
    tile_map = DaskTileMap(cluster.client)
    with tiles_on(tile_map):
        there, model_there = _tiled_labels(pol, valid)
    # every tile of the three passes (histograms, superpixels, labels) ran on the cluster
    assert tile_map.tasks == 3 * 9
    assert current_tile_map() is DEFAULT_MAP
    assert np.array_equal(model_here.regions, model_there.regions)
    assert np.array_equal(model_here.z, model_there.z)
    assert len(np.unique(here)) == 3
    assert np.array_equal(here, there)


def _square(x: np.ndarray, offset: int) -> tuple[int, float]:
    return offset, float((x.astype(np.float64) ** 2).sum())


def test_tile_map_order_and_window(cluster):
    tile_map = DaskTileMap(cluster.client, window=2)
    assert tile_map.window == 2 and tile_map.threads == 2
    assert tile_map.worker_bytes == pytest.approx(0.8 * 2**30)
    arrays = [np.full((600, 600), i, dtype=np.float32) for i in range(7)]  # 1.4 MB: scattered
    made: list[int] = []

    def payloads():
        for i, a in enumerate(arrays):
            made.append(i)
            yield a, i

    results = tile_map(_square, payloads())
    first = next(results)
    assert made == [0, 1, 2]  # the window, then one more as the first result is taken
    assert first == (0, 0.0)
    rest = list(results)
    assert [r[0] for r in rest] == list(range(1, 7))
    assert [r[1] for r in rest] == [float(i * i * 600 * 600) for i in range(1, 7)]


def test_worker_memory_bounds_the_tiles():
    shape, params = (8000, 8000), SurfaceSuperpixels().params
    limit = 64e6 * (WHOLE_BYTES_PER_PIXEL + 8 * KEPT_MAPS) - 1  # just tiled: the largest tiles
    alone = region_tiles(shape, params, limit)

    class Small:
        worker_bytes = 400e6

    with tiles_on(Small()):
        bounded = region_tiles(shape, params, limit)
    assert alone is not None and bounded is not None
    outer = (bounded.core + 2 * bounded.halo) ** 2
    assert alone.core == MAX_CORE
    assert bounded.core < alone.core and outer * TILE_BYTES_PER_PIXEL <= 400e6


def test_scene_on_cluster_equals_single_process(cluster, scene, forced_tiles):
    s = scene
    here = Scene(s.stack, s.angles).segment(PRESETS["auto"], maps=False, reconstruction=False)
    tile_map = DaskTileMap(cluster.client)
    with tiles_on(tile_map):
        there = Scene(s.stack, s.angles).segment(PRESETS["auto"], maps=False, reconstruction=False)
    assert tile_map.tasks == 3 * 6  # 2 × 3 tiles of at most 256 px
    assert np.array_equal(here.labels, there.labels)


def test_parse_scheduler():
    assert parse_scheduler("local") == (None, None)
    assert parse_scheduler("local:2") == (None, 2)
    assert parse_scheduler("tcp://10.0.0.5:8786") == ("tcp://10.0.0.5:8786", None)
    with pytest.raises(PolarsegError):
        parse_scheduler("local:0")


def test_cli_segment_dask(tmp_path: Path, scene, forced_tiles, capsys):
    s = scene
    stack = tmp_path / "scene.npz"
    np.savez(stack, stack=s.stack, angles=s.angles_deg)
    assert cli.main(["segment", str(stack), "--out", str(tmp_path / "here"), "--quiet"]) == 0
    flags = ["--dask", "local:2", "--memory-limit", "1GiB"]
    assert cli.main(["segment", str(stack), "--out", str(tmp_path / "there"), *flags]) == 0
    err = capsys.readouterr().err
    assert "tiles on local cluster (2 worker process(es)" in err
    assert "ran whole" not in err
    here, there = (tifffile.imread(tmp_path / d / "labels.tif") for d in ("here", "there"))
    assert np.array_equal(here, there)


def test_cli_segment_dask_scribbles(tmp_path: Path, capsys, monkeypatch):
    """``polarseg segment --scribbles --dask`` runs the scribbles method's tiles on the
    cluster (no line that the image ran whole) and writes the labels of the same tiles
    in one process."""
    from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter

    monkeypatch.setattr(PixelSegmenter, "work_limit", lambda self: int(40e6))  # tiled
    s = make_scene("leaves", shape=(360, 420), seed=1)
    stack = tmp_path / "scene.npz"
    np.savez(stack, stack=s.stack, angles=s.angles_deg)
    strokes = np.zeros(s.labels.shape, dtype=np.uint8)
    for c in range(int(s.labels.max()) + 1):
        rows, cols = np.nonzero(s.labels == c)
        strokes[rows[::40], cols[::40]] = c + 1
    tifffile.imwrite(tmp_path / "strokes.tif", strokes)
    args = ["segment", str(stack), "--scribbles", str(tmp_path / "strokes.tif"), "--quiet"]
    assert cli.main([*args, "--out", str(tmp_path / "here")]) == 0
    flags = ["--dask", "local:2", "--memory-limit", "1GiB"]
    assert cli.main([*args[:-1], *flags, "--out", str(tmp_path / "there")]) == 0
    err = capsys.readouterr().err
    assert "tiles on local cluster (2 worker process(es)" in err
    assert "ran whole" not in err
    here, there = (tifffile.imread(tmp_path / d / "labels.tif") for d in ("here", "there"))
    assert np.array_equal(here, there)


@pytest.mark.parametrize("walk", [0.0, 0.03])
def test_scribbles_tiles_on_cluster_equal_single_process(cluster, walk):
    """The scribbles method's tiles (features, prediction coarse to fine, the walk's
    sums) on the cluster give the labels, probabilities and uncertainty of the same
    tiles in this process, to the bit, and every tile ran there."""
    from napari_polarseg.engine import ScribbleSession
    from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
    from napari_polarseg.engine.synthetic.scenes import scribble_strokes

    angles = [0, 45, 90, 135]
    s = make_scene("leaves", shape=(360, 420), angles_deg=angles)
    strokes = scribble_strokes(s.labels, seed=0)

    def run(tile_map):
        session = ScribbleSession(
            s.stack, angles, classifier_params=ClassifierParams(region_walk=walk)
        )
        session.segmenter.max_bytes = 40e6  # tiled: far below the whole-image estimate
        with tiles_on(tile_map):
            session.update(strokes)
        return session.prediction

    here = run(None)
    tile_map = DaskTileMap(cluster.client)
    there = run(tile_map)
    assert tile_map.tasks > 1
    np.testing.assert_array_equal(here.labels, there.labels)
    np.testing.assert_array_equal(here.probabilities, there.probabilities)
    np.testing.assert_array_equal(here.uncertainty, there.uncertainty)
