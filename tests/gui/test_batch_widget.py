"""The batch and time-series widgets in a real napari viewer (run under Xvfb)."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile
from _gui_helpers import click
from scipy import ndimage

from napari_polarseg import batch, cli
from napari_polarseg.engine.analysis.timeseries import segment_timeseries
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.engine.synthetic.optics import render_stack
from napari_polarseg.engine.synthetic.scenes import DEFAULT_NOISE_SIGMA, make_scene
from napari_polarseg.widgets.batch import (
    BatchWidget,
    TimeSeriesWidget,
    add_timeseries_layers,
)

SHAPE = (64, 72)


def write_scenes(folder, names=("leaves", "fruit")):
    folder.mkdir()
    for seed, name in enumerate(names):
        scene = make_scene(name, shape=SHAPE, seed=seed)
        np.savez(folder / f"{name}.npz", stack=scene.stack, angles=scene.angles_deg)
    return folder


def test_batch_widget_applies_segment_widget_params_to_a_folder(
    viewer, add_widget, qtbot, tmp_path
):
    folder = write_scenes(tmp_path / "in")
    (folder / "broken.npz").write_bytes(b"not a zip")
    out = tmp_path / "out"
    segment = add_widget("Segment by material")
    segment.set_params(RECOMMENDED, window=8, n_segments=2)
    widget = add_widget("Batch over a folder")
    assert isinstance(widget, BatchWidget)
    widget.folder.value = folder
    widget.out.value = out
    widget.scheduler.value = "inline"
    assert widget.params() == RECOMMENDED.replace(window=8, n_segments=2)
    click(qtbot, widget.run_button)
    assert widget.wait(120)
    table = widget.table.to_dict("list")
    assert table["scene"] == ["broken", "fruit", "leaves"]
    assert table["status"] == ["failed", "done", "done"]
    assert "broken.npz" in table["error"][0]
    assert "2 done" in widget.status.value and "1 failed" in widget.status.value
    for name in ("fruit", "leaves"):
        assert batch.is_complete(out / name)
        assert tifffile.imread(out / name / "labels.tif").shape == SHAPE
    assert batch.read_summary(out)["params"]["method_params"]["thesis"]["window"] == 8
    # again: the complete scenes are skipped; the table can be reloaded from disk
    click(qtbot, widget.run_button)
    assert widget.wait(120)
    assert widget.table.to_dict("list")["status"] == ["failed", "skipped", "skipped"]
    widget.table.value = {"scene": []}
    click(qtbot, widget.load_button)
    assert widget.table.to_dict("list")["scene"] == ["broken", "fruit", "leaves"]


def test_batch_widget_cancel_and_bad_input(viewer, add_widget, qtbot, tmp_path):
    folder = write_scenes(tmp_path / "in", ("leaves", "fruit", "camouflage"))
    out = tmp_path / "out"
    widget = add_widget("Batch over a folder")
    widget.run()  # no folder chosen: an error in the status line, nothing started
    assert widget.status.value.startswith("error") and not widget.busy
    widget.folder.value = folder
    widget.out.value = out
    widget.scheduler.value = "inline"
    widget.source.value = "recommended"
    widget.run()
    widget.cancel()
    assert widget.wait(120)
    statuses = widget.table.to_dict("list")["status"]
    assert "cancelled" in statuses and len(statuses) == 3
    assert batch.read_summary(out)["counts"]["cancelled"] >= 1
    assert not any(p.name.startswith(".") and p.is_dir() for p in out.iterdir())


def fruit_days():
    """Day 1: the fruit scene; day 2: the same view with new noise and a patch 3 % darker
    and 30 % less polarised (a material change), rendered from day 1's noise-free images."""
    day1 = make_scene("fruit", shape=SHAPE, seed=0)
    patch = np.zeros(SHAPE, bool)
    patch[12:36, 24:48] = True
    stack = render_stack(
        np.where(patch, 0.97, 1.0) * day1.intensity,
        np.where(patch, 0.7, 1.0) * day1.dop,
        day1.phase,
        day1.angles,
        noise_sigma=DEFAULT_NOISE_SIGMA,
        bit_depth=12,
        rng=1,
    )
    return day1, stack, patch


