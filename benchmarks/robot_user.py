"""Robot user: how many corrections a scribble classifier needs (issue 23).

A simulated user paints discs of radius max(3, min(H, W) // 80) px:

- to start, one disc per material at the deepest point of that material's truth (the
  maximum of the distance transform of the class mask, the image border counting as
  an edge);
- then, each round, one disc of the TRUE class at the deepest point of the largest
  connected wrong region (the largest 4-connected component of prediction ≠ truth over
  the labelled pixels); every disc paints only pixels of its own true class.

After every update the prediction is scored by the adjusted Rand index (ARI) over the
labelled truth pixels. A row reports the ARI after 0, 2, 5, 10 and 15 corrections, the
corrections needed to reach ARI 0.9 (">15" when never), how many corrections made it
worse (the ARI fell by more than :data:`SETBACK`) and the largest fall, the median seconds of an
update (training plus predicting the whole image) and the one-off feature seconds.

Rows (methods):

- ``product``: the project's scribble loop (``ScribbleSession`` on the pipeline's
  polarisation image: features computed once per scene, each update retrains and
  predicts coarse to fine, default parameters and smoothing);
- ``plain RF``: the plain baseline's 20 smoothed polarisation features
  (``baselines.plain_features``) and a random forest of 100 trees;
- ``ilastik RF``: ilastik's default filter bank on the raw angle frames
  (``ilastik_features.py``, 196 features for four angles) and a random forest of 100
  trees.

Scenes: the hand-labelled real frames (``--real``; truth in
``napari_polarseg/sample_data/truth``, frames in ``../shared/data/polanalyser``) and the
rendered scenes ``../shared/data/rendered/scene_<seed>.npz`` (``--rendered``: dev =
seeds 0-11, test = 12-23). Beside each rendered scene: a truth-trained bound, a forest
on the 20 plain features trained on the truth of the scene's left half and scored on its
right half; marked † when the halves do not hold the same materials (a material only on
the right cannot be learnt; a right half of one material scores 1 whatever is predicted).
The half means are also given without the marked scenes.

Usage::

    python benchmarks/robot_user.py --real --rendered all --rounds 15
    python benchmarks/robot_user.py --real --rendered all --markdown docs/quality.md
    python benchmarks/robot_user.py --rendered dev
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage
from sklearn.ensemble import RandomForestClassifier
from sklearn.metrics import adjusted_rand_score

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import plain_features, real_frames  # noqa: E402
from ilastik_features import ilastik_features  # noqa: E402
from materials import RENDER_SETS, chosen_render_sets, folder_seeds, replace_block  # noqa: E402

#: The block of ``docs/quality.md`` that ``--markdown`` rewrites.
MARKDOWN_BEGIN = "<!-- robot user: begin -->"
MARKDOWN_END = "<!-- robot user: end -->"
#: Corrections after which the ARI is reported.
MILESTONES = (0, 2, 5, 10, 15)
#: The ARI whose number of corrections is reported.
TARGET_ARI = 0.9
#: The disc radius is min(H, W) // this, at least MIN_RADIUS.
RADIUS_DIVISOR = 80
MIN_RADIUS = 3
#: Labelled left-half pixels that train the truth bound (a seeded sample).
BOUND_PIXELS = 20_000
#: Forest predictions are made on chunks of about this many pixels.
CHUNK_PIXELS = 262_144

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
REAL_DIR = DATA / "polanalyser"
RENDERED_DIR = DATA / "rendered"
HALVES = {"dev": range(0, 12), "test": range(12, 24)}

#: An update: scribbles (H, W), 0 = none, else a truth value -> predicted truth values.
Update = Callable[[np.ndarray], np.ndarray]


@dataclass
class Scene:
    """One scene: the angle stack, its angles and the truth (0 = not labelled)."""

    name: str
    stack: np.ndarray
    angles_rad: np.ndarray
    truth: np.ndarray
    half: str = "real"


# -- the robot --------------------------------------------------------------------------


def disc_radius(shape: tuple[int, ...]) -> int:
    """Disc radius for an image of ``shape``: max(3, min(H, W) // 80)."""
    return max(MIN_RADIUS, min(shape[-2:]) // RADIUS_DIVISOR)


def deepest_point(mask: np.ndarray) -> tuple[int, int]:
    """(row, col) of the maximum of the distance transform of ``mask`` (the image border
    counts as an edge; the first in row order on a tie)."""
    depth = ndimage.distance_transform_edt(np.pad(mask, 1))[1:-1, 1:-1]
    r, c = np.unravel_index(int(np.argmax(depth)), mask.shape)
    return int(r), int(c)


def paint_disc(scribbles: np.ndarray, truth: np.ndarray, centre: tuple[int, int], radius: int):
    """Paint the true class at ``centre`` into ``scribbles`` (in place) on the disc's
    pixels of that class; returns the class."""
    value = truth[centre]
    r, c = centre
    r0, r1 = max(0, r - radius), min(truth.shape[0], r + radius + 1)
    c0, c1 = max(0, c - radius), min(truth.shape[1], c + radius + 1)
    yy, xx = np.ogrid[r0:r1, c0:c1]
    disc = (yy - r) ** 2 + (xx - c) ** 2 <= radius * radius
    window = scribbles[r0:r1, c0:c1]
    window[disc & (truth[r0:r1, c0:c1] == value)] = value
    return int(value)


def initial_scribbles(truth: np.ndarray, radius: int) -> tuple[np.ndarray, list]:
    """One disc per material at its deepest point: (scribbles, centres in class order)."""
    scribbles = np.zeros(truth.shape, dtype=np.int32)
    centres = []
    for value in np.unique(truth[truth > 0]):
        centre = deepest_point(truth == value)
        paint_disc(scribbles, truth, centre, radius)
        centres.append(centre)
    return scribbles, centres


def largest_wrong_region(prediction: np.ndarray, truth: np.ndarray) -> np.ndarray | None:
    """Mask of the largest 4-connected region of labelled pixels predicted wrong, or
    None when every labelled pixel is right."""
    wrong = (prediction != truth) & (truth > 0)
    components, n = ndimage.label(wrong)
    if n == 0:
        return None
    sizes = np.bincount(components.ravel())
    sizes[0] = 0
    return components == int(np.argmax(sizes))


def ari_labelled(truth: np.ndarray, prediction: np.ndarray) -> float:
    """ARI over the labelled truth pixels."""
    where = truth > 0
    return float(adjusted_rand_score(truth[where], prediction[where]))


#: A correction that lowers the ARI by more than this is counted as a setback.
SETBACK = 0.01


@dataclass
class RobotRun:
    """What :func:`run_robot` measured: ``ari[n]`` after n corrections, each update's
    seconds, the first discs' centres and every correction's centre."""

    ari: list[float]
    seconds: list[float]
    initial_centres: list
    corrections: list

    def setbacks(self, tolerance: float = SETBACK) -> tuple[int, float]:
        """How many corrections lowered the ARI by more than ``tolerance``, and the
        largest such fall (0 when none)."""
        falls = [b - a for a, b in zip(self.ari[1:], self.ari[:-1], strict=False)]
        worse = [f for f in falls if f > tolerance]
        return len(worse), max(worse, default=0.0)

    def corrections_to(self, target: float = TARGET_ARI) -> str:
        """Corrections needed to reach ``target`` (">rounds" when never)."""
        for n, value in enumerate(self.ari):
            if value >= target:
                return str(n)
        return f">{len(self.ari) - 1}"


def run_robot(truth: np.ndarray, update: Update, rounds: int = 15) -> RobotRun:
    """Start with one disc per material, then correct ``rounds`` times (module docstring).

    Once nothing is wrong the robot stops painting and the last ARI is repeated.
    """
    truth = np.asarray(truth)
    radius = disc_radius(truth.shape)
    scribbles, centres = initial_scribbles(truth, radius)
    run = RobotRun([], [], centres, [])
    while True:
        t0 = time.perf_counter()
        prediction = update(scribbles.copy())
        run.seconds.append(time.perf_counter() - t0)
        run.ari.append(ari_labelled(truth, prediction))
        if len(run.ari) > rounds:
            return run
        region = largest_wrong_region(prediction, truth)
        if region is None:
            run.ari += [run.ari[-1]] * (rounds + 1 - len(run.ari))
            return run
        centre = deepest_point(region)
        paint_disc(scribbles, truth, centre, radius)
        run.corrections.append(centre)


# -- the methods --------------------------------------------------------------------------


def forest_update(features: np.ndarray) -> Update:
    """Random forest (100 trees, seed 0, 2 jobs) on (H, W, F) features."""
    h, w, f = features.shape
    flat = features.reshape(-1, f)

    def update(scribbles: np.ndarray) -> np.ndarray:
        marked = np.flatnonzero(scribbles.ravel())
        model = RandomForestClassifier(100, random_state=0, n_jobs=2)
        model.fit(flat[marked], scribbles.ravel()[marked])
        step = CHUNK_PIXELS
        parts = [model.predict(flat[i : i + step]) for i in range(0, flat.shape[0], step)]
        return np.concatenate(parts).reshape(h, w)

    return update


def product_update(pipe) -> Update:
    """The project's scribble loop (``ScribbleSession``: features computed once, each
    update retrains and predicts coarse to fine with the default parameters)."""
    from napari_polarseg.engine import ScribbleSession

    session = ScribbleSession.on_pipeline(pipe)
    session.features()

    def update(scribbles: np.ndarray) -> np.ndarray:
        return session.update(scribbles)

    return update


def method_updates(scene: Scene) -> dict[str, tuple[Callable[[], Update], str]]:
    """Method name -> (factory computing the features, what it is)."""
    from napari_polarseg.engine import Pipeline

    pipe = Pipeline(scene.stack, scene.angles_rad)
    pol = pipe.get("polarisation")
    return {
        "product": (lambda: product_update(pipe), "pixel classifier"),
        "plain RF": (
            lambda: forest_update(plain_features(pol.intensity, pol.dop, pol.phase)),
            "20 plain features",
        ),
        "ilastik RF": (lambda: forest_update(ilastik_features(scene.stack)), "ilastik bank"),
    }


def halves_comparable(truth: np.ndarray) -> bool:
    """Whether the left and right halves of ``truth`` hold the same materials (at least
    two): only then does :func:`truth_bound` measure the features."""
    half = truth.shape[1] // 2
    left, right = (set(np.unique(t[t > 0]).tolist()) for t in (truth[:, :half], truth[:, half:]))
    return left == right and len(right) >= 2


def truth_bound(scene: Scene) -> float:
    """ARI on the right half of a forest on the plain features trained on the truth of
    the left half (at most :data:`BOUND_PIXELS` labelled pixels)."""
    from napari_polarseg.engine import Pipeline

    pol = Pipeline(scene.stack, scene.angles_rad).get("polarisation")
    feats = plain_features(pol.intensity, pol.dop, pol.phase)
    truth = scene.truth
    half = truth.shape[1] // 2
    left = np.argwhere(truth[:, :half] > 0)
    rng = np.random.default_rng(0)
    left = left[rng.choice(len(left), min(BOUND_PIXELS, len(left)), replace=False)]
    model = RandomForestClassifier(100, random_state=0, n_jobs=2)
    model.fit(feats[left[:, 0], left[:, 1]], truth[left[:, 0], left[:, 1]])
    right_truth = truth[:, half:]
    where = right_truth > 0
    predicted = model.predict(feats[:, half:][where])
    return float(adjusted_rand_score(right_truth[where], predicted))


# -- scenes and report --------------------------------------------------------------------


def real_scenes(folder: Path = REAL_DIR) -> list[Scene]:
    """The hand-labelled real frames."""
    return [
        Scene(Path(t.frame).stem, d.stack, np.asarray(d.angles_rad), t.truth, "real")
        for t, d in real_frames(folder)
    ]


def rendered_scene(seed: int, folder: Path = RENDERED_DIR, half: str | None = None) -> Scene:
    """``scene_<seed>.npz`` (``half``: by default dev for seeds 0-11, test for 12-23)."""
    with np.load(folder / f"scene_{seed}.npz", allow_pickle=False) as f:
        stack, angles, labels = f["stack"], np.deg2rad(f["angles"]), f["labels"]
    half = half or ("dev" if seed in HALVES["dev"] else "test")
    return Scene(f"scene_{seed}", stack, angles, labels.astype(np.int32), half)


def evaluate_scene(
    scene: Scene, rounds: int, bound: bool, methods: tuple[str, ...] | None = None
) -> list[dict]:
    """One row per method for ``scene`` (only ``methods`` when given)."""
    rows = []
    b = truth_bound(scene) if bound else None
    for name, (factory, _) in method_updates(scene).items():
        if methods is not None and name not in methods:
            continue
        t0 = time.perf_counter()
        update = factory()
        feature_seconds = time.perf_counter() - t0
        run = run_robot(scene.truth, update, rounds)
        rows.append(
            {
                "scene": scene.name,
                "half": scene.half,
                "method": name,
                "ari": run.ari,
                "to": run.corrections_to(),
                "setbacks": run.setbacks(),
                "update s": float(np.median(run.seconds)),
                "features s": feature_seconds,
                "bound": b,
                "comparable": halves_comparable(scene.truth),
            }
        )
        print(format_row(rows[-1], rounds), flush=True)
    return rows


def milestones(rounds: int) -> list[int]:
    return [m for m in MILESTONES if m <= rounds]


def header(rounds: int) -> str:
    cols = [f"ARI@{m}" for m in milestones(rounds)]
    cols += [f"to {TARGET_ARI}", "worse (largest fall)", "s/update", "features s", "bound L→R"]
    return "| scene | method | " + " | ".join(cols) + " |\n|---|---|" + "---:|" * len(cols)


def format_row(row: dict, rounds: int) -> str:
    cells = [f"{row['ari'][m]:.3f}" for m in milestones(rounds)]
    worse, fall = row.get("setbacks", (0, 0.0))
    cells += [row["to"], f"{worse} ({fall:.2f})" if worse else "0"]
    cells += [f"{row['update s']:.2f}", f"{row['features s']:.1f}"]
    mark = "" if row["comparable"] else " †"
    cells.append("" if row["bound"] is None else f"{row['bound']:.3f}{mark}")
    return f"| {row['scene']} | {row['method']} | " + " | ".join(cells) + " |"


def half_means(rows: list[dict], rounds: int) -> list[str]:
    """Per half and method: mean ARI after 5 corrections (or the last), and the bound."""
    at = min(5, rounds)
    lines = []
    for half in dict.fromkeys(r["half"] for r in rows):
        mine = [r for r in rows if r["half"] == half]
        scenes = {r["scene"]: r for r in mine}
        fair = {n for n, r in scenes.items() if r["comparable"]}
        parts = []
        for method in dict.fromkeys(r["method"] for r in mine):
            rs = [r for r in mine if r["method"] == method]
            reached = sum(r["to"][0] != ">" for r in rs)
            unmarked = np.mean([r["ari"][at] for r in rs if r["scene"] in fair] or [np.nan])
            parts.append(
                f"{method} {np.mean([r['ari'][at] for r in rs]):.3f} (without † "
                f"{unmarked:.3f}; 0.9 reached {reached}/{len(rs)})"
            )
        bounds = {n: r["bound"] for n, r in scenes.items() if r["bound"] is not None}
        bound = ""  # the real frames have no truth-trained bound
        if bounds:
            fair_bound = np.mean([b for n, b in bounds.items() if n in fair] or [np.nan])
            bound = f"; bound L→R {np.mean(list(bounds.values())):.3f}"
            bound += f" (without † {fair_bound:.3f}, {len(fair)} scenes)"
        lines.append(f"- {half} ({len(scenes)} scenes), mean ARI@{at}: " + ", ".join(parts) + bound)
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", action="store_true", help="the hand-labelled real frames")
    parser.add_argument("--rendered", choices=("dev", "test", "all"), help="rendered scenes")
    held_out = [name for name, render_set in RENDER_SETS.items() if render_set.role == "held-out"]
    for name in held_out:
        parser.add_argument(f"--{name}", action="store_true", help=f"the {RENDER_SETS[name].title}")
    parser.add_argument("--rounds", type=int, default=15, help="corrections [15]")
    parser.add_argument("--seeds", help="only these rendered seeds (comma-separated)")
    parser.add_argument(
        "--methods", help="only these rows (comma-separated: product, plain RF, ilastik RF)"
    )
    parser.add_argument(
        "--markdown", type=Path, help="also write the tables into this page's robot-user block"
    )
    args = parser.parse_args(argv)
    sets = chosen_render_sets(args)
    if not args.real and not args.rendered and not sets:
        parser.error(
            "choose --real, --rendered dev|test|all and/or "
            + ", ".join(f"--{name}" for name in held_out)
        )
    methods = None if not args.methods else tuple(m.strip() for m in args.methods.split(","))
    t0 = time.perf_counter()
    print(header(args.rounds), flush=True)
    rows = []
    if args.real:
        for scene in real_scenes():
            rows += evaluate_scene(scene, args.rounds, bound=False, methods=methods)
    if args.rendered:
        halves = ("dev", "test") if args.rendered == "all" else (args.rendered,)
        seeds = [s for h in halves for s in HALVES[h]]
        if args.seeds:
            seeds = [s for s in seeds if str(s) in args.seeds.split(",")]
        for seed in seeds:
            rows += evaluate_scene(rendered_scene(seed), args.rounds, bound=True, methods=methods)
    for name in sets:
        folder = RENDER_SETS[name].folder
        for seed in folder_seeds(folder):
            if args.seeds and str(seed) not in args.seeds.split(","):
                continue
            scene = rendered_scene(seed, folder, name)
            rows += evaluate_scene(scene, args.rounds, bound=True, methods=methods)
    print()
    print("\n".join(half_means(rows, args.rounds)))
    print(f"\ntotal {time.perf_counter() - t0:.1f} s")
    if args.markdown:
        body = "\n".join(
            [header(args.rounds), *(format_row(r, args.rounds) for r in rows), ""]
            + half_means(rows, args.rounds)
        )
        command = shlex.join(["python", "benchmarks/robot_user.py", *(argv or sys.argv[1:])])
        replace_block(args.markdown, body, command, MARKDOWN_BEGIN, MARKDOWN_END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
