"""The scene families of the bench (issue 37): each a development and a test half.

Every frame is a :class:`Frame`: the angle stack, its angles (radians), the truth
(0 = not scored, 1..k the materials), k, the truth's median object size in pixels
(``nan`` where the truth does not outline whole objects) and its family and half.

Families (:data:`FAMILIES`):

- ``objects`` (a): few large objects, the shared Mitsuba generator
  (``render_scenes.py --layout objects``). Development: the 24 shared scenes' seeds
  0–11. Test: fresh seeds (:func:`render_set`); without the first draw's renders, the
  shared seeds 12–23, marked as read before.
- ``small`` (b): 20–60 small flat objects of 2–3 materials (``--layout small``).
- ``textured`` (c): materials alike but for their surface texture (``--layout textured``).
- ``diffuse`` (d): the engine's own diffuse-polarisation generator at several object
  sizes (:mod:`diffuse_family`).

Each round reads a test half nobody has read: ``--test-base B`` draws the diffuse test
half from seeds 10 000 + 6 · B + j and the Mitsuba test halves from their first test
seed + 100 · B (:func:`render_set`: 4000, 5100 and 6100 for B = 0; 4100, 5200 and 6200
for B = 1).
- ``real`` (e): the hand-labelled real polarisation-camera frames (all four are
  development frames: none is kept aside on this machine).

The truth's object size: the median equivalent diameter of the rendered ``instances``
where a render has them, else of the connected components of the object materials
(labels ≥ 2; label 1 is the floor), else of the synthetic scenes' instances.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from materials import RENDERED_DIR, folder_seeds, labelled_real_frames

from napari_polarseg.engine.features.object_size import component_size, instance_size

HERE = Path(__file__).resolve().parent
REAL_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "polanalyser"
#: The families, in table order, with their titles.
FAMILIES = {
    "objects": "(a) few large objects (shared Mitsuba generator)",
    "small": "(b) many small objects (Mitsuba, --layout small)",
    "textured": "(c) texture-defined materials (Mitsuba, --layout textured)",
    "diffuse": "(d) the diffuse regime (the engine's synthetic generator)",
    "real": "(e) real polarisation-camera frames (hand-labelled)",
}
HALVES = ("dev", "test")

#: First seed of each Mitsuba family's halves; test round b (``test_base``) of a family
#: is the 12 seeds from its test start + 100 · b, so each round reads fresh scenes.
SEED_STARTS = {
    "objects": {"test": 4000},
    "small": {"dev": 5000, "test": 5100},
    "textured": {"dev": 6000, "test": 6100},
}
#: Seeds per Mitsuba half, and the stride between test rounds.
SEEDS_PER_HALF = 12
#: Development halves of more seeds: the small family's first 12 development scenes put
#: the default 0.15 above ``superpixels`` where two test rounds had the two level, so
#: its half is 24 scenes (seeds 5000–5023).
DEV_SEEDS = {"small": 24}
ROUND_STRIDE = 100
#: Folders of the first draw (round 0) under their historical names.
FIRST_FOLDERS = {
    ("objects", "test"): "renders_objects_fresh",
    ("small", "dev"): "renders_small_dev",
    ("small", "test"): "renders_small_test",
    ("textured", "dev"): "renders_textured_dev",
    ("textured", "test"): "renders_textured_test",
}


def seed_range(family: str, half: str, test_base: int = 0) -> str:
    """The seeds of a Mitsuba family's half, test round ``test_base``, as ``"A-B"``."""
    base = int(test_base) if half == "test" else 0
    first = SEED_STARTS[family][half] + ROUND_STRIDE * base
    count = DEV_SEEDS.get(family, SEEDS_PER_HALF) if half == "dev" else SEEDS_PER_HALF
    return f"{first}-{first + count - 1}"


def make_command(family: str, half: str, name: str, test_base: int = 0) -> str:
    """The ``render_scenes.py`` command that renders one half into ``benchmarks/name``."""
    seeds = seed_range(family, half, test_base)
    return f"render_scenes.py --layout {family} --seeds {seeds} --out benchmarks/{name}"


#: Render folders (git-ignored) of the Mitsuba families' first draw (round 0) → the
#: command that makes them.
RENDER_SETS = {key: (HERE / name, make_command(*key, name)) for key, name in FIRST_FOLDERS.items()}


