"""The family bench (benchmarks/evaluate_families.py, benchmarks/families.py): a tiny
render of each Mitsuba layout's format in a temporary folder stands in for a family's
half, so one row is scored end to end and the markdown block of a copy of
``docs/quality.md`` is rewritten with the summary, the floors and the per-frame table."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
import evaluate_families  # noqa: E402
import families  # noqa: E402

from napari_polarseg.engine.synthetic.scenes import make_scene  # noqa: E402


@pytest.fixture
def small_family(tmp_path, monkeypatch):
    """A ``small`` test half of one render: a synthetic leaves scene in the rendered
    files' format (labels + 1, with the instances of its leaves)."""
    sc = make_scene("leaves", shape=(64, 80), seed=0)
    folder = tmp_path / "renders_small_test"
    folder.mkdir()
    np.savez(
        folder / "scene_5100.npz",
        stack=sc.stack,
        angles=np.rad2deg(sc.angles),
        labels=(sc.labels + 1).astype(np.uint8),
        instances=sc.instances.astype(np.uint16),
    )
    sets = dict(families.RENDER_SETS)
    sets[("small", "test")] = (folder, "made by the test")
    monkeypatch.setattr(families, "RENDER_SETS", sets)
    return sc


def test_a_render_frame_reads_its_truth_and_object_size(small_family):
    (frame,) = families.frames("small", "test")
    assert frame.k == 3 and frame.family == "small" and frame.half == "test"
    assert frame.truth.min() == 1  # every pixel of the synthetic scene is a material
    # the truth's object size: the median equivalent diameter of the leaves' instances
    ids, areas = np.unique(small_family.instances[small_family.instances > 0], return_counts=True)
    areas = areas[areas >= 9]
    assert frame.object_size == pytest.approx(np.median(np.sqrt(4 * areas / np.pi)))


def test_each_test_round_reads_fresh_seeds():
    """Round 0 is the first draw's folders; round b >= 1 a folder and seeds of its own,
    disjoint from every other round and from the development seeds."""
    assert families.render_set("small", "test", 0) == families.RENDER_SETS[("small", "test")]
    folder, command = families.render_set("small", "test", 1)
    assert folder.name == "renders_small_test_b1"
    assert "--layout small --seeds 5200-5211 --out benchmarks/renders_small_test_b1" in command
    assert families.render_set("small", "dev", 3) == families.RENDER_SETS[("small", "dev")]
    seen: set[int] = set()
    for base in range(4):
        for family in ("objects", "small", "textured"):
            first, last = map(int, families.seed_range(family, "test", base).split("-"))
            seeds = set(range(first, last + 1))
            assert len(seeds) == families.SEEDS_PER_HALF and not seeds & seen
            seen |= seeds
    for family in ("small", "textured"):
        first, last = map(int, families.seed_range(family, "dev").split("-"))
        assert not set(range(first, last + 1)) & seen


def test_missing_renders_are_reported_not_fatal(tmp_path, monkeypatch, capsys):
    sets = dict(families.RENDER_SETS)
    sets[("textured", "dev")] = (tmp_path / "none", "render_scenes.py ...")
    monkeypatch.setattr(families, "RENDER_SETS", sets)
    assert list(families.frames("textured", "dev")) == []
    assert "no renders in" in capsys.readouterr().out


def test_one_command_scores_and_writes_the_block(small_family, tmp_path):
    page = tmp_path / "quality.md"
    page.write_text(
        f"before\n{evaluate_families.BEGIN}\nold\n{evaluate_families.END}\nafter\n",
        encoding="utf-8",
    )
    argv = ["--families", "small", "--halves", "test", "--rounds", "1", "--markdown", str(page)]
    assert evaluate_families.main(argv) == 0
    text = page.read_text(encoding="utf-8")
    assert text.startswith("before\n") and text.endswith("after\n") and "old" not in text
    assert "| small | test | 1 |" in text  # the summary line of the family's half
    assert "- small (test): default " in text  # the floors and targets
    assert "scene_5100" in text  # the per-frame table of a test half
    rows = [line for line in text.splitlines() if line.startswith("| scene_5100")]
    cells = rows[0].split(" | ")
    values = [float(c.rstrip("‡†")) for c in cells[2:-1] if c not in ("–",)]
    assert all(-1.0 <= v <= 1.0 for v in values)  # ARIs


def test_scribble_bound_learns_the_left_half_and_scores_the_right():
    """Three materials in horizontal bands (each in both halves of the frame), apart in
    intensity and ρ under 1 % noise: the scribble classifier given the left half's
    truth labels the right half's materials (ARI near 1); given a truth that is noise,
    it cannot (ARI near 0)."""
    from napari_polarseg.engine import Pipeline

    rng = np.random.default_rng(0)
    angles = np.deg2rad([0.0, 45.0, 90.0, 135.0])
    rows, cols = np.mgrid[0:96, 0:128]
    truth = (rows * 3 // 96 + 1).astype(np.int32)
    level = np.array([0.0, 1.0, 0.6, 1.4])[truth] * (1 + 0.01 * rng.standard_normal(truth.shape))
    rho = np.array([0.0, 0.05, 0.2, 0.35])[truth]
    phase = (cols / 128.0) % np.pi
    stack = 0.5 * level * (1 + rho * np.cos(2 * angles[:, None, None] - 2 * phase))
    pipe = Pipeline(np.round(stack * 2000).astype(np.uint16), angles)
    assert evaluate_families.scribble_bound(pipe, truth) > 0.9
    noise = rng.integers(1, 3, truth.shape).astype(np.int32)
    assert abs(evaluate_families.scribble_bound(pipe, noise)) < 0.1
    # One material left of the middle (bands split left and right): only it can be
    # named, so the right half is all of it (ARI 0), not an error.
    split = np.where(cols < 64, 1, rows * 2 // 96 + 2).astype(np.int32)
    assert evaluate_families.scribble_bound(pipe, split) == 0.0
    assert np.isnan(evaluate_families.scribble_bound(pipe, np.zeros_like(truth)))
