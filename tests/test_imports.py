"""The engine and the package import without napari, magicgui or Qt; the engine without
its methods (they register on the first lookup) or scikit-image and scikit-learn."""

import json
import subprocess
import sys

import pytest

GUI_ROOTS = ["napari", "magicgui", "qtpy", "PyQt5", "PyQt6", "PySide2", "PySide6", "vispy"]


@pytest.mark.parametrize(
    "module",
    [
        "napari_polarseg",
        "napari_polarseg.engine",
        "napari_polarseg.engine.pipeline",
        "napari_polarseg.outputs",
        # the widgets' headless session layer (pipeline store, jobs, results, texts)
        "napari_polarseg.widgets.session",
    ],
)
def test_import_loads_no_gui_module(module):
    code = (
        "import sys, json\n"
        f"import {module}\n"
        f"roots = {GUI_ROOTS!r}\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} & set(roots))))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert out == "[]", f"{module} imported GUI modules: {out}"


def test_engine_sources_never_import_gui():
    import re
    from pathlib import Path

    import napari_polarseg.engine as eng

    pattern = re.compile(rf"^\s*(import|from)\s+({'|'.join(GUI_ROOTS)})\b(?!_)", re.M)
    for path in Path(eng.__file__).parent.rglob("*.py"):
        assert not pattern.search(path.read_text()), path


def _fresh(code: str) -> str:
    """The last stdout line of ``code`` run in a fresh interpreter."""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    return out.stdout.strip().splitlines()[-1]


def test_importing_the_engine_loads_no_method_nor_scikit():
    """The light face: the methods register on the first lookup, not on import."""
    from napari_polarseg.engine.methods.registry import BUILT_IN

    code = (
        "import sys, json\n"
        "import napari_polarseg.engine\n"
        "roots = {m.split('.')[0] for m in sys.modules}\n"
        "own = [m for m in sys.modules if m.startswith('napari_polarseg')]\n"
        "print(json.dumps([sorted(roots & {'skimage', 'sklearn'}), own]))\n"
    )
    heavy, own = json.loads(_fresh(code))
    assert heavy == []
    assert len(own) <= 15, own
    methods = {f"napari_polarseg.engine.methods.{module}" for module, _ in BUILT_IN}
    assert not methods & set(own)


def test_the_first_lookup_registers_every_method_before_one_registered_from_outside():
    """A method registered from outside before any lookup comes after the built-in ones,
    in the registry, the choices of ``method`` (menus, params.json) and --help."""
    from napari_polarseg.engine.methods.registry import BUILT_IN, unsupervised_names

    code = (
        "import json, contextlib, io\n"
        "from napari_polarseg.engine import register_method\n"
        "class Toy:\n"
        "    name, title, reads, inputs = 'toy', 'a toy', (), ()\n"
        "    def stages(self, params): return ('toy',)\n"
        "    def segment(self, scene, params, inputs, run): raise NotImplementedError\n"
        "register_method(Toy())\n"
        "from napari_polarseg.engine import method_names\n"
        "from napari_polarseg.engine.params import PARAM_SPECS, SegmentParams\n"
        "from napari_polarseg import cli\n"
        "text = io.StringIO()\n"
        "with contextlib.redirect_stdout(text), contextlib.suppress(SystemExit):\n"
        "    cli.main(['segment', '--help'])\n"
        "SegmentParams.from_json(json.dumps({'method': 'valid_superpixels', 'n_segments': 0}))\n"
        "print(json.dumps([method_names(), PARAM_SPECS['method'].options(), text.getvalue()]))\n"
    )
    names, choices, help_text = json.loads(_fresh(code))
    built_in = _built_in_names(BUILT_IN)
    assert names == [*built_in, "toy"]
    # this process's registry may hold methods other tests registered: the built-in ones
    menu = [name for name in unsupervised_names() if name in built_in]
    assert choices == [*menu, "toy"]
    assert "{" + ",".join(choices) + "}" in help_text


def _built_in_names(built_in: tuple[tuple[str, str], ...]) -> list[str]:
    """The registry names of the built-in methods (their class's ``name``)."""
    import importlib

    return [
        getattr(importlib.import_module(f"napari_polarseg.engine.methods.{m}"), c).name
        for m, c in built_in
    ]
