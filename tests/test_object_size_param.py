"""The object size (``SegmentParams.object_size``, ``--object-size``): given, the
superpixel methods' superpixel area and diffusion reach follow it; left at 0 (auto),
they keep their frame-share scales and the size is estimated and reported. The run's
record, the command line and ``params.json`` say which."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score
from test_valid_superpixels import ANGLES

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import Scene
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features.object_size import estimate_object_size
from napari_polarseg.engine.methods.registry import get_method
from napari_polarseg.engine.params import AUTO, SegmentParams
from napari_polarseg.engine.unsupervised.params import (
    MAX_REGION_AREA,
    MIN_OBJECT_REGION_AREA,
    UnsupervisedParams,
)


def discs_stack(diameter: int, shape=(160, 200), seed=0):
    """Discs of one ``diameter`` (px) of two materials, assigned at random, on a grid
    of pitch 1.6 × the diameter over a third material; all three of equal intensity and
    different ρ and φ. The angle stack through the polariser at :data:`ANGLES` and the
    truth (0 = the background)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    truth = np.zeros(shape, dtype=np.int32)
    rows, cols = np.indices(shape)
    pitch = 1.6 * diameter
    for cy in np.arange(pitch / 2, h, pitch):
        for cx in np.arange(pitch / 2, w, pitch):
            disc = (rows - cy) ** 2 + (cols - cx) ** 2 <= (diameter / 2) ** 2
            truth[disc] = rng.integers(1, 3)
    dop = np.choose(truth, [0.02, 0.12, 0.30])
    phase = np.choose(truth, [0.3, 1.2, 2.2])
    stack = 1000.0 * (1 + dop * np.cos(2 * ANGLES[:, None, None] - 2 * phase))
    stack = stack + rng.normal(0, 5.0, stack.shape)
    return np.clip(np.round(stack), 0, None).astype(np.uint16), truth


def test_at_object_size_scales_area_and_reach():
    base = UnsupervisedParams()
    shape = (240, 320)
    p = base.at_object_size(64.0, shape, reach_objects=1.0, regions_per_side=8.0)
    assert p.region_area == 64  # (64 / 8)²
    assert p.diffusion_range == pytest.approx(64.0 / math.sqrt(240 * 320))
    tiny = base.at_object_size(4.0, shape, reach_objects=1.0, regions_per_side=8.0)
    assert tiny.region_area == MIN_OBJECT_REGION_AREA
    huge = base.at_object_size(1e5, shape, reach_objects=1.0, regions_per_side=8.0)
    assert huge.region_area == MAX_REGION_AREA and huge.diffusion_range == 1.0
    # everything else is left as it was
    assert p.replace(region_area=0, diffusion_range=base.diffusion_range) == base


def test_object_size_is_checked():
    with pytest.raises(PolarsegError, match="object size"):
        SegmentParams(object_size=-3)
    assert SegmentParams(object_size=0).object_size == 0


def test_given_size_sets_the_scales_and_the_record_says_so():
    stack, _ = discs_stack(16)
    scene = Scene(stack, ANGLES)
    method = get_method(AUTO.method)
    result = scene.segment(AUTO.replace(n_segments=3, object_size=16))
    record = result.method_record
    assert record["object_size"] == 16 and record["object_size_found"] is False
    expected = method.scaled_params(16.0, stack.shape[1:]).area_of(stack.shape[1:])
    assert record["region_areas"] == [expected]
    # the scales never go coarser than the frame-share ones
    assert expected <= method.params.area_of(stack.shape[1:])
    assert record["object_size_applied"] is True
    found = scene.segment(AUTO.replace(n_segments=3)).method_record
    # the estimate is followed where it is at least a tenth of the short side (160 px)
    shape = stack.shape[1:]
    followed = found["object_size"] >= method.estimate_floor * min(shape)
    assert method.estimate_floor == pytest.approx(0.10)
    assert found["object_size_found"] is True and found["object_size_applied"] is followed
    used = method.scaled_params(found["object_size"], shape) if followed else method.params
    assert found["region_areas"] == [used.area_of(shape)]
    pol = scene.polarisation(AUTO)
    estimate = estimate_object_size(pol.intensity, pol.dop, pol.phase, ~pol.invalid)
    assert found["object_size"] == pytest.approx(estimate.size_px, abs=0.05)
    # the estimate is within a factor 1.5 of the planted discs' diameter
    assert 16 / 1.5 < estimate.size_px < 16 * 1.5


@pytest.mark.parametrize("diameter", [12, 24, 48])
def test_small_planted_objects_are_found_at_their_size(diameter):
    """Discs of two materials mixed at random over a third: at its object size the
    default separates them; at the frame-share scales (any size above the frame's) the
    diffusion reaches across many small discs and joins their materials."""
    stack, truth = discs_stack(diameter)
    scene = Scene(stack, ANGLES)
    labels = scene.segment(AUTO.replace(n_segments=3, object_size=diameter)).labels
    assert adjusted_rand_score(truth.ravel(), labels.ravel()) > 0.9
    if diameter == 12:
        coarse = scene.segment(AUTO.replace(n_segments=3, object_size=10_000)).labels
        assert adjusted_rand_score(truth.ravel(), coarse.ravel()) < 0.5


def test_cli_object_size_flag(tmp_path, capsys):
    stack, _ = discs_stack(16)
    path = tmp_path / "discs.tif"
    pio.write_stack_tiff(path, stack, np.rad2deg(ANGLES))
    out = tmp_path / "out"
    argv = ["segment", str(path), "--segments", "3", "--object-size", "20", "--out", str(out)]
    assert cli.main(argv) == 0
    stdout = capsys.readouterr().out
    assert "polarseg: object size 20 px (given): superpixel area 9 px" in stdout
    assert json.loads((out / "params.json").read_text())["params"]["object_size"] == 20
    argv[argv.index("20")] = "auto"
    assert cli.main(argv) == 0
    line = next(t for t in capsys.readouterr().out.splitlines() if "object size" in t)
    size = float(line.split("object size")[1].split("px")[0].replace("about", ""))
    if size >= 16:  # a tenth of the 160 px side: followed
        assert "(estimated from the scene): superpixel area" in line
    else:
        assert "(estimated from the scene, not followed: the superpixels keep" in line
    assert json.loads((out / "params.json").read_text())["params"]["object_size"] == 0
