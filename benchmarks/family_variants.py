"""Variants of the default method on the development halves of every scene family
(:mod:`families`), for choosing: the mean ARI of each variant by family, over all
families together, and its paired difference to the default, with the scenes that moved
most.

A variant is the default method's class with some attributes changed (its node-feature
parameters, how far its diffusion reaches in object sizes, how many superpixels span one
object, whether it follows the estimated object size) or the default with the object
size set to the truth's (``truth size``: what a perfect estimate would give) or
estimated from ρ and φ alone (``size from polarisation``: :class:`PolarisationSize`) or
chosen between the two estimates by how little the labels change when it is nudged
(``steadier size``: :class:`SteadierSize`), or with the texture group's weight chosen
per scene among five by how well each weight's labels agree with the others' (``texture
weight medoid``: :class:`TextureWeightMedoid`), or the
consensus of the default's run and runs with other node parameters on the same
superpixels (``consensus …``: :class:`ReachConsensus`). The
development halves are read; ``--test-base B`` reads round B's test halves instead,
only to check a choice on a test half already read and reported (a fresh round's is
for reporting). ``--read-rounds B,B`` adds the test halves of rounds read before to
the development halves of every rendered family: more development scenes, which the
small family needs (its 24 development scenes put the default 0.09 above
``superpixels`` where the fresh rounds have the two level). ``--oracle`` also prints,
by family, the mean of the best variant of each frame, chosen with the truth: how far a
perfect per-scene choice among the variants could go.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python family_variants.py \\
        [--families objects,small,textured,diffuse,real] [--variants NAME,NAME]
        [--test-base B] [--read-rounds B,B] [--oracle]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
from baselines import smoothed_kmeans
from families import FAMILIES, Frame, add_check_round, frames, read_half, standard_error
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline, Scene
from napari_polarseg.engine.features.object_size import ObjectSize, scene_object_size
from napari_polarseg.engine.methods import MethodOutput, register_method
from napari_polarseg.engine.methods.superpixel_consensus import SuperpixelConsensus
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.methods.valid_superpixels import clustered_pixels
from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.unsupervised.merge import closest_centroids, weakest_border
from napari_polarseg.engine.unsupervised.pixel_maps import pixel_maps
from napari_polarseg.engine.unsupervised.segmenter import prepare_regions


@dataclass(frozen=True)
class Variant:
    """Attributes of the default's class to change, node-parameter changes, and whether
    the truth's object size is given."""

    attrs: dict[str, Any] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    truth_size: bool = False
    #: a registered method read as it is instead of the default's class (a baseline)
    method: str = ""
    #: segment again at the short reach above this largest-segment share (0: never)
    collapse: float = 0.0
    #: follow the estimated object size only where it is at least this share of the
    #: frame's short side (0: wherever the class's ``follows_estimate`` says)
    gate: float = 0.0
    #: node-parameter changes of further runs on the same superpixels; the labels are
    #: the runs' consensus with the default (:class:`ReachConsensus`)
    also: tuple[dict[str, Any], ...] = ()
    #: a subclass of the default's class run in its place (None: the default's class):
    #: :class:`PolarisationSize`, :class:`SteadierSize`, :class:`TextureWeightMedoid`
    base: type | None = None


class SmoothedKMeans:
    """The plain unsupervised baseline, k-means on the 20 smoothed polarisation features
    of the clustered pixels (``baselines.smoothed_kmeans``), as a method: its figures
    stand beside the variants' in the same run."""

    name = "baseline:smoothed k-means"
    title = "k-means on 20 smoothed features (baseline)"
    reads = ("fit", "n_segments")
    inputs: tuple[str, ...] = ()
    reads_normals = False

    def stages(self, params) -> tuple[str, ...]:
        return ("clustering",)

    def segment(self, scene, params, inputs, run) -> MethodOutput:
        run.begin("clustering")
        pol = scene.polarisation(params)
        valid = ~np.asarray(pol.invalid, bool)
        k = params.n_segments
        return MethodOutput(smoothed_kmeans(pol.intensity, pol.dop, pol.phase, k, valid))


