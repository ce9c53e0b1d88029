"""Can a scene say, without its truth, whether the diffusion should reach far or near?

The default's diffusion over 20 % of the image side wins on scenes whose materials
cover large regions (the diffuse *leaves* layout, the textured renders, few large
objects) and loses where they are mixed object by object (many small objects, the
diffuse *scattered leaves* and *texture patches*). This bench reads, on the
development halves of every family (:mod:`families`), the default (``long``: the
surface method's parameters, weakest-border merge) against the valid-superpixel method
(``short``: reach 7 % of the side, τ 0.75, closest-centroid merge) and three criteria a
scene can compute by itself, each choosing the setting it scores higher:

- ``stability``: the mean ARI between the labels at superpixel areas × 0.6, 1 and 1.7
  (a split that follows the materials should not move with the superpixels' size);
- ``silhouette``: the silhouette of the k clusters on the projected node features;
- ``separation``: R² of the clustering, the share of the node features' weighted
  variance between the clusters;
- ``shared``: the silhouette of both settings' labels on the *same* features, the short
  setting's node features (the two settings share their superpixels, so their node
  labels can be scored on one feature space; each setting's own silhouette reads a
  space of its own);
- ``agreement``: the mean ARI of the setting's labels with two pixel clusterings made
  apart from both settings, on cues that do not change with the light: k-means into k
  of the AoLP coherence |G_σ(ρ e^{2iφ})| / G_σ(ρ) and of log of the local spread of ρ,
  each at σ = 2, 4, 8 px (:func:`panel_labels`); the short setting is chosen only where
  it agrees more by :data:`AGREEMENT_MARGIN`.

It prints each frame's ARI for both settings and the criteria, then the mean ARI by
family of each setting, of each criterion's choice and of the better of the two on
every frame (``either``: read from the truth, the most any choice between the two
settings can give). The development halves are read; ``--test-base B`` reads round B's
test halves instead, only to check a criterion on a test half already read.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python reach_selection.py \\
        [--families objects,small,textured,diffuse,real] [--test-base B]
"""

from __future__ import annotations

import argparse
import itertools
import time
from typing import Any

import numpy as np
from families import FAMILIES, Frame, add_check_round, frames, read_half
from scipy import ndimage
from sklearn.cluster import KMeans
from sklearn.metrics import adjusted_rand_score, silhouette_score

from napari_polarseg.engine import Pipeline, Scene
from napari_polarseg.engine.methods.surface_superpixels import SurfaceSuperpixels
from napari_polarseg.engine.methods.valid_superpixels import ValidSuperpixels, clustered_pixels
from napari_polarseg.engine.params import PRESETS
from napari_polarseg.engine.unsupervised.merge import (
    closest_centroids,
    merged_clustering,
    weakest_border,
)
from napari_polarseg.engine.unsupervised.segmenter import prepare_regions

#: Superpixel areas read for the stability criterion, × the setting's own area.
AREA_FACTORS = (0.6, 1.0, 1.7)
SETTINGS = {
    "long": (SurfaceSuperpixels().params, weakest_border),
    "short": (ValidSuperpixels().params, closest_centroids),
}
CRITERIA = ("stability", "silhouette", "separation", "shared", "agreement")
#: How much more the short setting must agree with the pixel clusterings (ARI) to be
#: chosen by ``agreement`` (chosen on the development halves among 0.02–0.2).
AGREEMENT_MARGIN = 0.05
#: Gaussian σ (px) of the pixel clusterings' features.
PANEL_SIGMAS = (2.0, 4.0, 8.0)


def separation(z: np.ndarray, weight: np.ndarray, labels: np.ndarray) -> float:
    """R² = 1 − Σ_c Σ_{i∈c} w_i |z_i − z̄_c|² / Σ_i w_i |z_i − z̄|² (dimensionless)."""
    w = weight / weight.sum()
    total = float((w[:, None] * (z - (w[:, None] * z).sum(0)) ** 2).sum())
    within = 0.0
    for c in np.unique(labels):
        m = labels == c
        centre = (w[m, None] * z[m]).sum(0) / w[m].sum()
        within += float((w[m, None] * (z[m] - centre) ** 2).sum())
    return 1.0 - within / max(total, 1e-12)


def read_setting(frame: Frame, name: str) -> dict[str, Any]:
    """ARI at the setting's own superpixel area, the criteria computed on its own
    features, and its node labels and features (for ``shared``)."""
    pipe = Pipeline(frame.stack, frame.angles, PRESETS["auto"].replace(n_segments=frame.k))
    pol = Scene(pipeline=pipe).polarisation(pipe.params)
    valid = clustered_pixels(None, pol.invalid)
    params, merge = SETTINGS[name]
    shape = pol.intensity.shape
    labels, model, result = [], None, None
    for f in AREA_FACTORS:
        p = params.replace(region_area=max(9, int(params.area_of(shape) * f)))
        m = prepare_regions(pol.intensity, pol.dop, pol.phase, p, valid)
        r = merged_clustering(m, frame.k, merge=merge)
        labels.append(r.labels)
        if f == 1.0:
            model, result = m, r
    scored = frame.truth > 0
    inside = valid if valid is not None else np.ones(shape, bool)
    nodes = result.node_labels[: model.z.shape[0]]
    return {
        "ari": float(adjusted_rand_score(frame.truth[scored], result.labels[scored])),
        "stability": float(
            np.mean(
                [
                    adjusted_rand_score(a[inside], b[inside])
                    for a, b in itertools.combinations(labels, 2)
                ]
            )
        ),
        "silhouette": silhouette(model.z, nodes),
        "separation": separation(model.z, model.weight, nodes),
        "nodes": nodes,
        "z": model.z,
        "labels": result.labels,
    }


