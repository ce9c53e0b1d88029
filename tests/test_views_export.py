"""The polarisation views in the result folder: stokes.tif, aolp_dolp.png, overview.png's truth.

``stokes.tif`` is read back with tifffile and compared with the Stokes components of the
input frames themselves (I(0°) + I(90°), I(0°) − I(90°), I(45°) − I(135°)); the overview's
ground-truth panel and its ARI title are read off the matplotlib figure.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import tifffile
from skimage import io as skio
from test_cli import CONTRACT, run, two_material_scene

from napari_polarseg import outputs
from napari_polarseg.cli import demo as cli_demo
from napari_polarseg.engine import Pipeline, PolarsegError, SegmentParams
from napari_polarseg.engine.analysis.evaluation import adjusted_rand_index
from napari_polarseg.engine.analysis.views import (
    CompositeParams,
    aolp_dolp_composite,
    auto_dolp_max,
)
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.outputs import (
    COMPOSITE_FILE,
    STOKES_FILE,
    overview_figure,
    result_folder,
    segment_colours_for,
    write_result_folder,
)

SHAPE = (48, 56)
PARAMS = SegmentParams(window=8, degree=4, n_segments=3)


@pytest.fixture(scope="module")
def four_angle_run():
    """A noise-free float scene at the four angles of a polarisation camera."""
    scene = make_scene(
        "leaves", shape=SHAPE, angles_deg=(0.0, 45.0, 90.0, 135.0), bit_depth=None, noise_sigma=0
    )
    return scene, Pipeline(scene.stack, scene.angles, PARAMS).run()


def test_stokes_tif_round_trip_matches_the_input_frames(tmp_path, four_angle_run):
    scene, result = four_angle_run
    out = tmp_path / "out"
    written = write_result_folder(
        out, stack=scene.stack, angles_deg=scene.angles_deg, result=result, overview=False
    )
    assert STOKES_FILE in written and COMPOSITE_FILE in written
    with tifffile.TiffFile(out / STOKES_FILE) as tif:
        stokes = tif.asarray()
        meta = tif.shaped_metadata[0]
        description = json.loads(tif.pages[0].description)
    assert stokes.shape == (3, *SHAPE) and stokes.dtype == np.float32
    i0, i45, i90, i135 = scene.stack
    scale = float(np.abs(scene.stack).max())
    np.testing.assert_allclose(stokes[0], i0 + i90, rtol=1e-5)
    np.testing.assert_allclose(stokes[1], i0 - i90, atol=1e-5 * scale)
    np.testing.assert_allclose(stokes[2], i45 - i135, atol=1e-5 * scale)
    # a plain JSON ImageDescription naming the planes and the angle convention
    assert description["components"] == meta["components"] == ["S0", "S1", "S2"]
    assert "S0 = 2 I_mean" in description["definition"]
    assert "column axis towards the row axis" in description["angle_direction"]
    # the composite: the engine's, with the automatic ρ_max recorded in params.json
    info = json.loads((out / "params.json").read_text(encoding="utf-8"))
    dolp_max = auto_dolp_max(result.dop)
    assert info["aolp_dolp"] == {"dolp_max": dolp_max, "mode": "intensity",
                                 "intensity_percentile": 99.0}  # fmt: skip
    picture = skio.imread(out / COMPOSITE_FILE)
    want = aolp_dolp_composite(
        result.intensity, result.dop, result.phase, CompositeParams(dolp_max=dolp_max)
    )
    np.testing.assert_array_equal(picture, want)


def test_views_can_be_left_out_and_a_wrong_truth_is_refused(tmp_path, four_angle_run):
    scene, result = four_angle_run
    out = tmp_path / "plain"
    written = write_result_folder(
        out,
        stack=scene.stack,
        angles_deg=scene.angles_deg,
        result=result,
        overview=False,
        views=False,
    )
    assert STOKES_FILE not in written and not (out / COMPOSITE_FILE).exists()
    with pytest.raises(PolarsegError, match="ground truth"):
        write_result_folder(
            tmp_path / "never",
            stack=scene.stack,
            angles_deg=scene.angles_deg,
            result=result,
            truth=np.zeros((3, 3), int),
        )
    assert not (tmp_path / "never").exists()


def test_segment_colours_follow_the_matched_true_material():
    truth = np.repeat(np.array([[5, 7, 9]]), 4, axis=0)  # any label values
    labels = np.repeat(np.array([[2, 0, 1]]), 4, axis=0)  # the same partition, permuted
    true_index, colour = segment_colours_for(truth, labels)
    np.testing.assert_array_equal(true_index, [[0, 1, 2]] * 4)
    np.testing.assert_array_equal(colour[labels], true_index)
    # a split material: the extra segment gets a colour of its own
    labels = np.array([[0, 1, 2, 3]] * 4)
    truth = np.array([[0, 0, 1, 1]] * 4)
    _, colour = segment_colours_for(truth, labels)
    assert sorted(colour.tolist()) == [0, 1, 2, 3] and colour[0] != colour[1]


def test_overview_has_the_truth_panel_and_the_ari_when_the_truth_is_given(four_angle_run):
    scene, result = four_angle_run
    plain = overview_figure(scene.stack[0], result)
    with_truth = overview_figure(scene.stack[0], result, truth=scene.labels)
    titles = [ax.get_title() for ax in with_truth.axes]
    n_plain = 7  # input, Î, ρ, φ, HSV, segments, error
    assert [ax.get_title() for ax in plain.axes[:n_plain]][-1] == "reconstruction error"
    assert not any("ground truth" in t for t in [ax.get_title() for ax in plain.axes])
    assert not any("ARI" in t for t in [ax.get_title() for ax in plain.axes])
    n_true = np.unique(scene.labels).size
    truth_at = titles.index(f"ground truth ({n_true})")
    ari = adjusted_rand_index(scene.labels, result.labels)
    assert titles[truth_at - 1] == f"segments ({result.n_segments}), ARI {ari:.3f}"
    assert "AoLP" in titles[4]
    # the truth panel shows the truth (as colour indices 0, 1, ... of its sorted values)
    shown = np.asarray(with_truth.axes[truth_at].images[0].get_array())
    np.testing.assert_array_equal(shown, np.searchsorted(np.unique(scene.labels), scene.labels))
    # the HSV panel shows the composite
    hsv = np.asarray(with_truth.axes[4].images[0].get_array())
    assert hsv.shape == (*SHAPE, 3) and hsv.dtype == np.uint8
    # the grid of 2 x 4 panels has room for the truth panel: the same size
    a = outputs.render_overview(scene.stack[0], result)
    b = outputs.render_overview(scene.stack[0], result, truth=scene.labels)
    assert a.shape == b.shape


def _bar_ticks(fig, title_start):
    """The tick values and labels of the colour bar of the panel titled ``title_start...``."""
    (ax,) = [ax for ax in fig.axes if ax.get_title().startswith(title_start)]
    bar = ax.images[0].colorbar
    fig.canvas.draw()
    return list(bar.get_ticks()), [t.get_text() for t in bar.ax.get_yticklabels()]


def test_overview_is_a_grid_with_ordered_label_ticks(four_angle_run):
    """Issue 25: a grid readable at normal size (not a 2560 x 375 strip); the label
    panels' colour bars read 0, 1, 2, ... in order, and a segment keeps the colour of
    the material it is matched to."""
    scene, result = four_angle_run
    truth = scene.labels
    fig = overview_figure(scene.stack[0], result, truth=truth)
    width, height = fig.get_size_inches()
    assert 1.0 <= width / height <= 2.5
    pixels = outputs.render_overview(scene.stack[0], result, truth=truth)
    assert pixels.shape[1] <= 1600
    for title in ("segments", "ground truth"):
        values, names = _bar_ticks(fig, title)
        numbers = [int(n) for n in names]
        assert numbers == sorted(numbers) and values == sorted(values), (title, names)
    assert [int(n) for n in _bar_ticks(fig, "segments")[1]] == list(range(result.n_segments))
    (seg_ax,) = [ax for ax in fig.axes if ax.get_title().startswith("segments")]
    (true_ax,) = [ax for ax in fig.axes if ax.get_title().startswith("ground truth")]
    _, colour = segment_colours_for(truth, result.labels)
    seg_im, true_im = seg_ax.images[0], true_ax.images[0]
    for j in range(result.n_segments):
        if colour[j] < np.unique(truth).size:
            seg_rgba = seg_im.cmap(seg_im.norm(j))
            true_rgba = true_im.cmap(true_im.norm(colour[j]))
            assert seg_rgba == true_rgba


@pytest.fixture
def toy_samples(tmp_path, monkeypatch):
    stack, truth, _ = two_material_scene()
    folder = tmp_path / "samples"
    folder.mkdir()
    angles = np.arange(0.0, 180.0, 30.0)
    np.savez(
        folder / "toy.npz", stack=np.round(stack).astype(np.uint16), angles=angles, labels=truth
    )
    monkeypatch.setattr(cli_demo, "SAMPLE_DIR", folder)
    return truth


def test_cli_demo_writes_the_views_and_draws_the_truth(tmp_path, capsys, toy_samples, monkeypatch):
    drawn = {}
    real = result_folder.render_overview

    def spy(first_frame, result, **kwargs):
        drawn.update(kwargs)
        return real(first_frame, result, **kwargs)

    monkeypatch.setattr(result_folder, "render_overview", spy)
    out = tmp_path / "demo"
    code, _, err = run(capsys, "demo", "--out", out, "--scene", "toy", "--degree", "4")
    assert code == 0, err
    assert {STOKES_FILE, COMPOSITE_FILE} <= set(os.listdir(out))
    assert set(os.listdir(out)) == CONTRACT | {"overview.png"}
    np.testing.assert_array_equal(drawn["truth"], toy_samples)
    # stokes.tif agrees with the maps written beside it
    stokes = tifffile.imread(out / STOKES_FILE)
    intensity = tifffile.imread(out / "intensity.tif")
    dop = tifffile.imread(out / "dop.tif").astype(float)
    phase = tifffile.imread(out / "phase.tif").astype(float)
    np.testing.assert_allclose(stokes[0], 2 * intensity, rtol=1e-6)
    np.testing.assert_allclose(stokes[1], stokes[0] * dop * np.cos(2 * phase), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(stokes[2], stokes[0] * dop * np.sin(2 * phase), rtol=1e-4, atol=1e-3)
    png = skio.imread(out / COMPOSITE_FILE)
    assert png.shape == (*intensity.shape, 3) and png.dtype == np.uint8


def test_cli_segment_writes_the_views_without_truth(tmp_path, capsys, monkeypatch):
    stack, _, _ = two_material_scene()
    path = tmp_path / "stack.npy"
    np.save(path, stack)
    drawn = {}
    real = result_folder.render_overview

    def spy(first_frame, result, **kwargs):
        drawn.update(kwargs)
        return real(first_frame, result, **kwargs)

    monkeypatch.setattr(result_folder, "render_overview", spy)
    out = tmp_path / "out"
    angles = ",".join(str(a) for a in np.arange(0, 180, 30))
    code, _, err = run(
        capsys, "segment", path, "--out", out, "--angles", angles, "--window", "10",
        "--degree", "4", "--segments", "2", "--overview",
    )  # fmt: skip
    assert code == 0, err
    assert {STOKES_FILE, COMPOSITE_FILE, "overview.png"} <= set(os.listdir(out))
    assert drawn["truth"] is None
