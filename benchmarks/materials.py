"""The material tables of evaluate.py and evaluate_unsupervised.py: rendered scenes and
hand-labelled real frames, one row per frame, the same columns for both.

- **Rendered scenes** (``../shared/data/rendered/scene_<seed>.npz``, Mitsuba 3, 24
  seeds): a *development* half (seeds 0–11: pick methods and parameters on these) and a
  *test* half (seeds 12–23: report on these, never tune on them). Every table names its
  half and ends with that half's means. k = the classes present (``labels > 0``); ARI
  over the pixels with ``labels > 0`` (the sky, 0, is ignored).
- **Real frames** (``napari_polarseg/sample_data/truth``, frames in
  ``../shared/data/polanalyser``): k = the truth file's classes; ARI over the labelled
  pixels.

Columns (:data:`COLUMNS`): ``intensity k-means`` (``baselines.intensity_kmeans``),
``smoothed k-means`` (``baselines.smoothed_kmeans``: k-means on 20 smoothed
polarisation features), the previous defaults (:data:`METHOD_COLUMNS` but the default's
own method: ``superpixels``, preset ``auto`` before issue 24; ``valid_superpixels``, its
first step), ``auto (default)`` (what ``polarseg segment`` does: the
pipeline with preset ``auto`` cut into k segments), then the truth-trained bounds
(``baselines.truth_bound_halves``): a random forest trained on the truth of the frame's
left half and scored on its right half, on the 20 plain features, on those plus the
engine's pixel features (both a forest) and on those plus the default's own superpixel
node features (gradient-boosted trees: the strongest bound found on the test half);
beside them ``default, right half``, the default scored on the same right-half pixels
(``baselines.right_half_ari``). On the renders, ``default, sky counted``: the default
asked for k + 1 segments where the truth leaves more than 2 % of the frame unlabelled
(the sky, which a user sees and may count), its own figure elsewhere. The bounds are
supervised: a reference for what the features allow, not a competitor.

Markers: ``‡`` = degenerate (one segment holds ≥ 90 % of the scored pixels, and 5 points
more than the truth's largest class); ``†`` = a
bound whose left half lacks a class of the right half. Marked cells are counted and the
means are printed with and without them; nothing is dropped silently.

Below each table, the number of materials found by itself (:func:`k_lines`): preset
``auto`` with ``n_segments = 0`` against the true k, with the choice's confidence and
the ARI of the labels with that k; counted exact and within ±1. Last, the default
against issue 24's targets and floors (:func:`verdict_lines`), with the cause of each
degenerate result (:func:`degenerate_cause`). ``--markdown PAGE``
writes all of it into the block of PAGE between :data:`BEGIN` and :data:`END`
(``docs/quality.md``; :func:`replace_block`).
"""

from __future__ import annotations

import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from baselines import (
    intensity_kmeans,
    real_frames,
    right_half_ari,
    smoothed_kmeans,
    truth_bound_halves,
)
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline, Scene
from napari_polarseg.engine.params import PRESETS

#: The rendered scenes beside the repository.
RENDERED_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "rendered"
#: Seeds of each half of the rendered set.
HALVES = {"dev": tuple(range(12)), "test": tuple(range(12, 24))}
HALF_NAMES = {"dev": "development half (seeds 0–11)", "test": "test half (seeds 12–23)"}


@dataclass(frozen=True)
class RenderSet:
    """Scenes made by ``render_scenes.py`` in a folder beside this script.

    ``role``: ``held-out`` sets are never chosen or tuned on and are read against the
    test half's target; ``development`` sets are for choosing, and their table shows
    the means by number of materials instead of one line per scene."""

    folder: Path
    title: str
    role: str
    command: str


