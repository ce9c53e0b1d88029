"""Each method declares its own parameters (issue 38, point 1).

A toy method with one parameter, registered from outside the package in this file (one
dataclass, one class, one ``register_method`` call), is found in ``polarseg segment
--help`` (its own group), in ``params.json`` (round trip), in the Scene's cache key and
in the parameter sweep (engine and ``polarseg sweep --vary``); the plugin's controls are checked in
``tests/gui/test_param_controls.py`` with the same toy (:func:`toy_registered`).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score
from test_auto_preset import ANGLES, planted_stack

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import PolarsegError, Scene, SegmentParams
from napari_polarseg.engine.analysis.param_sweep import param_sweep, sweepable
from napari_polarseg.engine.methods import (
    MethodOutput,
    method_names,
    register_method,
    unregister_method,
)
from napari_polarseg.engine.param_spec import param_field
from napari_polarseg.engine.params import PRESETS


@dataclass(frozen=True)
class ToyParams:
    """The toy method's one parameter."""

    share: float = param_field(
        0.5,
        help="Share of the pixels, darkest first, in the first segment, in (0, 1)",
        flag="--toy-share",
        metavar="Q",
        label="toy share",
        minimum=0.05,
        maximum=0.95,
        step=0.05,
        decimals=2,
        effect="How much of the frame the toy's first segment takes",
    )


class IntensityShare:
    """A toy method: the darkest ``share`` of the pixels, then the rest."""

    name = "toy_share"
    title = "toy: darkest share"
    reads: tuple[str, ...] = ("fit",)  # its own parameter is left out on purpose
    inputs: tuple[str, ...] = ()
    params_class = ToyParams

    def stages(self, params: SegmentParams) -> tuple[str, ...]:
        return ("split",)

    def segment(self, scene, params, inputs, run) -> MethodOutput:
        run.begin("split")
        intensity = scene.polarisation(params).intensity
        share = params.params_of(self.name).share
        return MethodOutput((intensity > np.quantile(intensity, share)).astype(np.int32))


@contextmanager
def toy_registered() -> Iterator[str]:
    """The toy method registered while the block runs (its name)."""
    register_method(IntensityShare())
    try:
        yield IntensityShare.name
    finally:
        unregister_method(IntensityShare.name)


@pytest.fixture
def toy() -> Iterator[str]:
    with toy_registered() as name:
        yield name


@pytest.fixture
def stack_file(tmp_path):
    stack, _ = planted_stack(2)
    path = tmp_path / "planted.tif"
    pio.write_stack_tiff(path, stack, np.rad2deg(ANGLES))
    return path


def _segment_help(capsys) -> str:
    assert cli.main(["segment", "--help"]) == 0
    return capsys.readouterr().out


def test_the_toy_parameter_has_a_flag_in_its_own_group(toy, capsys):
    text = _segment_help(capsys)
    group = text[text.index(f"method {toy} (toy: darkest share):") :]
    assert group.split("\n\n", 2)[1].lstrip().startswith("--toy-share Q")
    assert "Share of the pixels, darkest first" in group
    # one group per registered method, the thesis flags in the thesis group
    thesis = text[text.index("method thesis (") : text.index(f"method {toy} (")]
    assert "--window W" in thesis and "--degree L" in thesis
    shared = text[text.index("segmentation parameters:") : text.index("method superpixels (")]
    assert "--segments K" in shared and "--window" not in shared