class GatedSurface(SurfaceSuperpixels):
    """The default's class following the estimated object size only at or above
    :attr:`gate` of the short side; below it (a texture's grain, a camouflage net's
    mesh) the frame-share scales."""

    gate = 0.0
    follows_estimate = True

    def scaled_params(self, object_size: float, shape: tuple[int, int]):
        if object_size < self.gate * min(shape):
            return self.params
        return super().scaled_params(object_size, shape)


class CollapseFallback(SurfaceSuperpixels):
    """The default's class that segments again with the shorter reach and narrower
    border scale of ``superpixels`` (reach 0.07 of the side, τ 0.75) where its own
    labels put more than :attr:`collapse` of the pixels in one segment: a criterion
    computed without truth, for the long diffusion running many small objects of
    different materials into one segment."""

    collapse = 0.85

    def segment(self, scene, params, inputs, run):
        out = super().segment(scene, params, inputs, run)
        largest = np.bincount(out.labels.ravel() - out.labels.min()).max() / out.labels.size
        if largest <= self.collapse:
            return out
        long_reach = self.params
        self.params = long_reach.replace(diffusion_range=0.07, diffusion_tau=0.75)
        try:
            return super().segment(scene, params, inputs, run)
        finally:
            self.params = long_reach


def polarisation_size(scene, params, name: str) -> ObjectSize:
    """The scene's object size estimated from the polarisation channels ρ cos 2φ,
    ρ sin 2φ alone: :func:`scene_object_size` given a constant Î, whose channel ln Î
    the estimate then leaves out (kept in the scene's cache under ``name``)."""
    pol = scene.polarisation(params)

    def estimate():
        flat = np.ones(pol.intensity.shape, dtype=np.float32)
        return scene_object_size(flat, pol.dop, pol.phase, pol.invalid, 0.0, scene.region)

    return scene.cached(f"{name}:object_size", id(pol), estimate)


class PolarisationSize(SurfaceSuperpixels):
    """The default's class with the object size estimated from ρ and φ alone
    (:func:`polarisation_size`). Followed as the default follows its own estimate
    (above a tenth of the short side); a size the run gives is kept."""

    def segment(self, scene, params, inputs, run):
        size = polarisation_size(scene, params, self.name)
        own = scene.object_size
        scene.object_size = lambda p: size if p.object_size <= 0 else own(p)
        try:
            return super().segment(scene, params, inputs, run)
        finally:
            del scene.object_size


class SteadierSize(SurfaceSuperpixels):
    """The default's class choosing its object size between the scene's estimate D and
    the estimate from ρ and φ alone D_p (:func:`polarisation_size`) by how little its
    labels change when the size is nudged (a stability criterion, no truth): where both
    are at least :attr:`estimate_floor` of the short side and differ by at least
    :attr:`nudge`, the labels at each size are compared with those at (1 ∓ nudge) times
    it (the mean ARI of the two comparisons over every pixel), and the size with the
    higher agreement is used (a tie keeps D). Six runs of the default where it chooses;
    elsewhere, and when the run gives a size, the default's one run."""

    nudge = 0.1

    def segment(self, scene, params, inputs, run):
        if params.object_size > 0:
            return super().segment(scene, params, inputs, run)
        sizes = (
            scene.object_size(params).size_px,
            polarisation_size(scene, params, self.name).size_px,
        )
        floor = self.estimate_floor * min(scene.polarisation(params).intensity.shape)
        if min(sizes) < floor or abs(sizes[1] / sizes[0] - 1.0) < self.nudge:
            return super().segment(scene, params, inputs, run)
        default = super().segment
        best = None
        for n, size in enumerate(sizes):
            own = default(
                scene, params if n == 0 else params.replace(object_size=size), inputs, run
            )
            nudged = [
                default(scene, params.replace(object_size=f * size), inputs, run).labels.ravel()
                for f in (1.0 - self.nudge, 1.0 + self.nudge)
            ]
            agree = np.mean([adjusted_rand_score(own.labels.ravel(), x) for x in nudged])
            if best is None or agree > best[0]:
                best = (agree, own)
        return best[1]