HERE = Path(__file__).resolve().parent
#: The render sets (flag name → set); their files are git-ignored, ``command`` makes them.
RENDER_SETS = {
    "dev-renders": RenderSet(
        HERE / "renders_dev",
        "development renders (seeds 1000–1059, and two-material seeds 200–519; for choosing)",
        "development",
        "render_scenes.py --seeds 1000-1059 --out benchmarks/renders_dev; "
        "render_scenes.py --seeds 200-519 --two-materials --out benchmarks/renders_dev",
    ),
    "dev-pool-2": RenderSet(
        HERE / "renders_dev2",
        "second development pool (seeds 1060–1159; for choosing)",
        "development",
        "render_scenes.py --seeds 1060-1159 --out benchmarks/renders_dev2",
    ),
    "unseen": RenderSet(
        HERE / "renders",
        "unseen renders (render_scenes.py, never chosen or tuned on)",
        "held-out",
        "render_scenes.py --seeds 100-123 --out benchmarks/renders",
    ),
    "two-materials": RenderSet(
        HERE / "renders_two",
        "held-out two-material renders (render_scenes.py --two-materials, never chosen or "
        "tuned on)",
        "held-out",
        "render_scenes.py --seeds 520-999 --two-materials --out benchmarks/renders_two",
    ),
    "second-held-out": RenderSet(
        HERE / "renders_held_out",
        "second held-out renders (render_scenes.py, read once, "
        "for the consensus over superpixel sizes)",
        "held-out",
        "render_scenes.py --seeds 3000-3079 --out benchmarks/renders_held_out",
    ),
}
#: A result is degenerate when one segment holds this share of the scored pixels.
DEGENERATE_SHARE = 0.90
#: Registered methods shown as columns of their own beside the default (those that are
#: not the default's method): the candidates and the previous defaults.
METHOD_COLUMNS = ("superpixels", "valid_superpixels", "surface_superpixels", "superpixel_consensus")
UNSUPERVISED = ("intensity k-means", "smoothed k-means", *METHOD_COLUMNS, "auto (default)")
#: The method that finds k by itself (``n_segments = 0``), scored by :func:`k_lines`:
#: the default's.
FINDS_K = PRESETS["auto"].method
#: Issue 24's targets for the default: the rendered test half's mean, each real frame.
TARGET_TEST_HALF = 0.5
TARGET_REAL_FRAME = 0.7
#: The block of ``docs/quality.md`` that ``--markdown`` rewrites.
BEGIN = "<!-- material tables: begin -->"
END = "<!-- material tables: end -->"
#: Column → (features, classifier) of ``baselines.truth_bound_halves``.
BOUNDS = {
    "bound L→R: 20 features": ("plain", "forest"),
    "bound L→R: rich": ("rich", "forest"),
    "bound L→R: 20 + node features, boosting": ("regions", "boosting"),
}
#: The default scored on the pixels the bounds are scored on (the right half's).
RIGHT_HALF = "default, right half"
#: The default asked for one segment more on a render whose truth leaves more than
#: :data:`SKY_SHARE` of the frame unlabelled (the sky): the reading of a user who counts
#: the sky they see as a segment (:func:`score_frame`).
SKY_COUNTED = "default, sky counted"
#: Share of a render's pixels left unlabelled (0, the sky) above which the sky is counted.
SKY_SHARE = 0.02
#: A segment whose pixels are more than this share unlabelled (mostly sky) was spent on
#: the sky (:func:`degenerate_cause`).
SKY_SEGMENT = 0.5
COLUMNS = UNSUPERVISED + (SKY_COUNTED, RIGHT_HALF, *BOUNDS)


def load_rendered(seed: int, folder: Path = RENDERED_DIR):
    """(stack, angles in radians, labels) of ``scene_<seed>.npz``."""
    with np.load(Path(folder) / f"scene_{seed}.npz", allow_pickle=False) as f:
        return f["stack"], np.deg2rad(f["angles"]), f["labels"].astype(np.int32)


