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
    assert materials.folder_seeds(tmp_path) == [101]
    materials.run(args, tmp_path / "no-real-frames", "cmd")
    out = capsys.readouterr().out
    assert f"{materials.RENDER_SETS['unseen'].title}, seeds 101–101" in out
    assert "| scene_101 | 2 |" in out
    assert f"- {materials.RENDER_SETS['unseen'].title}, mean" in out and "target 0.5" in out
    assert "development half" not in out


def test_development_renders_get_means_by_number_of_materials(tmp_path, capsys):
    """``--dev-renders``: a development set prints the means over all its scenes and
    over those of each number of materials (no line per scene) and no target verdict;
    ``--two-materials`` is a held-out set, read against the test half's target."""
    dev, two = tmp_path / "dev", tmp_path / "two"
    for folder in (dev, two):
        folder.mkdir()
        _rendered_folder(folder)
    (dev / "scene_0.npz").rename(dev / "scene_1000.npz")
    with np.load(dev / "scene_1000.npz") as f:  # a second scene, its right third a third class
        labels = f["labels"].copy()
        labels[:, 48:][labels[:, 48:] == 1] = 3
        np.savez(dev / "scene_1001.npz", stack=f["stack"], angles=f["angles"], labels=labels)
    (two / "scene_0.npz").rename(two / "scene_600.npz")
    parser = argparse.ArgumentParser()
    materials.add_arguments(parser)
    args = parser.parse_args(
        ["--dev-renders", "--two-materials", "--bounds", "none"]
        + ["--dev-renders-dir", str(dev), "--two-materials-dir", str(two)]
    )
    assert materials.chosen_render_sets(args) == ["dev-renders", "two-materials"]
    materials.run(args, tmp_path / "no-real-frames", "cmd")
    out = capsys.readouterr().out
    dev_title = materials.RENDER_SETS["dev-renders"].title
    two_title = materials.RENDER_SETS["two-materials"].title
    assert f"{dev_title}, 2 scenes" in out
    assert "| all | 2 |" in out and "| 2 materials | 1 |" in out and "| 3 materials | 1 |" in out
    assert "| scene_1000 |" not in out  # means only
    assert f"{two_title}, seeds 600–600" in out and "| scene_600 | 2 |" in out
    verdicts = out.split("against issue 24's targets")[1]
    dev_line = next(line for line in verdicts.splitlines() if line.startswith(f"- {dev_title}"))
    two_line = next(line for line in verdicts.splitlines() if line.startswith(f"- {two_title}"))
    assert "target" not in dev_line and "target 0.5" in two_line


def test_degenerate_cause_tells_a_segment_spent_on_the_sky_from_materials_joined():
    """The sky (0) is 30 % of a frame of two materials (1, 2). A result spending one of
    its two segments on the sky is degenerate over the scored pixels because of it; one
    that puts the sky and nearly all of both materials together joins the materials."""
    truth = np.ones((10, 10), int)
    truth[:3] = 0
    truth[3:, 5:] = 2
    sky_segment = (truth == 0).astype(int)
    assert materials.degenerate(sky_segment, truth)
    assert materials.degenerate_cause(sky_segment, truth) == "the sky took a segment"
    joined = np.zeros_like(truth)
    joined[9, :3] = 1  # three pixels of material 1 apart; sky and the rest together
    assert materials.degenerate(joined, truth)
    assert materials.degenerate_cause(joined, truth) == "the materials share a segment"
    right = (truth == 2).astype(int)
    assert not materials.degenerate(right, truth)


def test_sky_counted_asks_one_segment_more_only_where_a_sky_is_seen(tmp_path, capsys):
    """A render whose truth leaves > 2 % unlabelled is also scored with k + 1 segments
    (``default, sky counted``); one without a sky keeps the default's own figure there,
    and the verdict says on how many frames the sky was counted."""
    _rendered_folder(tmp_path)
    with np.load(tmp_path / "scene_0.npz") as f:
        labels = f["labels"].copy()
        labels[:8] = 0  # the top rows unlabelled: a sky of 12 %
        np.savez(tmp_path / "scene_1.npz", stack=f["stack"], angles=f["angles"], labels=labels)
    rows = materials.rendered_rows([0, 1], "none", tmp_path)
    no_sky, sky = rows
    assert materials.SKY_COUNTED not in no_sky["seconds"]
    assert no_sky[materials.SKY_COUNTED] == no_sky["auto (default)"]
    assert materials.SKY_COUNTED in sky["seconds"]
    verdict = materials.verdict_lines({"dev": rows})
    assert "with the sky counted as a segment (k + 1 on the 1 of 2 frames" in verdict
    assert materials.SKY_COUNTED in materials.table(rows, "t")
    real = materials.score_frame("real", *_frame(tmp_path / "scene_1.npz"), 2, "none")
    assert materials.SKY_COUNTED not in real  # hand-drawn truth: unlabelled is not a sky


def _frame(path: Path):
    with np.load(path) as f:
        return f["stack"], np.deg2rad(f["angles"]), f["labels"].astype(np.int32)