def medoid(labels: list[np.ndarray], prefer: int = 0) -> int:
    """The index of the label image (all of one shape) whose mean ARI with the others is
    highest, read on every second pixel of every second row (no truth); a tie keeps
    ``prefer``."""
    flat = [np.asarray(x)[::2, ::2].ravel() for x in labels]
    agree = [
        np.mean([adjusted_rand_score(a, b) for j, b in enumerate(flat) if j != i])
        for i, a in enumerate(flat)
    ]
    return max(range(len(flat)), key=lambda i: (agree[i], i == prefer))


class TextureWeightMedoid(SurfaceSuperpixels):
    """The default's class run at the texture group's weights :attr:`weights` (a
    per-scene weight of the texture group, issue 37 point 3, chosen without truth): the
    labels of the weight whose labels agree best with the others' (:func:`medoid`; a tie
    keeps the default's weight). Five runs of the default."""

    weights = (0.0, 0.1, 0.3, 0.5, 1.0)

    def segment(self, scene, params, inputs, run):
        own = self.params
        outputs = []
        try:
            for w in self.weights:
                self.params = own.replace(texture_weight=w)
                outputs.append(super().segment(scene, params, inputs, run))
        finally:
            self.params = own
        prefer = self.weights.index(own.texture_weight)
        return outputs[medoid([o.labels for o in outputs], prefer)]


class ReachConsensus(SuperpixelConsensus):
    """The default's run and runs with other node parameters (:attr:`others`: another
    reach, border scale or node features) on the same superpixels, the labels the runs
    agree on (:func:`~napari_polarseg.engine.unsupervised.consensus.consensus_clustering`,
    as ``superpixel_consensus`` combines superpixel sizes)."""

    others: tuple[dict[str, Any], ...] = ()

    def region_models(self, scene, pol, run, params):
        runs = [params, *(params.replace(**o) for o in self.others)]

        def prepare():
            valid = clustered_pixels(scene.region, pol.invalid)
            maps = (pol.intensity, pol.dop, pol.phase)
            shared = pixel_maps(*maps, params, valid)
            return [prepare_regions(*maps, p, pixels=shared) for p in runs]

        return scene.cached(self.name, (id(pol), params), prepare)


#: The node features of the default (``UnsupervisedParams().features``).
NODE_FEATURES = ("log_intensity", "dop", "dop_spread", "dop_vs_log_intensity_slope")
#: Light-invariant node features beyond the default's: the AoLP's and the Stokes
#: vector's coherence and ρ less its image-wide fit on the brightness.
INVARIANT_POOL = ("aolp_coherence", "dolp_over_dop", "log_dop_given_intensity")
#: The node parameters of the short reach (``superpixels``' reach and border scale).
SHORT_REACH = {"diffusion_range": 0.07, "diffusion_tau": 0.75}

