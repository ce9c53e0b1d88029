"""The engine and the package import without napari, magicgui or Qt."""

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
