"""Parameters JSON in "Segment by material": save/load in the CLI's format, new controls."""

from __future__ import annotations

import json
from dataclasses import fields

import pytest
from _gui_helpers import click, error_messages, wait_idle

from napari_polarseg import cli
from napari_polarseg._sample_data import SAMPLE_DIR
from napari_polarseg.engine import SegmentParams
from napari_polarseg.engine.params import CLUSTERING_METHODS, FEATURE_KINDS, RECOMMENDED
from napari_polarseg.io import read_params_dict
from napari_polarseg.widgets.segment import CONTROLLED
from napari_polarseg.widgets.segment_params import ParameterControls

pytestmark = pytest.mark.gui

#: Every field away from the thesis defaults (also those without a control).
CUSTOM = SegmentParams(
    window=7,
    degree=9,
    refractive_index=1.62,
    model="specular",
    specular_branch="above-brewster",
    coefficients="ridge",
    ridge=0.02,
    features="zonal+polstats",
    variance=0.9,
    scale=3.5,
    scale_mode="median",
    spatial_radius=2.5,
    spatial_sigma=1.5,
    n_segments=5,
    object_size=24.0,
    ncut_threshold=0.4,
    min_segment_blocks=3,
    clustering="kway",
    fit="robust",
    affinity_graph="sparse",
    method="superpixels",
)


def controls(widget) -> dict:
    """The value of every parameter control."""
    return {name: getattr(widget, name).value for name in CONTROLLED}


def test_custom_differs_from_the_defaults_in_every_field():
    default = SegmentParams()
    assert all(getattr(CUSTOM, f.name) != getattr(default, f.name) for f in fields(default))


def test_save_then_load_restores_every_control(viewer, add_widget, tmp_path):
    widget = add_widget("Segment by material")
    widget.set_params(CUSTOM)
    assert widget.params() == CUSTOM
    saved = controls(widget)
    path = tmp_path / "custom.json"
    assert widget.save_params(path)
    assert widget.status.value == f"saved the parameters to {path}"

    # the format of SegmentParams.to_json, which `polarseg segment --params` reads
    text = path.read_text(encoding="utf-8")
    assert text == CUSTOM.to_json() + "\n"
    assert set(json.loads(text)) == {f.name for f in fields(SegmentParams)}
    assert SegmentParams.from_json(text) == CUSTOM
    assert SegmentParams.from_dict(read_params_dict(str(path))) == CUSTOM

    widget.preset.value = "recommended"
    assert widget.params() == RECOMMENDED
    assert controls(widget) != saved
    assert widget.load_params(path)
    assert widget.status.value == f"loaded the parameters from {path}"
    assert widget.params() == CUSTOM
    assert controls(widget) == saved
    assert not widget.specular_branch.native.isHidden()  # follows the loaded model
    assert error_messages() == []


def test_loads_the_params_json_the_cli_writes(viewer, add_widget, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["segment", str(SAMPLE_DIR / "leaves.npz"), "--out", str(out), "--preset", "thesis"]
    argv += ["--window", "12", "--degree", "4", "--features", "zonal", "--segments", "2"]
    assert cli.main(argv) == 0, capsys.readouterr().err
    written = json.loads((out / "params.json").read_text(encoding="utf-8"))
    expected = SegmentParams.from_dict(written["params"])
    assert expected == SegmentParams(window=12, degree=4, features="zonal", n_segments=2)

    widget = add_widget("Segment by material")
    assert widget.load_params(out / "params.json")
    assert widget.params() == expected
    assert widget.window.value == 12 and widget.features.value == "zonal"


def test_a_partial_file_takes_the_thesis_defaults_like_the_cli(viewer, add_widget, tmp_path):
    widget = add_widget("Segment by material")
    widget.preset.value = "recommended"
    path = tmp_path / "partial.json"
    path.write_text('{"n_segments": 4, "clustering": "kway"}', encoding="utf-8")
    assert widget.load_params(path)
    assert widget.params() == SegmentParams(n_segments=4, clustering="kway")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ('{"window": 8,', "is not valid JSON"),
        ('{"window": 8, "colour": "red"}', "unknown parameter(s): colour"),
        ('{"window": -3}', "window must be a positive integer"),
        ('{"features": "wavelets"}', "features must be one of"),
        ("[1, 2, 3]", "must hold a JSON object"),
        ('{"window": 5000}', "window 5000 is outside the widget's range 2..4096"),
        ('{"n_segments": 1000}', "n_segments 1000 is outside the widget's range 0..256"),
        (None, "cannot read the parameters file"),
    ],
)
def test_bad_files_leave_the_controls_unchanged(viewer, add_widget, tmp_path, content, message):
    widget = add_widget("Segment by material")
    widget.set_params(CUSTOM)
    before, values = widget.params(), controls(widget)
    path = tmp_path / "bad.json"
    if content is not None:
        path.write_text(content, encoding="utf-8")
    assert not widget.load_params(path)
    assert widget.params() == before
    assert controls(widget) == values
    status = widget.status.value
    assert status.startswith(f"error: {path}: ") and message in status, status
    assert error_messages() == [status.removeprefix("error: ")]  # a notification, no trace