def test_the_toy_flag_reaches_the_run_and_params_json(toy, stack_file, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["segment", str(stack_file), "--method", toy, "--toy-share", "0.2", "--out", str(out)]
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert "warning" not in capsys.readouterr().err
    written = json.loads((out / "params.json").read_text())["params"]
    assert written["method_params"][toy] == {"share": 0.2}
    # the file reproduces the run, and SegmentParams reads it back
    assert SegmentParams.from_dict(written).params_of(toy).share == 0.2
    again = tmp_path / "again"
    params_file = out / "params.json"
    code = cli.main(["segment", str(stack_file), "--params", str(params_file), "--out", str(again)])
    assert code == 0
    assert json.loads((again / "params.json").read_text())["params"] == written


def test_params_json_round_trip_of_the_toy(toy):
    params = SegmentParams(method=toy, share=0.3, n_segments=2)
    assert params.params_of().share == 0.3 and params.share == 0.3
    text = params.to_json()
    assert json.loads(text)["method_params"] == {toy: {"share": 0.3}}
    assert SegmentParams.from_json(text) == params
    # the toy's default is written too: the file says what the run used
    plain = SegmentParams(method=toy)
    assert json.loads(plain.to_json())["method_params"] == {toy: {"share": 0.5}}
    with pytest.raises(PolarsegError, match="unknown parameter"):
        SegmentParams.from_dict({"method": toy, "method_params": {toy: {"shares": 1}}})


def test_a_flag_the_chosen_method_does_not_read_is_named_in_one_warning(
    stack_file, tmp_path, capsys
):
    out = tmp_path / "out"
    code = cli.main(["segment", str(stack_file), "--window", "10", "--out", str(out), "-q"])
    assert code == 0
    err = capsys.readouterr().err.strip().splitlines()
    method = PRESETS["auto"].method
    assert err == [
        f"polarseg: warning: method {method} does not read --window (a parameter of method "
        "thesis); its labels are the same without it"
    ]
    # the thesis maps read the block parameters: asked for, no warning
    code = cli.main(
        ["segment", str(stack_file), "--window", "10", "--thesis-maps", "-q", "--out", str(out)]
    )
    assert code == 0 and "warning" not in capsys.readouterr().err
    written = json.loads((out / "params.json").read_text())["params"]
    assert written["method"] == method and written["method_params"]["thesis"]["window"] == 10


def test_the_cache_key_holds_the_method_parameters_it_does_not_name(toy):
    stack, _ = planted_stack(2)
    scene = Scene(stack, ANGLES)
    base = SegmentParams(method=toy, n_segments=2)
    low = scene.segment(base.replace(share=0.2)).labels
    high = scene.segment(base.replace(share=0.8)).labels
    assert low.mean() == pytest.approx(0.8, abs=0.02)
    assert high.mean() == pytest.approx(0.2, abs=0.02)
    assert scene.method_calls[toy] == 2
    scene.segment(base.replace(share=0.8, object_size=40))  # a field the toy does not read
    assert scene.method_calls[toy] == 2


def test_method_parameters_by_name_alone_still_work():
    """Backward compatibility: a block parameter named alone goes to the thesis method's
    parameters, as does a params.json with the block fields at the top level."""
    params = SegmentParams(method="thesis", window=8, degree=6)
    assert params.params_of("thesis").window == 8 and params.degree == 6
    assert params.replace(window=9).window == 9
    old = {"method": "surface_superpixels", "window": 16, "n_segments": 4}
    read = SegmentParams.from_dict(old)
    assert read.method == "surface_superpixels" and read.params_of("thesis").window == 16
    # a file written before the methods were peers (no method, block fields): the thesis
    assert SegmentParams.from_dict({"window": 16, "degree": 4}).method == "thesis"
    with pytest.raises(PolarsegError, match="unknown parameter"):
        SegmentParams(no_such_knob=1)


def test_a_params_class_is_checked_at_registration():
    class Clashing(IntensityShare):
        name = "clashing"

        @dataclass(frozen=True)
        class params_class:  # noqa: N801
            n_segments: int = param_field(3, help="x", flag="--n")

    with pytest.raises(PolarsegError, match="named as shared"):
        register_method(Clashing())
    assert "clashing" not in method_names()


def test_a_sweep_of_the_toy_parameter_gives_one_result_per_value(toy):
    stack, truth = planted_stack(2)
    base = SegmentParams(method=toy, n_segments=2)
    assert sweepable(base) == ("share", "fit")  # its own, then the shared one it reads
    result = param_sweep(stack, ANGLES, base, {"share": [0.2, 0.8]}, ground_truth=truth)
    low, high = result.cells
    assert (low.values, high.values) == ({"share": 0.2}, {"share": 0.8})
    assert low.ok and high.ok and not np.array_equal(low.labels, high.labels)
    assert low.labels.mean() == pytest.approx(0.8, abs=0.02)
    # the stability of each: the ARI with its one neighbour, the other
    assert low.stability == high.stability < 1
    assert low.stability == pytest.approx(
        adjusted_rand_score(low.labels.ravel(), high.labels.ravel())
    )
    assert result.best() == base.replace(share=result.best_cell().values["share"])
    with pytest.raises(PolarsegError, match="no parameter 'window' to sweep; its parameters"):
        param_sweep(stack, ANGLES, base, {"window": [8, 10]})


def test_polarseg_sweep_varies_the_toy_parameter(toy, stack_file, tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = ["sweep", str(stack_file), "--method", toy, "--vary", "share=0.2,0.8"]
    assert cli.main([*argv, "--segments", "2", "--out", str(out)]) == 0, capsys.readouterr().err
    rows = (out / "sweep.csv").read_text().splitlines()
    assert rows[0].startswith("share,n_segments,stability") and len(rows) == 3
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["axes"] == {"share": [0.2, 0.8]} and summary["method"] == toy
    best = SegmentParams.from_json((out / "best_params.json").read_text())
    assert best.method == toy and best.params_of().share in (0.2, 0.8)
    # the block grid is the thesis method's: another method is asked for its parameters
    code = cli.main(["sweep", str(stack_file), "--method", toy, "--out", str(tmp_path / "x")])
    assert code == 2 and "give --vary NAME=V,V,... (its parameters: share, fit)" in (
        capsys.readouterr().err
    )
