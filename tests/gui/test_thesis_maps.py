"""The thesis maps on demand: always under the thesis method, else only with the *thesis
maps and error map* option; what a result without them shows, plots and exports; a
parameter the method does not read re-shows without a run; a registered method in the
menu."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from _gui_helpers import engine_result, error_messages, run_and_wait, wait_idle

from napari_polarseg.engine.methods import MethodOutput, register_method, unregister_method
from napari_polarseg.engine.params import AUTO
from napari_polarseg.widgets._layers import source_key

pytestmark = pytest.mark.gui

FAST = {"window": 10, "degree": 5, "n_segments": 3}


def _scene(widget, layer):
    return widget.store.scene(source_key(layer))


def test_default_method_computes_the_maps_only_when_asked(viewer, open_sample, add_widget, qtbot):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)  # auto: the superpixel method
    widget.set_params(**FAST)
    assert widget.params().method == AUTO.method
    assert widget.thesis_maps.enabled and not widget.thesis_maps.value
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    result = widget.shown_result(stack)
    assert result.features is None and result.reconstruction_error is None
    assert result.coefficients is None
    assert widget.output("error") is None
    assert "segments" in widget.status.value and "PCA" not in widget.status.value
    summary = widget.output("segments").metadata["polarseg_summary"]
    assert summary["n_components"] is None and summary["mean_reconstruction_error"] is None
    pipe = widget.pipeline
    assert pipe.calls.get("harmonics", 0) == 0 and pipe.calls.get("reconstruction", 0) == 0

    widget.thesis_maps.value = True  # the maps and the error map, the method not again
    run_and_wait(qtbot, widget)
    result = widget.shown_result(stack)
    assert result.features is not None and result.reconstruction_error is not None
    error = widget.output("error")
    assert error is not None and not error.visible
    np.testing.assert_allclose(error.data, result.reconstruction_error)
    assert "mean reconstruction error" in widget.status.value
    assert _scene(widget, stack).method_calls == {AUTO.method: 1}

    widget.thesis_maps.value = False  # off again: the error layer would be stale
    run_and_wait(qtbot, widget)
    assert widget.output("error") is None
    assert widget.shown_result(stack).features is None
    assert _scene(widget, stack).method_calls == {AUTO.method: 1}


def test_the_thesis_method_always_computes_the_maps(viewer, open_sample, add_widget, qtbot):
    open_sample("leaves")
    widget = add_widget("Segment by material")  # thesis preset
    widget.set_params(**FAST)
    assert widget.thesis_maps.value and not widget.thesis_maps.enabled
    run_and_wait(qtbot, widget)
    assert widget.output("error") is not None
    assert "mean reconstruction error" in widget.status.value
    widget.preset.value = "auto"  # another method: the user's choice (off) comes back
    assert widget.thesis_maps.enabled and not widget.thesis_maps.value
    widget.thesis_maps.value = True
    widget.preset.value = "thesis"
    assert widget.thesis_maps.value and not widget.thesis_maps.enabled
    widget.preset.value = "auto"
    assert widget.thesis_maps.enabled and widget.thesis_maps.value


def test_export_and_plots_of_a_result_without_the_maps(
    viewer, open_sample, add_widget, qtbot, tmp_path
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    assert widget.shown_result(stack).features is None
    # the folder is polarseg segment --out's for the default: no thesis maps
    assert widget.export_results(tmp_path / "out")
    wait_idle(qtbot, widget)
    assert error_messages() == [] and widget.status.value.startswith("exported")
    out = tmp_path / "out"
    want = engine_result(stack, widget.params())
    labels = tifffile.imread(out / "labels.tif")
    np.testing.assert_array_equal(labels, widget.output("segments").data - 1)
    assert np.array_equal(np.unique(labels), np.unique(want.labels))
    assert not (out / "reconstruction_error.tif").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == AUTO.method and summary["n_components"] is None
    assert summary["thesis_maps"] is False
    # with plots, the maps they are drawn from are computed for the export
    assert widget.export_results(tmp_path / "plots", plots=True)
    wait_idle(qtbot, widget)
    assert (tmp_path / "plots" / "reconstruction_error.tif").exists()
    summary = json.loads((tmp_path / "plots" / "summary.json").read_text())
    assert summary["n_components"] is not None
    assert _scene(widget, stack).method_calls == {AUTO.method: 1}

    plots = add_widget("Polarisation plots")
    plots.stack_layer.value = stack
    run_and_wait(qtbot, plots)  # "Load segmentation": the Segment widget's result
    assert plots.result is widget.shown_result(stack)
    assert "no PCA features" in plots.status.value
    plots.plot.value = "variance"
    assert "no PCA features" in plots.figure.texts[0].get_text()
    plots.plot.value = "scatter_dop"  # Î, ρ and the labels: drawn
    assert plots.figure.axes and not plots.figure.texts
    assert plots.add_component_maps() == []
    assert plots.status.value.startswith("error: no PCA features")


def test_a_parameter_the_method_does_not_read_only_reshows(
    viewer, open_sample, add_widget, qtbot, tmp_path
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)
    widget.set_params(**FAST)
    run_and_wait(qtbot, widget)
    widget.live.value = True
    wait_idle(qtbot, widget)
    runs, segments = widget._slot.run_id, widget.output("segments")
    data = segments.data
    widget.set_params(refractive_index=1.6, window=12)  # the superpixel method reads neither
    wait_idle(qtbot, widget)
    assert widget._slot.run_id == runs  # no worker started
    assert widget.output("segments") is segments and segments.data is data
    assert "unchanged" in widget.status.value and "refractive_index" in widget.status.value
    meta = segments.metadata["polarseg_params"]
    assert meta["refractive_index"] == 1.6 and meta["method_params"]["thesis"]["window"] == 12
    # the export records the parameters shown, its maps (θ) computed for them
    assert widget.export_results(tmp_path / "out")
    wait_idle(qtbot, widget)
    params = json.loads((tmp_path / "out" / "params.json").read_text())["params"]
    assert params["refractive_index"] == 1.6
    assert params["method_params"]["thesis"]["window"] == 12
    widget.set_params(n_segments=4)  # read: it runs
    wait_idle(qtbot, widget)
    assert widget._slot.run_id == runs + 1
    assert widget.shown_result(stack).n_segments == 4


class Halves:
    """A toy method: left half 0, right half 1 (reads nothing but the image)."""

    name = "halves"
    title = "left and right halves"
    reads: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()

    def stages(self, params):
        return ("halving",)

    def segment(self, scene, params, inputs, run):
        run.begin("halving")
        h, w = scene.shape
        labels = np.zeros((h, w), dtype=np.int32)
        labels[:, w // 2 :] = 1
        return MethodOutput(labels, record={"halves": 2})


@pytest.fixture
def toy_method():
    register_method(Halves())
    yield Halves.name
    unregister_method(Halves.name)


def test_a_registered_method_is_offered_and_runs(
    viewer, open_sample, add_widget, qtbot, toy_method
):
    stack = open_sample("leaves")
    widget = add_widget("Segment by material", preset=None)  # opened after registering
    assert toy_method in widget.method.choices
    widget.method.value = toy_method
    run_and_wait(qtbot, widget)
    assert error_messages() == []
    labels = widget.output("segments").data
    w = labels.shape[1]
    assert set(np.unique(labels[:, : w // 2])) == {1} and set(np.unique(labels[:, w // 2 :])) == {2}
    assert widget.output("error") is None
    assert widget.shown_result(stack).method == toy_method
    assert widget.output("segments").metadata["polarseg_params"]["method"] == toy_method