def degenerate(labels: np.ndarray, truth: np.ndarray) -> bool:
    """One segment holds ≥ :data:`DEGENERATE_SHARE` of the scored pixels (``truth > 0``)
    and more than the truth's own largest class does, plus 5 points (a frame that is
    94 % one class, such as the camera's mat, is not degenerate when cut right)."""
    scored = truth > 0
    counts = np.bincount(np.asarray(labels)[scored].ravel())
    share = counts.max() / counts.sum()
    truth_share = np.bincount(truth[scored].ravel()).max() / counts.sum()
    return bool(share >= max(DEGENERATE_SHARE, truth_share + 0.05))


def degenerate_cause(labels: np.ndarray, truth: np.ndarray) -> str:
    """Why a :func:`degenerate` result is so: ``"the sky took a segment"`` when one of its
    segments lies mostly (more than :data:`SKY_SEGMENT`) on unlabelled pixels (``truth ==
    0``), so that k − 1 segments were left for the k materials; else ``"the materials
    share a segment"``."""
    labels = np.asarray(labels).ravel()
    sky = np.bincount(labels, weights=(truth.ravel() == 0).astype(float))
    share = sky / np.maximum(np.bincount(labels), 1)
    if np.any(share > SKY_SEGMENT):
        return "the sky took a segment"
    return "the materials share a segment"


def score_frame(
    name: str, stack, angles, truth: np.ndarray, k: int, bounds: str, sky: bool = False
) -> dict:
    """One row: every column's ARI over ``truth > 0``, its markers and seconds.

    ``bounds``: ``all`` (both bounds), ``plain`` (the 20-feature one) or ``none``.
    ``sky``: ``truth == 0`` is the sky (a render), so :data:`SKY_COUNTED` is scored: the
    default with k + 1 segments when the sky is more than :data:`SKY_SHARE` of the frame,
    the default's own figure otherwise."""
    scored = truth > 0
    row: dict = {"frame": name, "k": k, "marks": {}, "seconds": {}}
    t0 = time.perf_counter()
    pipe = Pipeline(stack, angles, PRESETS["auto"].replace(n_segments=k))
    pol = pipe.get("polarisation")
    valid = ~np.asarray(pol.invalid, bool)
    prep = time.perf_counter() - t0
    scene, params = Scene(pipeline=pipe), pipe.params  # a segment() call resets pipe.params
    runs = {
        "intensity k-means": lambda: intensity_kmeans(pol.intensity, k),
        "smoothed k-means": lambda: smoothed_kmeans(pol.intensity, pol.dop, pol.phase, k, valid),
    }
    for method in METHOD_COLUMNS:
        if method != params.method:
            runs[method] = lambda m=method: scene.segment(params.replace(method=m)).labels
    runs["auto (default)"] = lambda: scene.segment(params).labels
    if sky and np.mean(~scored) > SKY_SHARE:
        runs[SKY_COUNTED] = lambda: scene.segment(params.replace(n_segments=k + 1)).labels
    for column, run in runs.items():
        t0 = time.perf_counter()
        labels = run()
        row["seconds"][column] = (
            time.perf_counter() - t0 + (prep if column == "auto (default)" else 0)
        )
        row[column] = float(adjusted_rand_score(truth[scored], labels[scored]))
        if degenerate(labels, truth):
            row["marks"][column] = "‡"
            if column == "auto (default)":
                row["degenerate cause"] = degenerate_cause(labels, truth)
        if column == "auto (default)" and bounds != "none":
            row[RIGHT_HALF] = right_half_ari(labels, truth)
    if sky and SKY_COUNTED not in row:  # no sky to count: the default's own figure
        row[SKY_COUNTED] = row["auto (default)"]
        if "auto (default)" in row["marks"]:
            row["marks"][SKY_COUNTED] = "‡"
    for column, (features, classifier) in BOUNDS.items():
        if bounds == "none" or (bounds == "plain" and features != "plain"):
            continue
        t0 = time.perf_counter()
        value, seen = truth_bound_halves(
            pol.intensity, pol.dop, pol.phase, truth, features, ~valid, classifier
        )
        row["seconds"][column] = time.perf_counter() - t0
        row[column] = value
        if not seen:
            row["marks"][column] = "†"
    found = scene.segment(params.replace(method=FINDS_K, n_segments=0))
    record = found.method_record
    value = float(adjusted_rand_score(truth[scored], found.labels[scored]))
    row["k found"] = (int(record["k"]), float(record.get("k_confidence", 0.0)), value)
    return row