#: The variants tried; ``default`` is the default as it is (its superpixels at their
#: share of the frame whatever the estimated object size).
VARIANTS: dict[str, Variant] = {
    "default": Variant(),
    "superpixels": Variant(method="superpixels"),
    "polarisation borders": Variant(method="polarisation_borders"),
    "smoothed k-means": Variant(method=SmoothedKMeans.name),
    # the default without its texture group; and without it nor the estimated size
    # (the default before both and before the merge's cohesion rule: ``before texture``)
    "no texture": Variant(params={"texture": ()}),
    "before texture": Variant(
        {
            "follows_estimate": False,
            "merge_rule": staticmethod(partial(weakest_border, cohesion_floor=0.0)),
        },
        params={"texture": (), "border_gate": 0.0},
    ),
    "no border gate": Variant(params={"border_gate": 0.0}),
    "frame-share scales": Variant({"follows_estimate": False}),
    "texture weight 0.1": Variant(params={"texture_weight": 0.1}),
    "texture weight medoid": Variant(base=TextureWeightMedoid),
    "texture weight 0.5": Variant(params={"texture_weight": 0.5}),
    "texture weight 1": Variant(params={"texture_weight": 1.0}),
    # the merge without its cohesion rule (the weakest border alone decides; the default
    # before it), and the rule's floor at other shares
    "no cohesion rule": Variant(
        {"merge_rule": staticmethod(partial(weakest_border, cohesion_floor=0.0))}
    ),
    "cohesion 0.3": Variant(
        {"merge_rule": staticmethod(partial(weakest_border, cohesion_floor=0.3))}
    ),
    "cohesion 0.7": Variant(
        {"merge_rule": staticmethod(partial(weakest_border, cohesion_floor=0.7))}
    ),
    "estimated size": Variant({"follows_estimate": True}),
    "truth size": Variant(truth_size=True),
    "size from polarisation": Variant(base=PolarisationSize),
    "steadier size": Variant(base=SteadierSize),
    "reach 0.25": Variant({"follows_estimate": True, "reach_objects": 0.25}),
    "side 12": Variant({"follows_estimate": True, "regions_per_side": 12.0}),
    "texture": Variant(
        params={
            "features": (
                "log_intensity",
                "dop",
                "dop_spread",
                "dop_vs_log_intensity_slope",
                "aolp_coherence",
                "dolp_over_dop",
            )
        }
    ),
    "no intensity": Variant(
        params={"features": ("dop", "dop_spread", "dop_vs_log_intensity_slope")}
    ),
    # the diffusion and the merge of the superpixel methods before the surface one
    "reach 0.07": Variant(params={"diffusion_range": 0.07}),
    "reach 0.07 tau 0.75": Variant(params={"diffusion_range": 0.07, "diffusion_tau": 0.75}),
    "closest centroids": Variant({"merge_rule": staticmethod(closest_centroids)}),
    "reach 0.07 closest centroids": Variant(
        {"merge_rule": staticmethod(closest_centroids)}, params={"diffusion_range": 0.07}
    ),
    "reach 0.12 closest centroids": Variant(
        {"merge_rule": staticmethod(closest_centroids)}, params={"diffusion_range": 0.12}
    ),
    "maf": Variant(params={"projection": "maf"}),
    # the default's node features but log Î, with the light-invariant pool in its place
    "invariant set": Variant(
        params={"features": ("dop", "dop_spread", *INVARIANT_POOL, "dop_vs_log_intensity_slope")}
    ),
    # each node feature weighed by its Moran's I in the scene (:mod:`spatial_weights`)
    **{f"coherence {p:g}": Variant(params={"coherence_power": p}) for p in (0.25, 0.5, 1, 2, 4)},
    **{
        f"pool coherence {p:g}": Variant(
            params={
                "coherence_power": p,
                "features": (*NODE_FEATURES, *INVARIANT_POOL),
            }
        )
        for p in (1, 2, 4)
    },
    "estimated size above 10 %": Variant(gate=0.10),
    "short reach above 85 % in one segment": Variant(collapse=0.85),
    "short reach above 80 % in one segment": Variant(collapse=0.80),
    "estimated size above 10 % reach 1": Variant({"reach_objects": 1.0}, gate=0.10),
    "estimated size above 10 % reach 1.5 side 4": Variant(
        {"reach_objects": 1.5, "regions_per_side": 4.0}, gate=0.10
    ),
    # polarisation texture as one more node feature, each alone
    "+dolp": Variant(params={"features": (*NODE_FEATURES, "dolp")}),
    "+aolp coherence": Variant(params={"features": (*NODE_FEATURES, "aolp_coherence")}),
    "+dolp over dop": Variant(params={"features": (*NODE_FEATURES, "dolp_over_dop")}),
    # the clustering and the diffusion's border scale, tried for the small family
    "gmm": Variant(params={"clustering": "gmm"}),
    "gmm tied": Variant(params={"clustering": "gmm", "covariance": "tied"}),
    "no smoothing": Variant(params={"smoothing": 0.0}),
    "smoothing 0.15": Variant(params={"smoothing": 0.15}),
    "tau 0.5": Variant(params={"diffusion_tau": 0.5}),
    "tau 0.75": Variant(params={"diffusion_tau": 0.75}),
    "tau 2": Variant(params={"diffusion_tau": 2.0}),
    # the projection's kept variance, the clipping, the diffusion's λ, the border
    # refinement and the clusters beyond k
    **{f"variance {v:g}": Variant(params={"variance": v}) for v in (0.9, 0.85, 0.8)},
    "clip 1.5": Variant(params={"clip": 1.5}),
    "clip 3": Variant(params={"clip": 3.0}),
    "lambda 0.3": Variant(params={"diffusion": 0.3}),
    "lambda 0.7": Variant(params={"diffusion": 0.7}),
    "no refinement": Variant(params={"refine_boundaries": False}),
    "variance 0.9 no refinement": Variant(params={"variance": 0.9, "refine_boundaries": False}),
    "clip 1.5 no refinement": Variant(params={"clip": 1.5, "refine_boundaries": False}),
    # nuisance perturbations (the k-means seed; the clipping and the border scale a few
    # per cent off): ``--oracle`` over them is how much the best of five draws of the
    # default gains by chance alone
    **{f"seed {s}": Variant(params={"seed": s}) for s in (1, 2, 3, 4)},
    **{f"clip {c:g}": Variant(params={"clip": c}) for c in (1.9, 2.1)},
    **{f"tau {t:g}": Variant(params={"diffusion_tau": t}) for t in (1.2, 1.3)},
    "k + 2 merged": Variant({"extra_segments": 2}),
    "k directly": Variant({"extra_segments": 0}),
    # each of the default's mean node features left out
    **{
        f"without {name}": Variant(
            params={"features": tuple(f for f in NODE_FEATURES if f != name)}
        )
        for name in NODE_FEATURES
    },
    # the consensus of the long reach and the short one (and one between)
    "consensus long short": Variant(also=(SHORT_REACH,)),
    "consensus long mid short": Variant(also=({"diffusion_range": 0.12}, SHORT_REACH)),
    "consensus long short short+coherence": Variant(
        also=(SHORT_REACH, {**SHORT_REACH, "features": (*NODE_FEATURES, "aolp_coherence")})
    ),
}


