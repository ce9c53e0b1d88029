"""Which node features carry the materials, family by family, and whether a criterion
computed without truth sees it: for every node feature of the unsupervised methods
(:data:`~napari_polarseg.engine.unsupervised.params.NODE_FEATURES` but the close-up
trend) on the default's superpixels of each development frame,

- **η²** (read from the truth): the share of the feature's spread over the superpixels
  that the materials explain, Σ_c w_c (m_c − m)² / Σ_a w_a (x_a − m)², over the
  superpixels at least 80 % of one material, weighted by their pixels;
- **Moran's I** (no truth): how alike the feature is on neighbouring superpixels
  (:func:`~napari_polarseg.engine.unsupervised.spatial_weights.morans_i`), the
  criterion of ``coherence_power``;

and, per frame, the Spearman correlation of the two over the features (does the
criterion rank the features as the truth does?), averaged by family.

``--zenith`` asks, on the diffuse family's development scenes (the engine's generator,
which knows each pixel's true zenith θ), how well the materials could be told apart by
the physics of diffuse polarisation: ρ = κ · ρ_F(θ; n = 1.5), κ set by the material's
refractive index, depolarisation and roughness. It prints the η² of a superpixel's
log κ = log(mean ρ / mean ρ_F(θ)) with the true zenith (what the data hold), with the
zenith from the shading of a frontal light, cos θ = Î / the 99.9th percentile of the
superpixels' mean Î (what a method without the zenith reads), and of
``log_dop_given_intensity`` (the node feature that stands for it), by layout.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python feature_separation.py \\
        [--families diffuse,small,objects,textured,real] [--zenith]
"""

from __future__ import annotations

import argparse

import numpy as np
from families import FAMILIES, frames
from scipy.stats import spearmanr

from napari_polarseg.engine import Pipeline
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.physics.fresnel import diffuse_dop
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.engine.unsupervised.params import CLOSE_UP_FEATURES, NODE_FEATURES
from napari_polarseg.engine.unsupervised.region_features import node_features
from napari_polarseg.engine.unsupervised.segmenter import prepare_regions, standardise_columns
from napari_polarseg.engine.unsupervised.spatial_weights import morans_i

#: The features compared (the close-up trend is made for one surface, not a scene).
FEATURES = tuple(n for n in NODE_FEATURES if n not in CLOSE_UP_FEATURES)
#: A superpixel counts for η² when this share of its labelled pixels is one material.
PURITY = 0.8


