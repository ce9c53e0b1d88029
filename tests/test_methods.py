"""Methods as peers (issue 22): one Scene, a registry, the mask honoured by every method,
reruns only for the parameters a method reads, progress from the method's own stages."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from sklearn.metrics import adjusted_rand_score
from test_auto_preset import ANGLES, planted_stack

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import (
    MethodOutput,
    PolarsegError,
    Scene,
    method_names,
    register_method,
)
from napari_polarseg.engine.errors import Cancelled
from napari_polarseg.engine.methods import unregister_method
from napari_polarseg.engine.params import AUTO, PARAM_SPECS, RECOMMENDED

K = 3


def _scribbles(truth: np.ndarray, columns: slice) -> np.ndarray:
    """A short horizontal stroke in each material, inside ``columns``."""
    strokes = np.zeros(truth.shape, dtype=np.int32)
    for value in np.unique(truth):
        rows, cols = np.nonzero(truth == value)
        keep = (cols >= (columns.start or 0)) & (cols < columns.stop)
        if not keep.any():
            continue
        r, c = rows[keep][len(rows[keep]) // 2], cols[keep][len(cols[keep]) // 2]
        strokes[r, max(c - 3, 0) : c + 3] = value + 1
    return strokes


def _with_bright_patch(stack: np.ndarray, outside: np.ndarray) -> np.ndarray:
    """The stack with a bright, strongly polarised patch everywhere in ``outside``."""
    patch = 0.5 * 3000 * (1 + 0.8 * np.cos(2 * ANGLES - 2 * 0.4))
    out = stack.copy()
    out[:, outside] = np.round(patch)[:, None].astype(stack.dtype)
    return out


@pytest.mark.parametrize(
    "method", ["superpixels", "valid_superpixels", "superpixel_consensus", "thesis", "classifier"]
)
def test_labels_inside_the_mask_do_not_depend_on_the_outside(method):
    stack, truth = planted_stack(K)
    w = stack.shape[2]
    region = np.zeros(truth.shape, dtype=bool)
    region[:, : int(0.6 * w)] = True
    params = AUTO.replace(n_segments=K, method=AUTO.method if method == "classifier" else method)
    inputs = None
    if method == "classifier":
        inputs = {"scribbles": _scribbles(truth, slice(0, int(0.6 * w)))}
    first = Scene(stack, ANGLES, region).segment(params, inputs)
    second = Scene(_with_bright_patch(stack, ~region), ANGLES, region).segment(params, inputs)
    assert first.method == second.method == method
    inside = first.labels[region], second.labels[region]
    assert adjusted_rand_score(*inside) == pytest.approx(1.0)
    np.testing.assert_array_equal(*inside)


def test_a_parameter_a_method_does_not_read_does_not_rerun_it():
    stack, truth = planted_stack(K)
    scene = Scene(stack, ANGLES)
    p = AUTO.replace(n_segments=K)
    first = scene.segment(p)
    for change in ({"refractive_index": 1.7}, {"scale": 5.0}, {"window": 8}, {"degree": 4}):
        again = scene.segment(p.replace(**change))
        np.testing.assert_array_equal(again.labels, first.labels)
    assert scene.method_calls == {AUTO.method: 1}
    assert scene.pipeline.calls["harmonics"] == 0  # no thesis map was asked for
    scene.segment(p.replace(n_segments=K + 1))
    assert scene.method_calls == {AUTO.method: 2}  # n_segments is read
    # the classifier reads the image and its strokes, not the block parameters
    strokes = _scribbles(truth, slice(0, stack.shape[2]))
    scene.segment(p, {"scribbles": strokes})
    scene.segment(p.replace(window=8, n_segments=2), {"scribbles": strokes})
    assert scene.method_calls["classifier"] == 1
    scene.segment(p, {"scribbles": strokes.copy()})
    assert scene.method_calls["classifier"] == 1  # the same strokes, another array
    # the thesis reads the refractive index
    scene.segment(RECOMMENDED.replace(n_segments=K))
    scene.segment(RECOMMENDED.replace(n_segments=K, refractive_index=1.7))
    assert scene.method_calls["thesis"] == 2


@pytest.mark.parametrize("method", method_names())
def test_progress_names_each_stage_as_it_starts_and_reaches_the_total(method):
    """Every built-in method (the thesis under its own preset, the others under the
    default's) reports each of its stages in order, as the progress bar shows them."""
    stack, truth = planted_stack(K)
    scene = Scene(stack, ANGLES)
    params = (RECOMMENDED if method == "thesis" else AUTO).replace(method=method, n_segments=K)
    inputs = {"scribbles": _scribbles(truth, slice(0, 999))} if method == "classifier" else None
    seen: list[tuple[str, float, int]] = []
    scene.segment(params, inputs, progress=lambda s, i, n: seen.append((s, i, n)))
    names = scene.stages(params, inputs, maps=method == "thesis", reconstruction=method == "thesis")
    total = len(names)
    assert {n for _, _, n in seen} == {total}
    started = list(dict.fromkeys(s for s, _, _ in seen if s != "done"))
    assert started == names
    indices = [i for _, i, _ in seen]
    assert indices == sorted(indices)  # never backwards
    assert max(np.diff(indices)) <= 1.0  # no jumps over a stage
    assert seen[-1] == ("done", float(total), total)


def test_cancel_stops_a_chunked_stage_inside_it():
    stack, _ = planted_stack(K)
    scene = Scene(stack, ANGLES)
    calls = []

    def cancel() -> bool:
        calls.append(1)
        return scene.pipeline.calls["normals"] == 1 and len(calls) > 4

    with pytest.raises(Cancelled):
        scene.segment(RECOMMENDED.replace(window=4, degree=6), cancel=cancel)
    assert scene.pipeline.calls["harmonics"] == 0  # stopped inside it


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


def test_a_registered_method_is_offered_by_the_cli_and_written_in_the_folder(
    toy_method, tmp_path, capsys
):
    assert toy_method in method_names()
    assert toy_method in PARAM_SPECS["method"].options()
    stack, _ = planted_stack(2)
    path = tmp_path / "planted.tif"
    pio.write_stack_tiff(path, stack, np.rad2deg(ANGLES))
    out = tmp_path / "out"
    code = cli.main(["segment", str(path), "--method", toy_method, "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    assert json.loads((out / "params.json").read_text())["params"]["method"] == toy_method
    assert json.loads((out / "summary.json").read_text())["method"] == toy_method
    labels = tifffile.imread(out / "labels.tif")
    assert set(np.unique(labels[:, : stack.shape[2] // 2])) == {0}
    assert set(np.unique(labels[:, stack.shape[2] // 2 :])) == {1}


def test_an_unknown_method_is_refused_with_the_known_ones():
    stack, _ = planted_stack(2)
    with pytest.raises(PolarsegError, match="unknown segmentation method 'nope'; known: "):
        Scene(stack, ANGLES).segment(AUTO.replace(method="nope"))
    parser = cli.build_parser()
    with pytest.raises(cli.UsageError, match="invalid choice: 'nope'"):
        parser.parse_args(["segment", "x.tif", "--out", "o", "--method", "nope"])
