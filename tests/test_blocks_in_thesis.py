"""The w × w blocks stay inside the methods that cut them (the thesis method).

A method declares ``block_maps`` (:class:`~napari_polarseg.engine.methods.base.Segmenter`)
instead of being recognised by its name: the summary names the block grid, the memory
estimate counts blocks, the plugin shows the maps and the time series cuts blocks only
for such a method (the time series of the others: ``tests/test_timeseries.py``).
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest
from test_cli import ANGLES, H, W, two_material_scene

import napari_polarseg
from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import PolarsegError, Scene
from napari_polarseg.engine.limits import (
    DEFAULT_MAX_BYTES,
    ENV_VAR,
    check_pipeline_memory,
    estimate_pipeline_bytes,
)
from napari_polarseg.engine.methods import MethodOutput, register_method, unregister_method
from napari_polarseg.engine.params import AUTO, RECOMMENDED
from napari_polarseg.engine.registered import computes_block_maps
from napari_polarseg.widgets.session import wants_maps

PACKAGE = Path(napari_polarseg.__file__).parent
#: The one module that may recognise the thesis method by its name.
THESIS_MODULE = PACKAGE / "engine" / "methods" / "thesis.py"
#: A 24 MP frame of a 4-angle camera (frames, rows, columns).
BIG = (4, 4096, 6120)


def _operands(node: ast.Compare) -> list[ast.expr]:
    return [node.left, *node.comparators]


def thesis_name_comparisons(source: str) -> list[str]:
    """Every ``== "thesis"`` / ``!= "thesis"`` whose other side is a method or its name
    (``params.method``, ``method.name``, ``str(method)``, …), as source text. The
    thesis *feature kind* and *coefficient estimator* share the word and are not
    methods (``kind == "thesis"``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Compare):
            continue
        if not any(isinstance(op, (ast.Eq, ast.NotEq)) for op in node.ops):
            continue
        operands = _operands(node)
        thesis = [o for o in operands if isinstance(o, ast.Constant) and o.value == "thesis"]
        others = [ast.unparse(o) for o in operands if o not in thesis]
        if thesis and any("method" in text or text.endswith(".name") for text in others):
            found.append(ast.unparse(node))
    return found


def test_the_scan_finds_method_name_comparisons():
    source = (
        'a = params.method == "thesis"\n'
        "b = 'thesis' != result.method\n"
        'c = method.name == "thesis"\n'
        'd = str(method) == "thesis"\n'
        'e = kind == "thesis"\n'
        'f = method not in ("thesis", "ridge")\n'
    )
    assert len(thesis_name_comparisons(source)) == 4


def test_no_method_name_comparison_with_thesis_outside_its_module():
    hits = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == THESIS_MODULE:
            continue
        found = thesis_name_comparisons(path.read_text(encoding="utf-8"))
        if found:
            hits[str(path.relative_to(PACKAGE))] = found
    assert hits == {}


def test_only_the_thesis_method_declares_block_maps():
    assert computes_block_maps("thesis")
    assert not computes_block_maps(AUTO.method)
    assert not computes_block_maps("no such method")


@pytest.fixture
def scene_tif(tmp_path):
    stack, _, _ = two_material_scene()
    path = tmp_path / "scene.tif"
    pio.write_stack_tiff(path, np.round(stack).astype(np.uint16), ANGLES)
    return path


def _summary(tmp_path: Path, name: str, *argv: str) -> dict:
    out = tmp_path / name
    assert cli.main(["segment", *argv, "--out", str(out), "--segments", "2"]) == 0
    return json.loads((out / "summary.json").read_text())


def test_a_default_run_summary_has_no_block_keys(tmp_path, scene_tif):
    default = _summary(tmp_path, "default", str(scene_tif))
    assert default["method"] == AUTO.method
    assert "n_blocks" not in default and "block_grid" not in default
    assert default["n_segments"] == 2  # the rest of the summary is there
    # the thesis method and a run asked for the thesis maps name the block grid
    thesis = _summary(tmp_path, "thesis", str(scene_tif), "--preset", "recommended")
    grid = [H // RECOMMENDED.window, W // RECOMMENDED.window]
    assert thesis["block_grid"] == grid and thesis["n_blocks"] == grid[0] * grid[1]
    maps = _summary(tmp_path, "maps", str(scene_tif), "--thesis-maps")
    assert maps["method"] == AUTO.method and maps["block_grid"] == grid


def test_the_default_on_a_24_mp_stack_is_not_refused_by_the_thesis_estimate(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    needed = check_pipeline_memory(BIG, AUTO)  # the default: no block estimate
    assert needed == estimate_pipeline_bytes(BIG, AUTO) < DEFAULT_MAX_BYTES
    # the thesis method with the same window and degree is refused by its blocks
    with pytest.raises(PolarsegError, match=r"window 12 \(173910 blocks\) and degree 8"):
        check_pipeline_memory(BIG, RECOMMENDED)
    # and so is the default when the thesis maps are asked for
    with pytest.raises(PolarsegError, match="173910 blocks"):
        check_pipeline_memory(BIG, AUTO, blocks=True)
    assert estimate_pipeline_bytes(BIG, AUTO) < estimate_pipeline_bytes(BIG, AUTO, blocks=True)


class Quarters:
    """A toy method registered from outside: four quadrants; ``block_maps`` on demand."""

    name = "quarters"
    title = "four quadrants"
    reads: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()

    def stages(self, params):
        return ("quartering",)

    def segment(self, scene, params, inputs, run):
        run.begin("quartering")
        h, w = scene.shape
        rows, cols = np.mgrid[0:h, 0:w]
        return MethodOutput(((rows >= h // 2) * 2 + (cols >= w // 2)).astype(np.int32))


@pytest.mark.parametrize("declared", [None, True])
def test_a_method_from_outside_declares_its_block_maps_or_has_none(declared):
    method = Quarters()
    if declared is not None:
        method.block_maps = declared
    register_method(method)
    try:
        blocks = bool(declared)
        assert computes_block_maps("quarters") is blocks
        params = AUTO.replace(method="quarters")
        stack, _, _ = two_material_scene()
        result = Scene(stack, np.deg2rad(ANGLES)).segment(params)
        assert (result.features is not None) is blocks  # the maps come with block_maps
        assert ("block_grid" in result.summary()) is blocks
        assert wants_maps(params) is blocks  # the plugin shows the maps of such a method
        estimate = estimate_pipeline_bytes(BIG, params)
        assert (estimate == estimate_pipeline_bytes(BIG, params, blocks=True)) is blocks
    finally:
        unregister_method("quarters")
    assert not computes_block_maps("quarters")