def k_lines(rows: list[dict]) -> str:
    """The k found by :data:`FINDS_K` with ``n_segments = 0`` against the true k, one
    frame a line, then how many are exact and within ±1."""
    lines = [f"number of materials found by itself ({FINDS_K}, n_segments = 0):"]
    exact = near = 0
    for r in rows:
        k, confidence, value = r["k found"]
        exact += k == r["k"]
        near += abs(k - r["k"]) <= 1
        lines.append(
            f"- {r['frame']}: true {r['k']}, found {k} (confidence {confidence:.2f}), "
            f"ARI with the k found {value:.3f}"
        )
    mean = np.mean([r["k found"][2] for r in rows])
    lines.append(f"- exact {exact} / {len(rows)}, within ±1 {near} / {len(rows)}")
    lines.append(f"- mean ARI with the k found {mean:.3f}")
    return "\n".join(lines)


def rendered_frames(seeds, folder: Path = RENDERED_DIR):
    """(name, stack, angles in radians, truth, k) of every rendered seed whose file is in
    ``folder`` (k: the classes scored, ``truth > 0``)."""
    for seed in seeds:
        if not (Path(folder) / f"scene_{seed}.npz").is_file():
            print(f"rendered scene {seed} not in {folder}: skipped")
            continue
        stack, angles, truth = load_rendered(seed, folder)
        yield f"scene_{seed}", stack, angles, truth, len(np.unique(truth[truth > 0]))


def labelled_real_frames(folder: Path):
    """(name, stack, angles in radians, truth, k) of every hand-labelled real frame found
    in ``folder``."""
    for tf, data in real_frames(folder):
        yield tf.frame, data.stack, data.angles_rad, tf.truth, len(tf.classes)


def set_frames(name: str, real_dir: Path):
    """The frames of one set, as :func:`rendered_frames`: a half of the shared renders
    (:data:`HALVES`), a render set (:data:`RENDER_SETS`, none when its folder is empty or
    missing) or ``real`` (the labelled real frames in ``real_dir``)."""
    if name in HALVES:
        return rendered_frames(HALVES[name])
    if name in RENDER_SETS:
        folder = RENDER_SETS[name].folder
        return rendered_frames(folder_seeds(folder), folder)
    if name == "real":
        return labelled_real_frames(real_dir)
    known = ", ".join([*HALVES, *RENDER_SETS, "real"])
    raise ValueError(f"unknown set {name!r}; known: {known}")


def rendered_rows(seeds, bounds: str, folder: Path = RENDERED_DIR) -> list[dict]:
    """:func:`score_frame` of every rendered seed whose file is in ``folder``."""
    return [score_frame(*frame, bounds, sky=True) for frame in rendered_frames(seeds, folder)]


def real_rows(folder: Path, bounds: str) -> list[dict]:
    """:func:`score_frame` of every hand-labelled real frame found in ``folder``."""
    return [score_frame(*frame, bounds) for frame in labelled_real_frames(folder)]


def _mean(values: list[float]) -> str:
    values = [v for v in values if np.isfinite(v)]
    return f"{np.mean(values):.3f}" if values else "–"


