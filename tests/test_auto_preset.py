"""The default preset ``auto``: the superpixel method, a peer of the thesis pipeline.

``auto`` is the recommended block parameters with ``method="surface_superpixels"``: the labels
come from :func:`~napari_polarseg.engine.unsupervised.segmenter.segment_unsupervised`
through :class:`~napari_polarseg.engine.Scene`, no block graph is built or cut, and the
contract files are written as for every preset.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from sklearn.metrics import adjusted_rand_score
from test_unsupervised import planted

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import Pipeline, PolarsegError, Scene, SegmentParams
from napari_polarseg.engine.analysis.timeseries import segment_timeseries
from napari_polarseg.engine.params import AUTO, PRESETS, RECOMMENDED

ANGLES = np.deg2rad([0.0, 45.0, 90.0, 135.0])


def planted_stack(k: int = 3, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Angle stack (4, H, W) of :func:`planted`'s materials, I(θ) = Î/2 (1 + ρ cos(2θ − 2φ)),
    scaled to 12-bit counts, and the truth (H, W)."""
    intensity, dop, phase, truth = planted(k, seed=seed)
    stack = 0.5 * intensity * (1 + dop * np.cos(2 * ANGLES[:, None, None] - 2 * phase))
    return np.round(stack * 2000).astype(np.uint16), truth


def test_auto_is_the_recommended_blocks_with_superpixel_labels():
    assert AUTO.method == "surface_superpixels"
    assert AUTO.replace(method="thesis") == RECOMMENDED
    assert PRESETS["auto"] == AUTO
    # a params.json written before the methods were peers still reads
    old = {**RECOMMENDED.to_dict(), "clustering": "superpixels"}
    del old["method"]
    assert SegmentParams.from_dict(old) == AUTO.replace(method="superpixels")


@pytest.mark.parametrize("k", [2, 3])
def test_pipeline_default_recovers_planted_materials_exactly(k):
    stack, truth = planted_stack(k)
    scene = Scene(stack, ANGLES)
    result = scene.segment(AUTO.replace(n_segments=k), maps=True, reconstruction=True)
    pipe = scene.pipeline
    assert adjusted_rand_score(truth.ravel(), result.labels.ravel()) == pytest.approx(1.0)
    assert result.labels.shape == truth.shape
    # no block graph is built or cut; the thesis maps and the error map are, when asked
    assert pipe.calls["affinity"] == 0 and pipe.calls["cut"] == 0
    assert pipe.calls["harmonics"] == 1 and pipe.calls["reconstruction"] == 1
    # the normals, which the superpixels do not read, come after them (for the result)
    assert scene.stages(AUTO, maps=True, reconstruction=True) == [
        "polarisation",
        "superpixels",
        "clustering",
        "normals",
        "harmonics",
        "pca",
        "reconstruction",
    ]
    assert result.method == "surface_superpixels"
    summary = result.summary()
    assert summary["degenerate"] is False
    assert result.ncut_values == []
    # the block labels are the pixel labels at each block's top-left pixel
    w = AUTO.window
    np.testing.assert_array_equal(
        result.block_labels, result.labels[::w, ::w][: result.block_labels.shape[0]]
    )


def test_changing_the_method_switches_between_cut_and_superpixels():
    stack, truth = planted_stack(3)
    scene = Scene(stack, ANGLES)
    first = scene.segment(AUTO, maps=True).labels
    scene.segment(AUTO.replace(method="thesis"), reconstruction=False)
    pipe = scene.pipeline
    assert pipe.calls["cut"] == 1 and pipe.calls["labels"] == 1
    again = scene.segment(AUTO).labels
    assert pipe.calls["harmonics"] == 1  # the block stages are shared
    assert scene.method_calls == {"surface_superpixels": 1, "thesis": 1}  # kept, not rerun
    np.testing.assert_array_equal(first, again)
    # a Pipeline alone cuts the block graph only
    with pytest.raises(PolarsegError, match="Scene"):
        Pipeline(stack, ANGLES, AUTO).run()


def test_segment_and_demo_default_to_auto(tmp_path, capsys):
    stack, truth = planted_stack(3)
    path = tmp_path / "planted.tif"
    pio.write_stack_tiff(path, stack, np.rad2deg(ANGLES))
    out = tmp_path / "out"
    assert cli.main(["segment", str(path), "--segments", "3", "--out", str(out)]) == 0
    params = json.loads((out / "params.json").read_text())["params"]
    assert params["method"] == "surface_superpixels"
    labels = tifffile.imread(out / "labels.tif")
    assert adjusted_rand_score(truth.ravel(), labels.ravel()) == pytest.approx(1.0)
    # --preset thesis keeps the faithful pipeline
    out2 = tmp_path / "thesis"
    argv = ["segment", str(path), "--out", str(out2)]
    assert cli.main(argv + ["--preset", "thesis"]) == 0
    assert json.loads((out2 / "params.json").read_text())["params"]["method"] == "thesis"
    parser = cli.build_parser()
    assert parser.parse_args(["demo"]).preset == "auto"
    assert parser.parse_args(["segment", "x.tif", "--out", "o"]).preset == "auto"


def test_block_graph_commands_do_not_offer_auto():
    parser = cli.build_parser()
    with pytest.raises(cli.UsageError, match="invalid choice: 'auto'"):
        parser.parse_args(["timeseries", "x.tif", "y.tif", "-o", "o", "--preset", "auto"])
    # the sweep offers auto: its --vary sweeps the chosen method's own parameters, and
    # the window/degree grid stays the thesis method's (tests/test_method_own_params.py)
    assert parser.parse_args(["sweep", "x.tif", "-o", "o", "--preset", "auto"]).preset == "auto"
    stack, _ = planted_stack(2)
    # the time series runs the superpixel methods on day 1's own labels, not a joint cut
    superpixels = SegmentParams(method="superpixels")
    with pytest.raises(PolarsegError, match="joint time series cuts one block graph"):
        segment_timeseries([stack, stack], ANGLES, superpixels, method="joint")
    with pytest.raises(PolarsegError, match="give day_labels"):
        segment_timeseries([stack, stack], ANGLES, superpixels)