def register(name: str, variant: Variant) -> str:
    """Register the variant as a method of its own; its method name."""
    if variant.method == SmoothedKMeans.name:
        register_method(SmoothedKMeans())
    if variant.method:
        return variant.method
    base, attrs = SurfaceSuperpixels, dict(variant.attrs)
    if variant.gate:
        base, attrs["gate"] = GatedSurface, variant.gate
    if variant.collapse:
        base, attrs["collapse"] = CollapseFallback, variant.collapse
    if variant.also:
        base, attrs["others"] = ReachConsensus, variant.also
    if variant.base is not None:
        base = variant.base
    cls = type("Variant", (base,), {"name": f"variant:{name}", "title": name, **attrs})
    method = cls()
    if variant.params:
        method.params = method.params.replace(**variant.params)
    register_method(method)
    return method.name


def score(frame: Frame, scene: Scene, params, method: str, variant: Variant) -> float:
    run = params.replace(method=method)
    if variant.truth_size and np.isfinite(frame.object_size):
        run = run.replace(object_size=float(frame.object_size))
    labels = scene.segment(run).labels
    scored = frame.truth > 0
    return float(adjusted_rand_score(frame.truth[scored], labels[scored]))


def frame_scores(
    frame: Frame, chosen: dict[str, Variant], methods: dict[str, str]
) -> dict[str, float]:
    """The ARI of every chosen variant (registered as ``methods``) on one frame, each
    run from the frame's own parameters: a run leaves its parameters in the pipeline,
    so reading them there after ``truth size`` would give every later variant the
    truth's size."""
    pipe = Pipeline(frame.stack, frame.angles, PRESETS["auto"].replace(n_segments=frame.k))
    scene, params = Scene(pipeline=pipe), pipe.params
    return {n: score(frame, scene, params, methods[n], v) for n, v in chosen.items()}