def standardised(x: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Columns of ``x`` standardised and clipped as the default's node features are
    (:func:`~napari_polarseg.engine.unsupervised.segmenter.standardise_columns`, its
    ``clip``); non-finite → 0."""
    clip = SurfaceSuperpixels().params.clip
    return np.clip(standardise_columns(np.where(np.isfinite(x), x, 0.0), weight), -clip, clip)


def eta_squared(x: np.ndarray, material: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(c,) the share of each column's ``weight``-ed variance that ``material`` explains."""
    mean = np.average(x, axis=0, weights=weight)
    total = np.average((x - mean) ** 2, axis=0, weights=weight) * weight.sum()
    between = np.zeros(x.shape[1])
    for c in np.unique(material):
        w = weight[material == c]
        between += w.sum() * (np.average(x[material == c], axis=0, weights=w) - mean) ** 2
    return between / np.maximum(total, 1e-12)


def default_superpixels(stack: np.ndarray, angles: np.ndarray, k: int):
    """(polarisation image, the default's :class:`RegionModel`, pixels a superpixel) of
    one frame."""
    pipe = Pipeline(stack, angles, PRESETS["auto"].replace(n_segments=k))
    pol = pipe.get("polarisation")
    model = prepare_regions(pol.intensity, pol.dop, pol.phase, SurfaceSuperpixels().params)
    pixels = np.bincount(model.regions.ravel(), minlength=model.n)[: model.n].astype(float)
    return pol, model, pixels


def pure_materials(
    labels: np.ndarray, regions: np.ndarray, n: int, scored: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(n,) whether each of the n superpixels is at least :data:`PURITY` one material of
    its ``scored`` pixels' ``labels`` (and has any), and that material."""
    flat, truth = regions.ravel(), labels.ravel()
    keep = scored.ravel() & (flat < n)
    counts = np.zeros((n, int(truth.max()) + 1))
    np.add.at(counts, (flat[keep], truth[keep]), 1)
    total = counts.sum(axis=1)
    pure = (counts.max(axis=1) >= PURITY * np.maximum(total, 1)) & (total > 0)
    return pure, counts.argmax(axis=1)


def frame_figures(frame) -> tuple[np.ndarray, np.ndarray]:
    """(η², Moran's I) of every feature of :data:`FEATURES` on one frame."""
    pol, model, pixels = default_superpixels(frame.stack, frame.angles, frame.k)
    x = node_features(pol.intensity, pol.dop, pol.phase, model.regions, FEATURES)[: model.n]
    xs = standardised(x, np.maximum(pixels, 1.0))
    pure, material = pure_materials(frame.truth, model.regions, model.n, frame.truth > 0)
    eta = eta_squared(xs[pure], material[pure], pixels[pure])
    return eta, morans_i(xs, model.adjacency)


def zenith_figures(scene) -> tuple[float, float, float]:
    """η² of log κ with the true zenith, with the zenith from a frontal light's shading,
    and of ``log_dop_given_intensity``, on one synthetic scene's default superpixels
    (module docstring)."""
    pol, model, pixels = default_superpixels(scene.stack, scene.angles, 2)
    flat, n = model.regions.ravel(), model.n

    def means(a: np.ndarray) -> np.ndarray:
        return np.bincount(flat, weights=a.ravel(), minlength=n)[:n] / np.maximum(pixels, 1)

    rho, lit = means(pol.dop), means(pol.intensity)
    true_rho = means(diffuse_dop(np.clip(scene.zenith, 0, np.pi / 2 - 1e-3), 1.5))
    cos_shade = np.clip(lit / np.percentile(lit[pixels > 0], 99.9), 0.05, 1.0)
    shade_rho = diffuse_dop(np.minimum(np.arccos(cos_shade), np.pi / 2 - 1e-3), 1.5)
    given = node_features(
        pol.intensity, pol.dop, pol.phase, model.regions, ("log_dop_given_intensity",)
    )
    columns = np.stack(
        [
            np.log(np.maximum(rho, 1e-4) / np.maximum(true_rho, 1e-4)),
            np.log(np.maximum(rho, 1e-4) / np.maximum(shade_rho, 1e-4)),
            given[:n, 0],
        ],
        axis=1,
    )
    every = np.ones(scene.labels.shape, dtype=bool)  # every synthetic pixel is labelled
    pure, material = pure_materials(scene.labels, model.regions, n, every)
    xs = standardised(columns, np.maximum(pixels, 1.0))
    return tuple(eta_squared(xs[pure], material[pure], pixels[pure]))


def zenith_table() -> None:
    """The ``--zenith`` table (module docstring), by layout of the diffuse family."""
    from diffuse_family import SHAPE, scene_draws

    rows: dict[str, list[tuple[float, float, float]]] = {}
    for layout, size, _, seed in scene_draws("dev"):
        scene = make_scene(layout, shape=SHAPE, seed=seed, object_size=size)
        rows.setdefault(layout, []).append(zenith_figures(scene))
        print(f"{layout} seed {seed}: " + ", ".join(f"{v:.2f}" for v in rows[layout][-1]))
    print(
        "\n| layout | log κ, true zenith | log κ, zenith from shading | log_dop_given_intensity |"
    )
    print("|---|---:|---:|---:|")
    for layout, figures in rows.items():
        cells = " | ".join(f"{v:.2f}" for v in np.mean(figures, axis=0))
        print(f"| {layout} | {cells} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--zenith", action="store_true", help="the diffuse family's physics table")
    args = ap.parse_args(argv)
    if args.zenith:
        zenith_table()
        return 0
    rows: dict[str, tuple[np.ndarray, np.ndarray, float]] = {}
    for family in args.families.split(","):
        etas, morans, ranks = [], [], []
        for frame in frames(family, "dev"):
            eta, moran = frame_figures(frame)
            etas.append(eta)
            morans.append(moran)
            ranks.append(spearmanr(eta, moran).correlation)
            print(f"{family} {frame.name}: Spearman {ranks[-1]:+.2f}", flush=True)
        rows[family] = (np.mean(etas, axis=0), np.mean(morans, axis=0), float(np.nanmean(ranks)))
    families = list(rows)
    print("\n| feature | " + " | ".join(f"{f} η² / I" for f in families) + " |")
    print("|---|" + "---:|" * len(families))
    for j, name in enumerate(FEATURES):
        cells = [f"{rows[f][0][j]:.2f} / {rows[f][1][j]:.2f}" for f in families]
        print(f"| {name} | " + " | ".join(cells) + " |")
    ranks = " | ".join(f"{rows[f][2]:+.2f}" for f in families)
    print(f"| Spearman (η², I) per frame | {ranks} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