def silhouette(z: np.ndarray, nodes: np.ndarray) -> float:
    """The silhouette of the node labels ``nodes`` on the node features ``z`` (3000
    nodes sampled; −1 for a single cluster)."""
    if np.unique(nodes).size < 2:
        return -1.0
    sample = min(3000, nodes.size)
    return float(silhouette_score(z, nodes, sample_size=sample, random_state=0))


def add_shared(read: dict[str, dict[str, Any]]) -> None:
    """Each setting's ``shared`` criterion: its labels' silhouette on the short setting's
    node features (both settings draw the same superpixels)."""
    z = read["short"]["z"]
    for r in read.values():
        r["shared"] = silhouette(z, r["nodes"]) if r["nodes"].size == z.shape[0] else -1.0


def panel_labels(frame: Frame) -> tuple[list[np.ndarray], np.ndarray]:
    """The ``agreement`` criterion's pixel clusterings of ``frame`` (module docstring)
    and the clustered pixels (H, W) bool they and the settings are compared on."""
    pipe = Pipeline(frame.stack, frame.angles, PRESETS["auto"].replace(n_segments=frame.k))
    pol = Scene(pipeline=pipe).polarisation(pipe.params)
    rho, phi = pol.dop.astype(np.float64), pol.phase.astype(np.float64)
    valid = ~np.asarray(pol.invalid, bool)

    def g(a: np.ndarray, s: float) -> np.ndarray:
        return ndimage.gaussian_filter(a, s)

    coherence = [
        np.hypot(g(rho * np.cos(2 * phi), s), g(rho * np.sin(2 * phi), s))
        / np.maximum(g(rho, s), 1e-4)
        for s in PANEL_SIGMAS
    ]
    spread = [
        np.log(np.sqrt(np.maximum(g(rho * rho, s) - g(rho, s) ** 2, 0)) + 1e-4)
        for s in PANEL_SIGMAS
    ]
    labels = []
    for planes in (coherence, spread):
        x = np.stack(planes, axis=-1).reshape(-1, len(planes))
        fit = x[valid.ravel()]
        mean, std = fit.mean(axis=0), fit.std(axis=0) + 1e-6
        km = KMeans(frame.k, n_init=10, random_state=0).fit((fit - mean) / std)
        labels.append(km.predict((x - mean) / std).reshape(valid.shape))
    return labels, valid


def add_agreement(read: dict[str, dict[str, Any]], frame: Frame) -> None:
    """Each setting's ``agreement``: the mean ARI of its labels with
    :func:`panel_labels` over the clustered pixels."""
    panel, valid = panel_labels(frame)
    for r in read.values():
        r["agreement"] = float(
            np.mean([adjusted_rand_score(q[valid], r["labels"][valid]) for q in panel])
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    add_check_round(ap)
    args = ap.parse_args(argv)
    half = read_half(args.test_base)
    t0 = time.perf_counter()
    means: dict[str, dict[str, list[float]]] = {}
    for family in args.families.split(","):
        rows = means.setdefault(family, {})
        for frame in frames(family, half, args.test_base or 0):
            read = {name: read_setting(frame, name) for name in SETTINGS}
            add_shared(read)
            add_agreement(read, frame)
            for name in SETTINGS:
                rows.setdefault(name, []).append(read[name]["ari"])
            rows.setdefault("either", []).append(max(r["ari"] for r in read.values()))
            for c in CRITERIA:
                margin = AGREEMENT_MARGIN if c == "agreement" else 0.0
                pick = "short" if read["short"][c] > read["long"][c] + margin else "long"
                rows.setdefault(c, []).append(read[pick]["ari"])
            cells = ", ".join(
                f"{n} ARI {r['ari']:.3f} stab {r['stability']:.2f} sil {r['silhouette']:.2f} "
                f"R² {r['separation']:.2f} shared {r['shared']:.2f} "
                f"agreement {r['agreement']:.2f}"
                for n, r in read.items()
            )
            print(f"{family} {frame.name}: {cells}", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    cols = [*SETTINGS, *(f"chosen by {c}" for c in CRITERIA), "either (truth)"]
    print("| family | " + " | ".join(cols) + " |\n|---|" + "---:|" * len(cols))
    for family, rows in means.items():
        cells = [f"{np.mean(rows[k]):.3f}" for k in (*SETTINGS, *CRITERIA, "either")]
        print(f"| {family} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
