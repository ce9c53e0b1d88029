"""How the default (preset ``auto``, ``surface_superpixels``) was chosen: its neighbours
and the variants tried beside it, on the rendered development half and the real frames.

Every variant is the valid-superpixel method (``engine/methods/valid_superpixels.py``:
invalid pixels left out, k + 1 clusters merged to k, the two closest in features) with
other ``UnsupervisedParams``; the last rows are the wide diffusion with the default's
merge rule (``engine/unsupervised/merge.py``: the weakest border). The rows print the
mean ARI over the development half (seeds 0–11) and over the four labelled real
frames, and each real frame's ARI, scored as in ``materials.py`` (k = the truth's
classes, ARI over the labelled pixels). Then the number of materials found by itself
(``n_segments = 0``) by the silhouette rule with each tolerance (``estimate_k``: the
fewest k within that share of the best score), for the 7 % diffusion of
``valid_superpixels`` and the 20 % one of the default: exact and within ±1 of the true
k. The test half (seeds 12–23) is only read with ``--test``: choose on the development
half, report on the test half. ``--dev-renders`` adds the 72 development renders of
``render_scenes.py`` and ``--dev-pool-2`` the second pool of 100 (``materials.RENDER_SETS``
names both and the commands that make them): twelve development scenes give a
mean with a standard error of about 0.07, seventy-two about 0.03. The rows named
"default with …" change one thing of the default (its merge included); "default with
superpixels × f the area" draws superpixels f times the default's area on each frame
(the default's area follows the frame's size: 32 px on a 240 × 320 render, 418 px on
a 1224 × 1024 camera frame).

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python default_variants.py  # ~10 min
    ... python default_variants.py --variants "reach 20 %, τ 1.25" --test
    ... python default_variants.py --dev-renders --variants "default with τ 1.5;..."
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from evaluate import REAL_DIR
from materials import RENDER_SETS, set_frames
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import Pipeline
from napari_polarseg.engine.methods.surface_superpixels import BORDER_SCALE, REACH
from napari_polarseg.engine.methods.valid_superpixels import choose_k, clustered_pixels
from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.unsupervised.merge import (
    Merge,
    closest_centroids,
    merged_clustering,
    weakest_border,
)
from napari_polarseg.engine.unsupervised.params import UnsupervisedParams
from napari_polarseg.engine.unsupervised.segmenter import prepare_regions

#: A variant: its parameters (or a function of the frame's shape giving them), with
#: optionally its merge rule and the extra clusters merged (``score``).
Params = UnsupervisedParams | Callable[[tuple[int, int]], UnsupervisedParams]
Variant = Params | tuple[Params, Merge] | tuple[Params, Merge, int]

V = UnsupervisedParams()  # valid_superpixels
W = V.replace(diffusion_range=REACH, diffusion_tau=BORDER_SCALE)  # surface_superpixels


def _variants() -> dict[str, Variant]:
    out: dict = {"valid_superpixels (reach 7 %, τ 0.75)": V}
    for reach in (0.10, 0.14, 0.17, 0.20):
        for tau in (0.75, 1.0, 1.25):
            out[f"reach {reach * 100:.0f} %, τ {tau}"] = V.replace(
                diffusion_range=reach, diffusion_tau=tau
            )
    out["reach 20 %, τ 1.5"] = W.replace(diffusion_tau=1.5)
    out["reach 20 %, τ 2"] = W.replace(diffusion_tau=2.0)
    out["reach 20 %, τ 1.25, λ 0.7"] = W.replace(diffusion=0.7)
    out["reach 20 %, τ 1.25, no posterior smoothing"] = W.replace(smoothing=0.0)
    for extra in ("intensity_spread", "dolp", "aolp_coherence", "log_dop_given_intensity"):
        out[f"reach 20 %, τ 1.25, + {extra}"] = W.replace(features=W.features + (extra,))
    out["reach 20 %, τ 1.25, − dop"] = W.replace(
        features=tuple(f for f in W.features if f != "dop")
    )
    out["reach 7 %, log Î counted twice"] = V.replace(features=V.features + ("log_intensity",))
    out["reach 14 %, log Î counted twice"] = V.replace(
        features=V.features + ("log_intensity",), diffusion_range=0.14
    )
    for name, params in (
        ("reach 30 %", W.replace(diffusion_range=0.30)),
        ("clip 3", W.replace(clip=3.0)),
        ("all PCA components", W.replace(variance=1.0)),
        ("no border refinement", W.replace(refine_boundaries=False)),
        ("Gaussian mixture", W.replace(clustering="gmm")),
        ("Gaussian mixture, seed 1", W.replace(clustering="gmm", seed=1)),
        ("seed 1", W.replace(seed=1)),
        ("λ 0.3", W.replace(diffusion=0.3)),
        ("τ 1.5", W.replace(diffusion_tau=1.5)),
        ("no posterior smoothing", W.replace(smoothing=0.0)),
        ("+ intensity_spread", W.replace(features=W.features + ("intensity_spread",))),
        ("+ dop_over_shape_trend", W.replace(features=W.features + ("dop_over_shape_trend",))),
    ):
        out[f"default with {name}"] = (params, weakest_border)
    out["reach 20 %, τ 1.25, weakest-border merge (default)"] = (W, weakest_border)
    out["reach 20 %, τ 1.25, k + 2, weakest-border merge"] = (W, weakest_border, 2)
    for factor in AREA_FACTORS:
        name = f"default with superpixels × {factor:g} the area"
        out[name] = (area_times(factor), weakest_border)
    return out


#: Superpixel areas tried, as multiples of the default's on each frame
#: (``UnsupervisedParams.area_of``: 32 px on a 240 × 320 render, 418 px on a camera frame).
AREA_FACTORS = (1.5, 2.0, 2.5, 3.0, 4.0)


def area_times(factor: float) -> Callable[[tuple[int, int]], UnsupervisedParams]:
    """The default's parameters with ``factor`` × its superpixel area on a frame of the
    given shape (the default's area depends on the frame's size, so the variant does)."""
    return lambda shape: W.replace(region_area=int(factor * W.area_of(shape)))


def frames(
    test: bool, renders: tuple[str, ...] = ()
) -> list[tuple[str, str, tuple, np.ndarray, int]]:
    """(set, name, (Î, ρ, φ, invalid), truth, k) of the development half, the real
    frames, with ``test`` the test half and the development render sets named in
    ``renders`` (``materials.RENDER_SETS``); polarisation as preset ``auto`` fits it."""
    out = []
    for group in ["dev", *(["test"] if test else []), *renders, "real"]:
        for name, stack, angles, truth, k in set_frames(group, REAL_DIR):
            pol = Pipeline(stack, angles, PRESETS["auto"].replace(n_segments=k))
            pol = pol.get("polarisation")
            maps = (pol.intensity, pol.dop, pol.phase, np.asarray(pol.invalid, bool))
            out.append((group, name, maps, truth, k))
    return out


def score(variant, data: list, tolerances=(0.0,)) -> dict:
    """ARI per frame of the k + extra → k clustering of ``variant`` (parameters, or
    (parameters, merge rule[, extra]); parameters may be a function of the frame's
    shape), and the k found per tolerance."""
    if not isinstance(variant, tuple):
        variant = (variant, closest_centroids)
    params, merge, extra = (*variant, 1)[:3]
    row: dict = {"ari": {}, "k": {t: {} for t in tolerances}}
    for _group, name, (i, d, ph, invalid), truth, k in data:
        used = params(i.shape) if callable(params) else params
        model = prepare_regions(i, d, ph, used, clustered_pixels(None, invalid))
        labels = merged_clustering(model, k, extra, merge).labels
        scored = truth > 0
        row["ari"][name] = float(adjusted_rand_score(truth[scored], labels[scored]))
        for t in tolerances:
            row["k"][t][name] = choose_k(model, t)["k"]
    return row


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", help="names separated by ; (default: all)")
    parser.add_argument("--test", action="store_true", help="also score the test half")
    development = [n for n, s in RENDER_SETS.items() if s.role == "development"]
    for name in development:
        parser.add_argument(
            f"--{name}",
            action="store_true",
            help=f"also score the {RENDER_SETS[name].title} (made by "
            f"`{RENDER_SETS[name].command}`)",
        )
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    renders = tuple(n for n in development if getattr(args, n.replace("-", "_")))
    data = frames(args.test, renders)
    order = ("dev", *development, "test", "real")
    groups = [g for g in order if any(f[0] == g for f in data)]
    real = [f[1] for f in data if f[0] == "real"]
    variants = _variants()
    names = args.variants.split(";") if args.variants else list(variants)
    print(
        "| variant | " + " | ".join(f"{g} mean" for g in groups) + " | " + " | ".join(real) + " |"
    )
    print("|---|" + "---:|" * (len(groups) + len(real)))
    for name in names:
        r = score(variants[name], data)["ari"]
        means = [np.mean([r[f[1]] for f in data if f[0] == g]) for g in groups]
        cells = [f"{m:.3f}" for m in means] + [f"{r[n]:.3f}" for n in real]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    tolerances = (0.0, 0.05, 0.10, 0.15)
    print("\nk found by itself (n_segments = 0), exact / within ±1 of the true k:\n")
    print("| diffusion | tolerance | " + " | ".join(groups) + " |")
    print("|---|---:|" + "---:|" * len(groups))
    for label, params in (("reach 7 % (valid_superpixels)", V), ("reach 20 % (default)", W)):
        found = score(params, data, tolerances)["k"]
        for t in tolerances:
            cells = []
            for g in groups:
                fs = [f for f in data if f[0] == g]
                exact = sum(found[t][f[1]] == f[4] for f in fs)
                near = sum(abs(found[t][f[1]] - f[4]) <= 1 for f in fs)
                cells.append(f"{exact} / {near} of {len(fs)}")
            print(f"| {label} | {t:.2f} | " + " | ".join(cells) + " |", flush=True)
    print(f"\n{time.perf_counter() - t0:.1f} s wall")


if __name__ == "__main__":
    main()