def test_timeseries_widget_adds_segments_change_and_score_layers(viewer, add_widget, qtbot):
    day1, stack2, patch = fruit_days()
    layers = [
        viewer.add_image(s, name=f"day {i}", metadata={"angles_deg": day1.angles_deg})
        for i, s in enumerate((day1.stack, stack2), start=1)
    ]
    widget = add_widget("Time series change map")
    assert isinstance(widget, TimeSeriesWidget)
    assert widget.method.value == "tracked" and widget.false_alarm.value == 1e-3
    widget.source.value = "recommended"
    widget.false_alarm.value = 1e-4
    widget.days.value = layers
    click(qtbot, widget.run_button)
    assert widget.wait(120)
    expected = segment_timeseries(
        [day1.stack, stack2], day1.angles, RECOMMENDED, method="tracked", false_alarm=1e-4
    )
    # named after the first day; never offered as a day of another series (issue 25)
    seg = viewer.layers["time series segments (day 1)"]
    change = viewer.layers["time series change (day 1)"]
    score = viewer.layers["time series change score (day 1)"]
    distance = viewer.layers["time series feature distance (day 1)"]
    widget.days.reset_choices()
    assert list(widget.days.choices) == layers
    assert score.ndim == distance.ndim == 3  # shaped like a stack, yet not a day
    assert seg.data.shape == (2, *SHAPE) and change.data.shape == (1, *SHAPE)
    np.testing.assert_array_equal(seg.data, expected.labels + 1)
    np.testing.assert_array_equal(change.data[0], expected.changes[0])
    np.testing.assert_array_equal(score.data, expected.change_score)
    # the darkened patch is what changed segment, and nothing far from it
    assert change.data[0][patch].mean() > 0.7
    far = ~ndimage.binary_dilation(patch, iterations=6)
    assert change.data[0][far].mean() < 0.02
    assert score.data[0][patch].mean() > 3.7
    assert "2 days" in widget.status.value and "significant change blocks" in widget.status.value


def test_add_timeseries_layers_from_a_cli_folder(viewer, tmp_path):
    day1, stack2, _ = fruit_days()
    paths = []
    for i, stack in enumerate((day1.stack, stack2), start=1):
        paths.append(tmp_path / f"day{i}.npz")
        np.savez(paths[-1], stack=stack, angles=day1.angles_deg)
    out = tmp_path / "series"
    assert cli.main(["timeseries", *map(str, paths), "--out", str(out), "--window", "8"]) == 0
    layers = add_timeseries_layers(viewer, out, name="cli")
    assert [layer.name for layer in layers] == [
        "cli segments",
        "cli change",
        "cli change score",
        "cli feature distance",
    ]
    labels = tifffile.imread(out / "labels_02.tif")
    np.testing.assert_array_equal(layers[0].data[1], labels + 1)
    np.testing.assert_array_equal(layers[1].data[0], tifffile.imread(out / "change_01.tif"))
    np.testing.assert_array_equal(layers[2].data[0], tifffile.imread(out / "score_01.tif"))
    assert layers[1].data.any()
    # an older folder without score maps still loads (no score layer)
    (out / "score_01.tif").unlink()
    names = [layer.name for layer in add_timeseries_layers(viewer, out, name="old")]
    assert names == ["old segments", "old change", "old feature distance"]


def test_batch_params_json_file_accepts_a_polarseg_params_json(viewer, tmp_path):
    """The batch widget reads a parameters file as `segment --params` does: a SegmentParams
    JSON, or the params.json that polarseg writes into a result folder."""
    from napari_polarseg.engine import PolarsegError
    from napari_polarseg.widgets.batch import params_from

    plain = tmp_path / "plain.json"
    plain.write_text(RECOMMENDED.replace(n_segments=4).to_json(), encoding="utf-8")
    assert params_from(viewer, "JSON file", plain) == RECOMMENDED.replace(n_segments=4)
    folder = tmp_path / "out"
    assert cli.main(["demo", "--out", str(folder), "--preset", "recommended"]) == 0
    from_folder = params_from(viewer, "JSON file", folder / "params.json")
    assert from_folder.window == RECOMMENDED.window
    (tmp_path / "bad.json").write_text("[1]", encoding="utf-8")
    with pytest.raises(PolarsegError, match="must hold a JSON object"):
        params_from(viewer, "JSON file", tmp_path / "bad.json")