def development_frames(
    family: str, half: str, test_base: int, read_rounds: list[int]
) -> Iterator[Frame]:
    """The frames of ``family``'s ``half`` and, on the development half of a rendered
    family, those of the test halves of ``read_rounds`` (read before: development
    scenes now)."""
    yield from frames(family, half, test_base)
    if half == "dev" and family != "real":
        for b in read_rounds:
            yield from frames(family, "test", b)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="NAME=ATTR:VALUE[;ATTR:VALUE]",
        help="an extra variant: class attributes (numbers; follows_estimate:1 follows the "
        "estimate), 'truth:1' for the truth's size, 'collapse:S' for the short reach "
        "above S in one segment",
    )
    ap.add_argument(
        "--oracle",
        action="store_true",
        help="also print, by family, the mean of the best variant of each frame (a "
        "per-frame choice made with the truth: what a perfect criterion could reach)",
    )
    ap.add_argument(
        "--read-rounds",
        default="",
        metavar="B[,B...]",
        help="add these test rounds, already read and reported, to the development halves "
        "of every rendered family (more development scenes; never a fresh round)",
    )
    add_check_round(ap)
    args = ap.parse_args(argv)
    half = read_half(args.test_base)
    read_rounds = [int(b) for b in args.read_rounds.split(",") if b]
    chosen = {n: VARIANTS[n] for n in args.variants.split(",") if n}
    for text in args.grid:
        name, spec = text.split("=", 1)
        attrs = dict(part.split(":", 1) for part in spec.split(";") if part)
        truth = attrs.pop("truth", "0") == "1"
        collapse = float(attrs.pop("collapse", 0))
        chosen[name] = Variant(
            {a: float(v) for a, v in attrs.items()}, truth_size=truth, collapse=collapse
        )
    methods = {n: register(n, v) for n, v in chosen.items()}
    results: dict[str, dict[str, list[float]]] = {n: {} for n in chosen}
    names: dict[str, list[str]] = {}
    t0 = time.perf_counter()
    for family in args.families.split(","):
        for frame in development_frames(family, half, args.test_base or 0, read_rounds):
            names.setdefault(family, []).append(frame.name)
            line = []
            for n, value in frame_scores(frame, chosen, methods).items():
                results[n].setdefault(family, []).append(value)
                line.append(f"{n} {value:.3f}")
            print(f"{family} {frame.name}: " + ", ".join(line), flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    families = list(names)
    head = ["variant", *families, "all (mean of families)", "paired vs default (all frames)"]
    print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    base = results.get("default")
    for n in chosen:
        means = [float(np.mean(results[n][f])) for f in families]
        cells = [n, *(f"{m:.3f}" for m in means), f"{np.mean(means):.3f}"]
        if base is not None:
            d = np.concatenate([np.subtract(results[n][f], base[f]) for f in families])
            cells.append(f"{d.mean():+.3f} ± {standard_error(d):.3f}")
        print("| " + " | ".join(cells) + " |")
    if base is not None:
        for n in chosen:
            if n == "default":
                continue
            moved = [
                (results[n][f][i] - base[f][i], f"{f}/{names[f][i]}")
                for f in families
                for i in range(len(names[f]))
            ]
            moved.sort()
            worst = ", ".join(f"{s} {d:+.2f}" for d, s in moved[:3])
            best = ", ".join(f"{s} {d:+.2f}" for d, s in moved[::-1][:3])
            print(f"- {n}: most down {worst}; most up {best}")
    if args.oracle:
        print_oracle(results, families)
    return 0


def print_oracle(results: dict[str, dict[str, list[float]]], families: list[str]) -> None:
    """By family: the mean over its frames of the best variant's ARI on each (chosen with
    the truth), and its paired difference to the default. Part of it is the largest of
    several noisy scores, not a gain a criterion could find."""
    print("\n| family | best variant of each frame | minus default |\n|---|---:|---:|")
    for f in families:
        scores = np.array([results[n][f] for n in results])
        best = scores.max(axis=0)
        d = best - np.asarray(results["default"][f]) if "default" in results else best * np.nan
        print(f"| {f} | {best.mean():.3f} | {d.mean():+.3f} ± {standard_error(d):.3f} |")


if __name__ == "__main__":
    raise SystemExit(main())
