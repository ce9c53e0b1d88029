"""The material tables' markdown block (benchmarks/materials.py ``--markdown``).

One tiny rendered scene in a temporary folder stands in for the 24 Mitsuba scenes, so
the whole generator runs in seconds: the block between the markers of a copy of
``docs/quality.md`` is rewritten with the development-half table, the k found by
itself and the verdicts, and the text around it is kept.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
import materials  # noqa: E402

from napari_polarseg.engine.synthetic.scenes import make_scene  # noqa: E402


def _rendered_folder(folder: Path) -> None:
    """``scene_0.npz`` in the rendered scenes' format: a small synthetic scene, its
    labels shifted by one (0 = unscored sky, as in the Mitsuba set)."""
    sc = make_scene("camouflage", shape=(64, 72), seed=0)
    np.savez(
        folder / "scene_0.npz",
        stack=sc.stack,
        angles=np.rad2deg(sc.angles),
        labels=(sc.labels + 1).astype(np.uint8),
    )


def _args(rendered_dir: Path, page: Path) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    materials.add_arguments(parser)
    return parser.parse_args(
        ["--rendered", "dev", "--bounds", "none", "--rendered-dir", str(rendered_dir)]
        + ["--markdown", str(page)]
    )


def test_docs_quality_has_one_material_block():
    text = (REPO / "docs" / "quality.md").read_text(encoding="utf-8")
    assert text.count(materials.BEGIN) == 1 and text.count(materials.END) == 1
    assert text.index(materials.BEGIN) < text.index(materials.END)


def test_markdown_block_is_rewritten_with_the_tables(tmp_path, capsys):
    _rendered_folder(tmp_path)
    page = tmp_path / "quality.md"
    page.write_text(
        f"# before\n\n{materials.BEGIN}\nold figures 0.123\n{materials.END}\n\nafter\n",
        encoding="utf-8",
    )
    command = "python benchmarks/evaluate_unsupervised.py --rendered dev --markdown x.md"
    materials.run(_args(tmp_path, page), tmp_path / "no-real-frames", command)
    text = page.read_text(encoding="utf-8")
    assert text.startswith(f"# before\n\n{materials.BEGIN}\n")
    assert text.endswith(f"{materials.END}\n\nafter\n")
    block = text.split(materials.BEGIN)[1].split(materials.END)[0]
    assert "old figures" not in block
    assert f"`{command}`" in block
    assert "development half (seeds 0–11)" in block
    assert "| scene_0 | 2 |" in block  # the scene's row, k = 2 classes scored
    assert "| **mean, all** |" in block
    assert "scene_0: true 2, found" in block  # the k found by itself
    assert "the plain baseline" in block  # the verdicts
    assert "| scene_0 | 2 |" in capsys.readouterr().out  # printed as well


def test_markdown_needs_the_markers(tmp_path):
    _rendered_folder(tmp_path)
    page = tmp_path / "quality.md"
    page.write_text("# no block here\n", encoding="utf-8")
    with pytest.raises(SystemExit):
        materials.run(_args(tmp_path, page), tmp_path / "no-real-frames", "cmd")
    assert page.read_text(encoding="utf-8") == "# no block here\n"


def test_unseen_renders_get_a_table_and_a_verdict_of_their_own(tmp_path, capsys):
    """``--unseen``: every ``scene_<seed>.npz`` of the held-out folder is scored, in seed
    order, in a table and a verdict line of its own; the halves are not run."""
    _rendered_folder(tmp_path)
    (tmp_path / "scene_0.npz").rename(tmp_path / "scene_101.npz")
    parser = argparse.ArgumentParser()
    materials.add_arguments(parser)
    args = parser.parse_args(["--unseen", "--bounds", "none", "--unseen-dir", str(tmp_path)])
    assert materials.subset_only(args)
    assert materials.unseen_seeds(tmp_path) == [101]
    materials.run(args, tmp_path / "no-real-frames", "cmd")
    out = capsys.readouterr().out
    assert f"{materials.UNSEEN_NAME}, seeds 101–101" in out
    assert "| scene_101 | 2 |" in out
    assert f"- {materials.UNSEEN_NAME}, mean" in out and "target 0.5" in out
    assert "development half" not in out
