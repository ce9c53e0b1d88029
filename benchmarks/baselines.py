"""The baselines every quality figure of evaluate.py stands beside.

- :func:`plain_baseline`: the "plain pixel classifier" of issue 12 — a scikit-learn random
  forest (100 trees, seed 0) on Gaussian-smoothed (σ = 1, 2, 4, 8, 16 px) log Î, log ρ,
  log Stokes-averaged DoLP and the local spread of ρ (20 features), trained on the same
  strokes as the method it is compared with. Written with SciPy directly, not with the
  engine's feature code, so it stays a fixed yardstick when that code changes.
- :func:`intensity_kmeans`: k-means (k = number of classes, 10 restarts, seed 0) on
  log Î smoothed at σ = 2 and 8 px — "intensity alone", no polarisation, no training.
- :func:`smoothed_kmeans`: k-means (10 restarts, seed 0) on the plain baseline's 20
  features, standardised — the plain *unsupervised* yardstick: what clustering the
  smoothed polarisation features does with no superpixels, no graph and no training.
- :func:`truth_bound_halves`: a random forest on the same 20 features (or those plus the
  engine's pixel features, or those plus the default method's own superpixel node
  features; a forest, or gradient-boosted trees) trained on the *truth* of a scene's left
  half and scored on its right half: what these features can tell apart given labels,
  without scoring pixels the classifier saw.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
from scipy import ndimage
from sklearn.cluster import KMeans
from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
from threadpoolctl import threadpool_limits

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
    return _kmeans(x, x, k).reshape(intensity.shape)


def _kmeans(fit: np.ndarray, x: np.ndarray, k: int) -> np.ndarray:
    """k-means (10 restarts, seed 0) fitted on ``fit`` (evenly subsampled to about
    200 000 rows), nearest centre of every row of ``x``. One OpenMP thread: on a small
    shared machine k-means' threads cost more than they gain (2 s against 0.2 s for a
    240 × 320 scene, measured with other jobs running)."""
    with threadpool_limits(1, user_api="openmp"):
        km = KMeans(k, n_init=10, random_state=0).fit(fit[:: max(1, fit.shape[0] // 200_000)])
        return km.predict(x)


def smoothed_kmeans(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    k: int,
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """Labels (H, W) of k-means on the plain baseline's 20 smoothed features.

    The features of :func:`plain_features` (log Î, log ρ, log Stokes-averaged DoLP and
    the local spread of ρ, each Gaussian-smoothed at σ = 1, 2, 4, 8, 16 px) are
    standardised (zero mean, unit variance over the fitted pixels) and clustered by
    k-means into ``k`` clusters (10 restarts, seed 0). The centres are fitted on the
    pixels where ``valid`` is True (all when None; at most about 200 000 of them, evenly
    subsampled) and every pixel gets its nearest centre. Unsupervised and spatially
    naive: no superpixels, no graph, no smoothing of the labels.
    """
    f = plain_features(intensity, dop, phase)
    x = f.reshape(-1, f.shape[-1]).astype(np.float64)
    fit = x if valid is None else x[np.asarray(valid, bool).ravel()]
    mean, std = fit.mean(axis=0), fit.std(axis=0) + EPS
    return _kmeans((fit - mean) / std, (x - mean) / std, k).reshape(intensity.shape)


#: Feature sets of :func:`truth_bound_halves`.
BOUND_FEATURE_SETS = ("plain", "rich", "regions")
#: Classifiers of :func:`truth_bound_halves`.
BOUND_CLASSIFIERS = ("forest", "boosting")
#: Training pixels sampled from the left half's truth.
BOUND_HALF_PIXELS = 20_000


def default_region_model(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, invalid: np.ndarray | None = None
):
    """The default method's (preset ``auto``) superpixels and projected node features
    (``unsupervised.segmenter.RegionModel``) on the pixels it clusters (not ``invalid``)."""
    from napari_polarseg.engine.methods.registry import get_method
    from napari_polarseg.engine.methods.valid_superpixels import clustered_pixels
    from napari_polarseg.engine.params import PRESETS
    from napari_polarseg.engine.unsupervised.segmenter import prepare_regions

    default = get_method(PRESETS["auto"].method)
    bad = np.zeros(np.shape(intensity), bool) if invalid is None else np.asarray(invalid, bool)
    return prepare_regions(intensity, dop, phase, default.params, clustered_pixels(None, bad))


def region_features(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, invalid: np.ndarray | None = None
) -> np.ndarray:
    """(H, W, C) the default method's projected superpixel node features
    (:func:`default_region_model`), each pixel carrying its superpixel's: what the
    default clusters (``invalid`` pixels carry the nearest clustered one's)."""
    model = default_region_model(intensity, dop, phase, invalid)
    nodes = np.zeros((int(model.regions.max()) + 1, model.z.shape[1]))
    nodes[: model.n] = model.z  # with a mask, the region outside it stays 0
    regions = model.regions if model.nearest is None else model.regions.ravel()[model.nearest]
    return nodes[regions].astype(np.float32)


def bound_features(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    features: str = "plain",
    invalid: np.ndarray | None = None,
) -> np.ndarray:
    """(H, W, F) features of the bound: ``plain`` = the 20 of :func:`plain_features`;
    ``rich`` = those plus the engine's default pixel feature stack
    (``napari_polarseg.engine.pixel_features``, 88 features at σ = 1..16); ``regions`` =
    the 20 plus the default method's node features (:func:`region_features`, which read
    ``invalid``)."""
    if features not in BOUND_FEATURE_SETS:
        raise ValueError(f"features must be one of {BOUND_FEATURE_SETS}, got {features!r}")
    f = plain_features(intensity, dop, phase)
    if features == "plain":
        return f
    if features == "regions":
        regions = region_features(intensity, dop, phase, invalid).reshape(*f.shape[:2], -1)
        return np.concatenate([f, regions], axis=-1)
    from napari_polarseg.engine import pixel_features

    rich = np.moveaxis(pixel_features(intensity, dop, phase).planes(), 0, -1)
    return np.concatenate([f, rich], axis=-1)


def truth_bound_halves(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    truth: np.ndarray,
    features: str = "plain",
    invalid: np.ndarray | None = None,
    classifier: str = "forest",
) -> tuple[float, bool]:
    """(ARI, every class seen) of a classifier trained on the truth of the LEFT half.

    A random forest (``forest``: 100 trees, seed 0, balanced classes) or gradient-boosted
    trees (``boosting``: scikit-learn's ``HistGradientBoostingClassifier``, seed 0,
    balanced classes) on :func:`bound_features` learns from up to
    :data:`BOUND_HALF_PIXELS` labelled pixels (``truth > 0``) of the columns left of the
    middle and predicts the labelled pixels right of it; the ARI is
    over those right-half pixels. The features are computed on the whole image (a
    smoothing scale reaches across the middle, as it would for any method). The flag is
    False when a class labelled in the right half has no pixel in the left half (the
    forest cannot name it: the bound is lower than the features allow). ``invalid``: the
    image's invalid pixels, read by the ``regions`` features only. A method's labels are
    scored on the same pixels by :func:`right_half_ari`.
    """
    if classifier not in BOUND_CLASSIFIERS:
        raise ValueError(f"classifier must be one of {BOUND_CLASSIFIERS}, got {classifier!r}")
    f = bound_features(intensity, dop, phase, features, invalid)
    half = truth.shape[1] // 2
    left, right = truth[:, :half], truth[:, half:]
    train = np.flatnonzero((left > 0).ravel())
    scored = right > 0
    if train.size == 0 or not scored.any():
        return float("nan"), False
    rng = np.random.default_rng(0)
    train = rng.choice(train, min(BOUND_HALF_PIXELS, train.size), replace=False)
    fl = f[:, :half].reshape(-1, f.shape[-1])
    if classifier == "forest":
        model = RandomForestClassifier(100, n_jobs=-1, random_state=0, class_weight="balanced")
    else:
        model = HistGradientBoostingClassifier(random_state=0, class_weight="balanced")
    model.fit(fl[train], left.ravel()[train])
    pred = np.zeros(truth.shape, model.classes_.dtype)
    pred[:, half:][scored] = model.predict(f[:, half:][scored])
    seen = set(np.unique(right[scored])) <= set(model.classes_)
    return right_half_ari(pred, truth), bool(seen)


def right_half_ari(labels: np.ndarray, truth: np.ndarray) -> float:
    """ARI of ``labels`` over the labelled pixels (``truth > 0``) of the columns right of
    the middle: the pixels :func:`truth_bound_halves` scores, so that a method stands
    beside the bounds on the same pixels."""
    from sklearn.metrics import adjusted_rand_score

    half = truth.shape[1] // 2
    right = truth[:, half:]
    scored = right > 0
    return float(adjusted_rand_score(right[scored], np.asarray(labels)[:, half:][scored]))


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
