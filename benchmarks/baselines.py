"""The baselines every quality figure of evaluate.py stands beside.

- :func:`plain_baseline`: the "plain pixel classifier" of issue 12 — a scikit-learn random
  forest (100 trees, seed 0) on Gaussian-smoothed (σ = 1, 2, 4, 8, 16 px) log Î, log ρ,
  log Stokes-averaged DoLP and the local spread of ρ (20 features), trained on the same
  strokes as the method it is compared with. Written with SciPy directly, not with the
  engine's feature code, so it stays a fixed yardstick when that code changes.
- :func:`intensity_kmeans`: k-means (k = number of classes, 10 restarts, seed 0) on
  log Î smoothed at σ = 2 and 8 px — "intensity alone", no polarisation, no training.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
from scipy import ndimage
from sklearn.cluster import KMeans
from sklearn.ensemble import RandomForestClassifier

PLAIN_SIGMAS = (1, 2, 4, 8, 16)
EPS = 1e-6


def plain_features(intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """(H, W, 20) float32: the plain baseline's features (module docstring)."""
    s1 = intensity * dop * np.cos(2 * phase)
    s2 = intensity * dop * np.sin(2 * phase)
    out = []
    for s in PLAIN_SIGMAS:

        def g(a, s=s):
            return ndimage.gaussian_filter(a, s)

        gi = g(intensity)
        rho = g(dop)
        out += [
            np.log(np.maximum(gi, EPS)),
            np.log(np.maximum(rho, EPS)),
            np.log(np.maximum(np.hypot(g(s1), g(s2)) / np.maximum(gi, EPS), EPS)),
            np.sqrt(np.maximum(g(dop * dop) - rho * rho, 0)),
        ]
    return np.stack(out, axis=-1).astype(np.float32)


def plain_baseline(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, strokes: np.ndarray
) -> np.ndarray:
    """Labels (class index of the ascending stroke values) of the plain random forest."""
    f = plain_features(intensity, dop, phase)
    marked = strokes > 0
    model = RandomForestClassifier(100, n_jobs=-1, random_state=0)
    model.fit(f[marked], strokes[marked])
    pred = model.predict(f.reshape(-1, f.shape[-1])).reshape(strokes.shape)
    return np.searchsorted(model.classes_, pred)


def intensity_kmeans(intensity: np.ndarray, k: int) -> np.ndarray:
    """k-means labels of smoothed log Î (module docstring)."""
    log_i = np.log(np.maximum(intensity, EPS))
    f = np.stack([ndimage.gaussian_filter(log_i, s) for s in (2, 8)], axis=-1)
    x = f.reshape(-1, 2)
    x = (x - x.mean(axis=0)) / (x.std(axis=0) + EPS)
    km = KMeans(k, n_init=10, random_state=0).fit(x[:: max(1, x.shape[0] // 200_000)])
    return km.predict(x).reshape(intensity.shape)


def real_frames(folder: Path) -> Iterator[tuple]:
    """(truth file, stack data) of every bundled hand-labelled real frame in ``folder``
    (read with the truth file's mosaic layout); a missing frame is reported and skipped."""
    from napari_polarseg import io as pio
    from napari_polarseg.truth import read_truth_file, truth_files

    for path in truth_files():
        truth_file = read_truth_file(path)
        frame = Path(folder) / truth_file.frame
        if not frame.is_file():
            print(f"real frame {frame} not found: skipped")
            continue
        yield truth_file, pio.read_stack(frame, mosaic=list(truth_file.mosaic))