def test_extra_decimals_of_a_loaded_value_are_kept(viewer, add_widget, tmp_path):
    widget = add_widget("Segment by material")
    path = tmp_path / "precise.json"
    path.write_text('{"refractive_index": 1.45371, "scale": 0.00123}', encoding="utf-8")
    assert widget.load_params(path)
    assert widget.refractive_index.value == pytest.approx(1.454)  # shown rounded
    assert widget.scale.value == pytest.approx(0.001)
    params = widget.params()
    assert params.refractive_index == 1.45371 and params.scale == 0.00123  # kept exactly
    widget.refractive_index.value = 1.5  # once changed, the control's value counts
    assert widget.params().refractive_index == 1.5
    # the float controls' ranges are no longer rounded to 2 decimals
    assert widget.scale.min == pytest.approx(0.001)


def test_buttons_ask_for_a_file(viewer, add_widget, qtbot, tmp_path, monkeypatch):
    widget = add_widget("Segment by material")
    widget.set_params(CUSTOM)
    answers: list = [str(tmp_path / "from_button")]  # no suffix: .json is added
    # (on the class: magicgui containers take ``del widget.name`` for removing a widget)
    monkeypatch.setattr(ParameterControls, "ask_path", lambda self, save: answers.pop(0))
    click(qtbot, widget.save_button)
    saved = tmp_path / "from_button.json"
    assert SegmentParams.from_json(saved.read_text(encoding="utf-8")) == CUSTOM

    widget.preset.value = "recommended"
    answers.append(None)  # the dialog was cancelled: nothing happens
    click(qtbot, widget.load_button)
    assert widget.params() == RECOMMENDED
    answers.append(str(saved))
    click(qtbot, widget.load_button)
    assert widget.params() == CUSTOM


def test_loading_with_live_update_runs_once(viewer, open_sample, add_widget, qtbot, tmp_path):
    open_sample("leaves")
    widget = add_widget("Segment by material")
    path = tmp_path / "fast.json"
    params = SegmentParams(window=10, degree=4, n_segments=2, features="zonal")
    path.write_text(params.to_json(), encoding="utf-8")
    widget.live.value = True
    wait_idle(qtbot, widget)
    first = widget._slot.run_id
    assert widget.load_params(path)
    wait_idle(qtbot, widget)
    assert widget._slot.run_id == first + 1  # one run for the whole burst of changes
    shown = widget.output("segments").metadata["polarseg_params"]
    assert shown["method_params"]["thesis"]["features"] == "zonal"
    assert error_messages() == []


def test_clustering_and_feature_controls(viewer, add_widget):
    widget = add_widget("Segment by material")
    assert tuple(widget.clustering.choices) == CLUSTERING_METHODS
    assert widget.clustering.value == "recursive"
    tip = widget.clustering.tooltip
    assert "recursive two-way normalized cuts" in tip and "k-way spectral clustering" in tip
    widget.clustering.value = "kway"
    assert widget.params() == SegmentParams(clustering="kway")
    widget.preset.value = "recommended"
    assert widget.params().clustering == RECOMMENDED.clustering

    assert tuple(widget.features.choices) == FEATURE_KINDS
    assert {"polstats", "zonal+polstats"} <= set(widget.features.choices)
    tip = widget.features.tooltip
    assert "polstats" in tip and "zonal+polstats" in tip and "ρ, θ and Î" in tip
    widget.features.value = "polstats"
    assert widget.params().features == "polstats"
