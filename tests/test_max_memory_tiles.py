"""``--max-memory`` reaches the methods' tile decision, and the memory check counts the
tiles: a run that tiles to fit is not refused (issue 39)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from napari_polarseg import cli
from napari_polarseg._sample_data import SAMPLE_DIR
from napari_polarseg.engine import PRESETS, Scene
from napari_polarseg.engine.classifier import pixel_segmentation
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.limits import (
    DEFAULT_MAX_BYTES,
    RUNTIME_BYTES,
)
from napari_polarseg.engine.methods import valid_superpixels
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.run_memory import check_pipeline_memory, estimate_pipeline_bytes
from napari_polarseg.engine.unsupervised.tiled_regions import region_tiles

AUTO = PRESETS["auto"]
#: (N, H, W) of the sizes of issue 39: 1.25, 5, 24 and just under 100 MP, 4 angles
SIZES = [(4, 1024, 1224), (4, 2048, 2448), (4, 4096, 6120), (4, 8160, 12240)]


def _leaves(copies: int = 1) -> tuple[np.ndarray, np.ndarray]:
    data = np.load(SAMPLE_DIR / "leaves.npz")
    return np.tile(data["stack"], (1, copies, copies)), np.deg2rad(data["angles"])


@pytest.fixture
def region_calls(monkeypatch) -> list[tuple]:
    """Every tile decision of the default method: (shape, limit, grid)."""
    calls: list[tuple] = []

    def spy(shape, params, limit=None):
        grid = region_tiles(shape, params, limit)
        calls.append((shape, limit, grid))
        return grid

    monkeypatch.setattr(valid_superpixels, "region_tiles", spy)
    return calls


def test_the_default_method_tiles_by_the_scenes_limit(region_calls):
    stack, angles = _leaves(5)  # 7 x 600 x 650
    shape = stack.shape[1:]
    held = stack.nbytes + stack.size + RUNTIME_BYTES  # the stack, its flags, the libraries
    cores = []
    for limit in (held + 50 * 2**20, held + 75 * 2**20, 2**40):
        scene = Scene(stack, angles, max_bytes=limit)
        labels = scene.segment(AUTO, maps=False, reconstruction=False).labels
        assert labels.shape == shape
        assert scene.work_limit() == limit - held
        _, seen, grid = region_calls[-1]
        assert seen == limit - held  # the limit given, not the environment's
        cores.append(None if grid is None else grid.core)
    # the smaller the limit, the smaller the tiles; the largest runs on the whole image
    assert cores[0] is not None and cores[2] is None
    assert cores[1] is None or cores[0] <= cores[1]


def test_the_pixel_classifier_tiles_by_the_scenes_limit(monkeypatch):
    seen = []

    def spy(*args, limit=None, **kwargs):
        seen.append(limit)
        return None  # the whole image: only the limit is looked at here

    monkeypatch.setattr(pixel_segmentation, "scribble_tiles", spy)
    stack, angles = _leaves()
    strokes = np.zeros(stack.shape[1:], dtype=np.int32)
    strokes[10:20, 10:20], strokes[80:90, 100:110] = 1, 2
    scene = Scene(stack, angles, max_bytes=2**30)
    scene.segment(AUTO, {"scribbles": strokes}, maps=False, reconstruction=False)
    held = stack.nbytes + stack.size + RUNTIME_BYTES  # the stack, its flags, the libraries
    assert seen and seen[-1] == scene.work_limit() == 2**30 - held


def test_a_run_under_a_small_max_memory_is_tiled_not_refused(tmp_path, capsys, region_calls):
    stack, angles = _leaves(9)  # 7 x 1080 x 1170: the method's peak is above the fit's
    path = tmp_path / "big.npz"
    np.savez(path, stack=stack, angles=np.rad2deg(angles))
    whole = estimate_pipeline_bytes(stack.shape, AUTO, limit=2**40, itemsize=2)
    limit = (whole - 1) // 1024 * 1024  # the whole image no longer fits
    assert estimate_pipeline_bytes(stack.shape, AUTO, limit=limit, itemsize=2) <= limit
    out = tmp_path / "out"
    code = cli.main(["segment", str(path), "--out", str(out), "--max-memory", f"{limit // 1024}K"])
    err = capsys.readouterr().err
    assert code == 0, err
    (shape, seen, grid) = region_calls[-1]
    held = stack.nbytes + stack.size + RUNTIME_BYTES  # the stack, its flags, the libraries
    assert seen == limit - held and grid is not None and len(grid) > 1
    assert json.loads((out / "summary.json").read_text())["n_segments"] >= 2
    # the same run on the whole image would have been refused at this limit
    with pytest.raises(PolarsegError, match="would need"):
        check_pipeline_memory(stack.shape, AUTO, limit, blocks=True)


@pytest.mark.parametrize("scribbles", [False, True])
def test_nothing_under_100_mp_is_refused_at_the_default_limit(scribbles):
    for shape in SIZES:
        for itemsize in (1, 2):  # camera counts, 8 or 16 bits
            needed = check_pipeline_memory(
                shape, AUTO, DEFAULT_MAX_BYTES, itemsize=itemsize, scribbles=scribbles
            )
            assert needed <= DEFAULT_MAX_BYTES


def test_the_estimate_counts_the_tiles_and_refuses_only_what_cannot_fit():
    big = SIZES[2]  # 24 MP
    limit = 3 * 2**30
    tiled = estimate_pipeline_bytes(big, AUTO, limit=limit, itemsize=1)
    whole = estimate_pipeline_bytes(big, AUTO, limit=2**40, itemsize=1)
    assert tiled <= limit < whole  # tiled to fit: not refused
    check_pipeline_memory(big, AUTO, limit, itemsize=1)
    work = limit - 2 * big[0] * 4096 * 6120 - RUNTIME_BYTES
    grid = region_tiles(big[1:], SurfaceSuperpixels().params, work)
    assert grid is not None and len(grid) > 1
    # 100 MP at 2 GiB: its full-size arrays go to temporary files (disk_arrays), the
    # tiles and the stack stay in memory, within the limit
    huge, two = SIZES[3], 2 * 2**30
    assert estimate_pipeline_bytes(huge, AUTO, limit=two, itemsize=1) <= two
    check_pipeline_memory(huge, AUTO, two, itemsize=1)
    # in memory the same run would need several times as much
    assert estimate_pipeline_bytes(huge, AUTO, limit=2**40, itemsize=1) > 3 * two
    # below what the stack alone holds it is refused
    with pytest.raises(PolarsegError, match="segmenting 4 frames of 8160 x 12240 pixels"):
        check_pipeline_memory(huge, AUTO, 2**29, itemsize=1)


def test_the_superpixel_methods_compute_the_normals_after_their_work():
    stack, angles = _leaves()
    scene = Scene(stack, angles)
    seen = {}

    def progress(stage, index, total):
        seen.setdefault(stage, scene.pipeline.calls["normals"])

    result = scene.segment(AUTO, maps=False, reconstruction=False, progress=progress)
    assert seen["superpixels"] == seen["clustering"] == 0  # not while the method works
    assert scene.pipeline.calls["normals"] == 1 and result.zenith.shape == stack.shape[1:]
    assert Scene.stages(AUTO) == ["polarisation", "superpixels", "clustering", "normals"]
    thesis = Scene.stages(PRESETS["thesis"])
    assert thesis[:3] == ["polarisation", "normals", "harmonics"]  # the thesis reads them
