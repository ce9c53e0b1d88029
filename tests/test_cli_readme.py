"""Issue 25: the README's ``polarseg`` commands run as written from a clone, on the
example inputs the repository ships, and the napari example starts from the plugin's
default preset."""

from __future__ import annotations

import importlib.util
import shlex
from pathlib import Path

import numpy as np
import pytest
import tifffile

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine.params import DEFAULT_PRESET, PRESETS

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
EXAMPLE_DATA = REPO / "examples" / "data"


def bash_commands(path: Path) -> list[str]:
    """Every command of the fenced ``bash`` blocks of ``path``: continuation lines
    joined, comments dropped."""
    commands, block, pending = [], False, ""
    for line in path.read_text(encoding="utf-8").splitlines():
        if not block:
            block = line.strip() == "```bash"
            continue
        if line.strip().startswith("```"):
            block = False
            continue
        text = pending + line.split("#", 1)[0].strip()
        if text.endswith("\\"):
            pending = text[:-1].strip() + " "
            continue
        pending = ""
        if text:
            commands.append(text)
    return commands


def polarseg_commands() -> list[list[str]]:
    """The README's ``polarseg`` (or ``.venv/bin/polarseg``) commands, split into words."""
    words = [shlex.split(c) for c in bash_commands(README)]
    return [w[1:] for w in words if Path(w[0]).name == "polarseg"]


def test_the_readme_has_polarseg_commands_on_shipped_inputs():
    commands = polarseg_commands()
    assert len(commands) >= 4
    for argv in commands:
        for word in argv:
            if "/" in word and Path(word).suffix:  # a path with an extension: an input
                assert (REPO / word).is_file(), f"README names {word}, which is not shipped"
    assert "stack.tif" not in README.read_text(encoding="utf-8").replace("leaves_stack.tif", "")


@pytest.mark.parametrize("argv", polarseg_commands(), ids=" ".join)
def test_every_readme_command_runs_as_written(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(REPO)
    argv = list(argv)
    out = argv.index("--out") + 1
    argv[out] = str(tmp_path / "result")
    code = cli.main([*argv, "-q"])
    _, err = capsys.readouterr()
    assert code == 0, err
    assert "warning" not in err
    assert (tmp_path / "result" / "labels.tif").is_file()


def test_the_shipped_examples_are_small_and_carry_their_angles():
    stack = EXAMPLE_DATA / "leaves_stack.tif"
    assert stack.stat().st_size <= 1_000_000
    data = pio.read_stack(stack)
    assert data.metadata["angles_from"] == "tiff"
    with np.load(REPO / "napari_polarseg" / "sample_data" / "leaves.npz") as sample:
        np.testing.assert_array_equal(data.stack, sample["stack"])
        np.testing.assert_array_equal(data.angles_deg, sample["angles"])
        truth = sample["labels"]
    strokes = tifffile.imread(EXAMPLE_DATA / "leaves_strokes.tif")
    assert strokes.shape == truth.shape
    painted = strokes > 0
    assert set(np.unique(strokes[painted])) == set(np.unique(truth) + 1)
    np.testing.assert_array_equal(strokes[painted], truth[painted] + 1)


def test_the_readme_says_napari_needs_a_display():
    text = " ".join(README.read_text(encoding="utf-8").split())
    assert "needs a display" in text and "aborts" in text


def test_the_napari_example_starts_from_the_plugins_default_preset():
    """Without a viewer: the example's parser (napari is imported only by its main)."""
    path = REPO / "examples" / "segment_in_napari.py"
    spec = importlib.util.spec_from_file_location("segment_in_napari", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    parser = example.build_parser()
    assert parser.get_default("preset") == DEFAULT_PRESET == "auto"
    (preset,) = [a for a in parser._actions if "--preset" in a.option_strings]
    assert list(preset.choices) == list(PRESETS)
    assert parser.parse_args([]).preset == DEFAULT_PRESET