def table(rows: list[dict], title: str) -> str:
    """Markdown table of ``rows`` under ``title``: one line per frame, then the mean of
    every column over all frames, over the unmarked ones (and how many are left), the
    count of marked cells and the total seconds."""
    cols = [c for c in COLUMNS if any(c in r for r in rows)]
    lines = [
        f"{title}: ARI over the labelled pixels (‡ = degenerate, one segment ≥ "
        f"{DEGENERATE_SHARE:.0%} of them and > the truth's largest class + 5 points; "
        "† = bound's left half lacks a class)",
        "",
        "| frame | k | " + " | ".join(cols) + " |",
        "|---|---:|" + "---:|" * len(cols),
    ]

    def cell(r: dict, c: str) -> str:
        return f"{r[c]:.3f}" + (" " + r["marks"][c] if c in r["marks"] else "") if c in r else "–"

    for r in rows:
        lines.append(f"| {r['frame']} | {r['k']} | " + " | ".join(cell(r, c) for c in cols) + " |")
    every = [_mean([r[c] for r in rows if c in r]) for c in cols]
    clean = [
        f"{_mean([r[c] for r in rows if c in r and c not in r['marks']])} "
        f"(n={sum(c in r and c not in r['marks'] for r in rows)})"
        for c in cols
    ]
    marked = [str(sum(c in r["marks"] for r in rows)) for c in cols]
    seconds = [f"{sum(r['seconds'].get(c, 0.0) for r in rows):.1f}" for c in cols]
    lines.append("| **mean, all** | | " + " | ".join(f"**{v}**" for v in every) + " |")
    lines.append("| mean without ‡/† | | " + " | ".join(clean) + " |")
    lines.append("| marked (‡/†) | | " + " | ".join(marked) + " |")
    lines.append("| seconds, total | | " + " | ".join(seconds) + " |")
    return "\n".join(lines)


