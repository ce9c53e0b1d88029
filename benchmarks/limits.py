"""What limits unsupervised material segmentation on the synthetic scenes, measured.

Issue 6 asks for ARI >= 0.8 from the best unsupervised option, or figures explaining what
limits it. This script gives those figures (docs/quality.md, "Why not 0.8"). For each scene, block
side w = 12, it trains a *supervised* classifier (standardised logistic regression) on
the blocks of one rendering (seed 1) and tests it on another (seed 2), then the other way
round, and reports the mean pixel ARI on the held-out rendering. A supervised classifier
that knows the answer on a whole training scene is an upper bound for what an
unsupervised method can extract from the same features. Feature sets:

- ``available``: everything the pipeline can compute — zonal harmonic coefficients
  (degree 8) and every polarisation statistic (engine.features.polstats);
- ``oracle geometry``: the true zenith θ of every pixel from the generator (no method
  has it) and the measured ρ: per block the least-squares factor ``k`` in
  ``ρ ≈ k · ρ_Fresnel(θ_true, 1.45)`` — the material's polarisation at a *known* tilt,
  plus the block's mean Î (ρ projected on the true azimuth, ``ρ cos 2(φ − azimuth)``,
  which, unlike ρ itself, is not biased upwards by noise);
- ``oracle geometry, no noise``: the same with the generator's noise-free ρ.

It also reports the share of blocks whose mean true zenith is below 15°, where diffuse ρ
is below 0.005 (about the per-pixel noise of ρ at 0.3 % read noise and 7 angles), so
that no polarisation measurement can tell the materials apart there.

Usage::

    .venv/bin/python benchmarks/limits.py      # ~1 minute
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import adjusted_rand_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from napari_polarseg.engine import Pipeline
from napari_polarseg.engine.features import harmonics, polstats
from napari_polarseg.engine.features.pca import harmonic_features
from napari_polarseg.engine.params import RECOMMENDED
from napari_polarseg.engine.synthetic.optics import diffuse_dop_from_transmission
from napari_polarseg.engine.synthetic.scenes import SCENES, make_scene

WINDOW = 12
SEEDS = (1, 2)


def _blocks(a: np.ndarray, w: int) -> np.ndarray:
    r, c = a.shape[0] // w, a.shape[1] // w
    return a[: r * w, : c * w].reshape(r, w, c, w).transpose(0, 2, 1, 3).reshape(r * c, -1)


def scene_features(name: str, seed: int) -> dict:
    sc = make_scene(name, seed=seed)
    pipe = Pipeline(sc.stack, sc.angles, RECOMMENDED.replace(window=WINDOW))
    pol, nrm = pipe.get("polarisation"), pipe.get("normals")
    zonal = harmonic_features(pipe.get("harmonics"), "zonal").reshape(-1, 9)
    stats = polstats.block_polarisation_statistics(
        pol.intensity, pol.dop, pol.phase, nrm.zenith, WINDOW
    ).reshape(zonal.shape[0], -1)
    theta = _blocks(sc.zenith, WINDOW)
    fresnel = diffuse_dop_from_transmission(np.clip(theta, 0, np.pi / 2 - 1e-3), 1.45)

    azimuth = _blocks(sc.azimuth, WINDOW)

    def factor(dop: np.ndarray, phase: np.ndarray) -> np.ndarray:
        # ρ projected on the true polarisation direction: Re(ρ e^{2i(φ − azimuth)}) is
        # unbiased under noise (|ρ e^{2iφ}| is biased upwards where ρ ~ its noise)
        r = _blocks(dop, WINDOW) * np.cos(2.0 * (_blocks(phase, WINDOW) - azimuth))
        return (r * fresnel).sum(1) / np.maximum((fresnel**2).sum(1), 1e-12)

    mean_i = _blocks(pol.intensity, WINDOW).mean(1)
    truth = np.array([np.bincount(b).argmax() for b in _blocks(sc.labels, WINDOW)])
    grid = (sc.labels.shape[0] // WINDOW, sc.labels.shape[1] // WINDOW)
    return {
        "available": np.column_stack([zonal, stats]),
        "oracle geometry": np.column_stack([factor(pol.dop, pol.phase), mean_i]),
        "oracle geometry, no noise": np.column_stack([factor(sc.dop, sc.phase), mean_i]),
        "block truth": truth,
        "pixel truth": sc.labels,
        "grid": grid,
        "flat share": float(np.mean(theta.mean(1) < np.deg2rad(15.0))),
    }


def held_out_ari(train: dict, test: dict, key: str) -> float:
    clf = make_pipeline(StandardScaler(), LogisticRegression(max_iter=5000, C=10.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clf.fit(train[key], train["block truth"])
    block = clf.predict(test[key]).reshape(test["grid"])
    labels = harmonics.upsample_block_labels(block, test["pixel truth"].shape, WINDOW)
    return float(adjusted_rand_score(test["pixel truth"].ravel(), labels.ravel()))


def main() -> None:
    keys = ("available", "oracle geometry", "oracle geometry, no noise")
    print(f"supervised upper bounds, w = {WINDOW}, trained on one seed, tested on the other")
    print("(mean pixel ARI of seed 1 -> 2 and 2 -> 1)\n")
    header = "| scene | " + " | ".join(keys) + " | blocks with mean zenith < 15° |"
    print(header)
    print("|---|" + "---:|" * (len(keys) + 1))
    for name in SCENES:
        a, b = (scene_features(name, s) for s in SEEDS)
        cells = [np.mean([held_out_ari(a, b, k), held_out_ari(b, a, k)]) for k in keys]
        flat = np.mean([a["flat share"], b["flat share"]])
        print(f"| {name} | " + " | ".join(f"{c:.3f}" for c in cells) + f" | {flat:.0%} |")


if __name__ == "__main__":
    main()