def render_set(family: str, half: str, test_base: int = 0) -> tuple[Path, str]:
    """(folder, the command that makes it) of a Mitsuba family's half: the first draw's
    (:data:`RENDER_SETS`) or, for the test half of round ``test_base`` >= 1,
    ``renders_<family>_test_b<base>``."""
    if half != "test" or int(test_base) == 0:
        return RENDER_SETS[(family, half)]
    name = f"renders_{family}_test_b{int(test_base)}"
    return HERE / name, make_command(family, half, name, test_base)


#: The shared renders' halves (family ``objects``).
SHARED_HALVES = {"dev": tuple(range(12)), "test": tuple(range(12, 24))}


@dataclass(frozen=True)
class Frame:
    """One scored frame of the bench (module docstring)."""

    name: str
    stack: np.ndarray
    angles: np.ndarray
    truth: np.ndarray
    k: int
    object_size: float
    family: str
    half: str
    note: str = ""


def render_frame(path: Path, family: str, half: str, note: str = "") -> Frame:
    """A :class:`Frame` of a ``scene_<seed>.npz`` render (sky = 0, floor = 1, objects ≥ 2)."""
    with np.load(path, allow_pickle=False) as f:
        stack, angles = f["stack"], np.deg2rad(f["angles"])
        truth = f["labels"].astype(np.int32)
        instances = f["instances"] if "instances" in f.files else None
    classes = [c for c in np.unique(truth) if c >= 2]
    size = instance_size(instances) if instances is not None else component_size(truth, classes)
    k = len(np.unique(truth[truth > 0]))
    return Frame(path.stem, stack, angles, truth, k, float(size), family, half, note)


def render_frames(family: str, half: str, test_base: int = 0) -> Iterator[Frame]:
    """The frames of a Mitsuba family's half, test round ``test_base`` (missing folders
    are reported, not fatal)."""
    if family == "objects" and half == "dev":
        for seed in SHARED_HALVES["dev"]:
            yield render_frame(RENDERED_DIR / f"scene_{seed}.npz", family, half)
        return
    folder, command = render_set(family, half, test_base)
    seeds = folder_seeds(folder) if folder.is_dir() else []
    if not seeds and family == "objects" and int(test_base) == 0:
        print(f"{folder} is empty: the shared test seeds 12–23 (read before) instead")
        for seed in SHARED_HALVES["test"]:
            path = RENDERED_DIR / f"scene_{seed}.npz"
            yield render_frame(path, family, half, "read before")
        return
    if not seeds:
        print(f"{family} {half}: no renders in {folder} (make them: {command})")
    for seed in seeds:
        yield render_frame(folder / f"scene_{seed}.npz", family, half)


def diffuse_frames(half: str, test_base: int) -> Iterator[Frame]:
    """The engine-generated diffuse-regime frames (:mod:`diffuse_family`)."""
    from diffuse_family import family_scenes

    for s in family_scenes(half, test_base=test_base):
        yield Frame(s.name, s.stack, s.angles, s.labels, s.k, float(s.object_size), "diffuse", half)


def real_frames() -> Iterator[Frame]:
    """The hand-labelled real frames (development; their truth polygons lie inside the
    objects, so no object size is read from them)."""
    for name, stack, angles, truth, k in labelled_real_frames(REAL_DIR):
        yield Frame(Path(name).stem, stack, angles, truth, k, float("nan"), "real", "dev")


def frames(family: str, half: str, test_base: int = 0) -> Iterator[Frame]:
    """Every frame of one family's half."""
    if family == "diffuse":
        return diffuse_frames(half, test_base)
    if family == "real":
        return real_frames() if half == "dev" else iter(())
    return render_frames(family, half, test_base)


def standard_error(d: np.ndarray) -> float:
    """Standard error of the mean of the paired differences ``d`` (NaN under two)."""
    d = np.asarray(d, dtype=float)
    return float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else float("nan")


def add_check_round(ap: argparse.ArgumentParser) -> None:
    """The option ``--test-base B`` of a bench that chooses on the development halves:
    read round B's test halves instead, only to check a choice on a test half already
    read and reported (:func:`read_half` gives the half)."""
    ap.add_argument(
        "--test-base",
        type=int,
        default=None,
        metavar="B",
        help="read the test halves of round B instead (a check of a test half read before)",
    )


def read_half(test_base: int | None) -> str:
    """The half a bench with :func:`add_check_round` reads: ``"dev"`` without
    ``--test-base``, else ``"test"``."""
    return "dev" if test_base is None else "test"