def summary_table(rows: list[dict], title: str) -> str:
    """Markdown table of the mean of every column of ``rows`` over all scenes and over
    the scenes of each number of materials, with the count of degenerate results."""
    cols = [c for c in COLUMNS if any(c in r for r in rows)]
    groups = {"all": rows}
    for k in sorted({r["k"] for r in rows}):
        groups[f"{k} materials"] = [r for r in rows if r["k"] == k]
    lines = [
        f"{title}: mean ARI over the labelled pixels (‡ n = degenerate results, one "
        f"segment ≥ {DEGENERATE_SHARE:.0%} of them)",
        "",
        "| scenes | n | " + " | ".join(cols) + " |",
        "|---|---:|" + "---:|" * len(cols),
    ]
    for name, group in groups.items():
        cells = []
        for c in cols:
            marked = sum(r["marks"].get(c) == "‡" for r in group)
            mean = _mean([r[c] for r in group if c in r])
            cells.append(mean + (f" ‡ {marked}" if marked else ""))
        lines.append(f"| {name} | {len(group)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def add_arguments(parser) -> None:
    """The subset flags shared by both evaluate scripts."""
    parser.add_argument(
        "--rendered",
        choices=("dev", "test", "all"),
        help="only the rendered scenes of this half (with --real: and the real frames); "
        "without --rendered and --real everything runs",
    )
    parser.add_argument(
        "--real",
        action="store_true",
        help="only the real frames' material table (with --rendered: and those scenes)",
    )
    parser.add_argument(
        "--bounds",
        choices=("all", "plain", "none"),
        default="all",
        help="truth-trained left→right bounds of the material tables [all]",
    )
    parser.add_argument("--rendered-dir", type=Path, default=RENDERED_DIR, help=f"[{RENDERED_DIR}]")
    for name, render_set in RENDER_SETS.items():
        parser.add_argument(
            f"--{name}",
            action="store_true",
            help=f"also the {render_set.title} (made by `{render_set.command}`)",
        )
        parser.add_argument(
            f"--{name}-dir", type=Path, default=render_set.folder, help=f"[{render_set.folder}]"
        )
    parser.add_argument(
        "--markdown",
        type=Path,
        metavar="PAGE",
        help=f"also write the material tables into PAGE (docs/quality.md) between {BEGIN} "
        f"and {END}",
    )


def subset_only(args) -> bool:
    """True when the flags pick a subset of the material tables (skip everything else)."""
    return bool(args.rendered or args.real or chosen_render_sets(args))


def chosen_render_sets(args) -> list[str]:
    """The :data:`RENDER_SETS` whose flags are given (a parser may offer only some)."""
    return [name for name in RENDER_SETS if getattr(args, name.replace("-", "_"), False)]


def folder_seeds(folder: Path) -> list[int]:
    """Seeds of the ``scene_<seed>.npz`` files in ``folder``, in order."""
    return sorted(int(f.stem.split("_")[1]) for f in Path(folder).glob("scene_*.npz"))


def like_for_like(rows: list[dict]) -> str:
    """ "; on the right halves …": the default's mean ARI on the pixels the truth-trained
    bounds are scored on, beside each bound's mean ("" when the bounds were not run)."""
    bounds = [c for c in BOUNDS if all(c in r for r in rows)]
    if not bounds or not all(RIGHT_HALF in r for r in rows):
        return ""
    means = " / ".join(f"{np.nanmean([r[c] for r in rows]):.3f}" for c in bounds)
    names = ", ".join(c.removeprefix("bound L→R: ") for c in bounds)
    default = np.mean([r[RIGHT_HALF] for r in rows])
    return (
        f"; on the right halves, where the bounds are scored: the default {default:.3f}, "
        f"the truth-trained bounds ({names}) {means}"
    )


def sky_counted(rows: list[dict]) -> str:
    """ "; with the sky counted …": the mean and degenerate count of :data:`SKY_COUNTED`
    ("" when it was not scored, as on the real frames)."""
    if not rows or not all(SKY_COUNTED in r for r in rows):
        return ""
    counted = sum(SKY_COUNTED in r["seconds"] for r in rows)
    mean = np.mean([r[SKY_COUNTED] for r in rows])
    marked = [r["frame"] for r in rows if SKY_COUNTED in r["marks"]]
    return (
        f"; with the sky counted as a segment (k + 1 on the {counted} of {len(rows)} frames "
        f"whose sky is > {SKY_SHARE:.0%} of the frame): mean {mean:.3f}, degenerate on "
        f"{len(marked)}" + (f" ({', '.join(marked)})" if marked else "")
    )


def verdict_lines(sets: dict[str, list[dict]]) -> str:
    """The default against issue 24's targets and floors, one line per set: the mean of
    each rendered half and every real frame against the plain unsupervised baseline
    (smoothed k-means) and intensity k-means; the test half against
    :data:`TARGET_TEST_HALF`, each real frame against :data:`TARGET_REAL_FRAME`."""
    lines = ["the default (preset auto) against issue 24's targets and floors:"]
    default, plain, km = "auto (default)", "smoothed k-means", "intensity k-means"

    def verdict(value: float, target: float | None, floor: float, other: float) -> str:
        parts = (
            []
            if target is None
            else [
                f"target {target} "
                + ("met" if value >= target else f"MISSED by {target - value:.3f}")
            ]
        )
        parts.append(
            ("at least" if value >= floor else f"BELOW by {floor - value:.3f}")
            + f" the plain baseline {floor:.3f}"
        )
        parts.append(
            ("above" if value > other else "not above") + f" intensity k-means {other:.3f}"
        )
        return "; ".join(parts)

    for key, rows in sets.items():
        if not rows:
            continue
        if key in HALVES or key in RENDER_SETS:
            mean = {c: float(np.mean([r[c] for r in rows])) for c in (default, plain, km)}
            held_out = key == "test" or (key in RENDER_SETS and RENDER_SETS[key].role == "held-out")
            target = TARGET_TEST_HALF if held_out else None
            what = verdict(mean[default], target, mean[plain], mean[km])
            marked = [r for r in rows if default in r["marks"]]
            if marked:
                causes = "; ".join(f"{r['frame']}: {r['degenerate cause']}" for r in marked)
                what += f"; degenerate on {len(marked)} of {len(rows)} ({causes})"
            what += sky_counted(rows)
            what += like_for_like(rows)
            name = HALF_NAMES[key] if key in HALVES else RENDER_SETS[key].title
            lines.append(f"- {name}, mean {mean[default]:.3f}: {what}")
            continue
        for r in rows:
            what = verdict(r[default], TARGET_REAL_FRAME, r[plain], r[km])
            mark = "; DEGENERATE" if default in r["marks"] else ""
            lines.append(f"- {r['frame']} {r[default]:.3f}: {what}{mark}")
    return "\n".join(lines)


def replace_block(page: Path, body: str, command: str, begin: str = BEGIN, end: str = END) -> None:
    """Replace the text between ``begin`` and ``end`` (default :data:`BEGIN` and
    :data:`END`) of ``page`` with ``body`` (and a line naming ``command``); SystemExit
    when the page has no such block."""
    text = Path(page).read_text(encoding="utf-8")
    if text.count(begin) != 1 or text.count(end) != 1 or text.index(begin) > text.index(end):
        raise SystemExit(f"{page} has no single {begin} ... {end} block to replace")
    head, rest = text.split(begin, 1)
    tail = rest.split(end, 1)[1]
    note = f"<!-- generated by `{command}`; do not edit by hand -->"
    Path(page).write_text(f"{head}{begin}\n{note}\n\n{body}\n\n{end}{tail}", encoding="utf-8")


def command_line() -> str:
    """How this run was started, as typed (``python`` and the script's arguments)."""
    return shlex.join(["python", *sys.argv])


def run(args, real_dir: Path, command: str | None = None) -> None:
    """Print the material tables the flags ask for (all of them when none is given),
    then the default against issue 24's targets; with ``args.markdown``, write the same
    text into that page's :data:`BEGIN` … :data:`END` block (``command`` names the run,
    :func:`command_line` by default)."""
    t0 = time.perf_counter()
    halves = {"all": ("dev", "test"), None: ("dev", "test"), "dev": ("dev",)}
    halves["test"] = ("test",)
    blocks: list[str] = []
    sets: dict[str, list[dict]] = {}

    def add(*texts: str) -> None:
        for text in texts:
            print(f"\n{text}", flush=True)
            blocks.append(text)

    renders = chosen_render_sets(args)
    if args.rendered or not (args.real or renders):
        if not Path(args.rendered_dir).is_dir():
            add(f"no rendered scenes in {args.rendered_dir}: their tables are skipped")
        else:
            for half in halves[args.rendered]:
                rows = sets[half] = rendered_rows(HALVES[half], args.bounds, args.rendered_dir)
                if rows:
                    add(table(rows, "rendered scenes, " + HALF_NAMES[half]), k_lines(rows))
    for name in renders:
        render_set = RENDER_SETS[name]
        folder = getattr(args, f"{name.replace('-', '_')}_dir")
        seeds = folder_seeds(folder)
        rows = sets[name] = rendered_rows(seeds, args.bounds, folder)
        if not rows:
            add(
                f"no {render_set.title} in {folder} (make them with "
                f"`{render_set.command}`): their table is skipped"
            )
        elif render_set.role == "development":
            add(summary_table(rows, f"{render_set.title}, {len(rows)} scenes"))
        else:
            add(table(rows, f"{render_set.title}, seeds {seeds[0]}–{seeds[-1]}"), k_lines(rows))
    if args.real or not (args.rendered or renders):
        rows = sets["real"] = real_rows(real_dir, args.bounds) if Path(real_dir).is_dir() else []
        if rows:
            add(table(rows, "real frames (hand-labelled truth)"), k_lines(rows))
        else:
            add(f"no real frames in {real_dir}: their material table is skipped")
    add(verdict_lines(sets))
    if getattr(args, "markdown", None):
        replace_block(args.markdown, "\n\n".join(blocks), command or command_line())
        print(f"\nmaterial tables written into {args.markdown}")
    print(f"\nmaterial tables: {time.perf_counter() - t0:.1f} s wall")
