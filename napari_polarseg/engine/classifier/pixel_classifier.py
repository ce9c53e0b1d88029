"""Scribble-trained pixel classifier, as ilastik / napari-apoc / convpaint do it.

The analyst paints a few strokes per material in a labels image (0 = unlabelled,
1, 2, … = materials). Every scribbled pixel is a training example described by its
pixel features (:mod:`.pixel_features`); a random forest (scikit-learn) learns the
classes and predicts the class probabilities p_k(x) of every pixel. Labels are
argmax_k p_k (label c − 1 for scribble value c, so label 0 is the first material, as
in the segmentation contract); the uncertainty is 1 − (p_(1) − p_(2)), one minus the
margin between the two most probable classes (0 = sure, 1 = a tie).

Optional edge-aware smoothing of the probabilities (:func:`guided_filter`, He et al.
2013, "Guided image filtering", eq. 13–14) averages p_k over a window where the guide
image (log Î) is flat and not across its edges.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from scipy import ndimage

from ..errors import PolarsegError
from ..features.pixel_features import FeatureStack, PixelFeatureParams
from ..materials import Materials
from .refined_prediction import refined_probabilities

#: Classifier kinds of :class:`ClassifierParams`.
MODELS = ("random_forest", "extra_trees", "hist_gradient_boosting")
#: Grid step (pixels) of the coarse-to-fine prediction the segmenters use
#: (:mod:`.refined_prediction`; 1 = every pixel on its own features).
PREDICTION_STRIDE = 4


@dataclass(frozen=True)
class ClassifierParams:
    """How the pixel classifier is trained.

    Attributes
    ----------
    model : str
        One of :data:`MODELS` (scikit-learn's RandomForestClassifier,
        ExtraTreesClassifier, HistGradientBoostingClassifier). Extremely randomised
        trees measured best (rendered scenes and real frames) and train fastest;
        boosting overfits a few strokes and predicts slowly.
    n_estimators : int
        Trees of a forest (boosting iterations for ``hist_gradient_boosting``).
    max_depth : int or None
        Deepest tree (None: grown until pure).
    balance_classes : bool
        Weight every class equally (scikit-learn ``class_weight="balanced"``), whatever
        the number of scribbled pixels of each.
    max_pixels_per_class : int
        At most this many scribbled pixels of a class train the model (a random,
        seeded sample); 0 = all.
    smoothing : float
        Radius (pixels) of the edge-aware smoothing of the probabilities; 0 = none.
        Not used while ``region_walk`` > 0 (the walk regularises instead).
    region_walk : float
        γ of the random walk with priors over the superpixel graph
        (:mod:`.region_walk`): the weight of the classifier's probabilities against the
        graph (dimensionless, > 0; smaller lets a stroke label more of its surface);
        0 = no walk, every pixel labelled by the classifier alone.
    seed : int
        Random seed of the forest and the sampling.
    """

    model: str = "extra_trees"
    n_estimators: int = 50
    max_depth: int | None = None
    balance_classes: bool = False
    max_pixels_per_class: int = 5_000
    smoothing: float = 3.0
    region_walk: float = 0.03
    seed: int = 0

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise PolarsegError(f"model must be one of {', '.join(MODELS)}; got {self.model!r}")
        if int(self.n_estimators) < 1:
            raise PolarsegError(f"n_estimators must be >= 1, got {self.n_estimators}")
        if self.max_depth is not None and int(self.max_depth) < 1:
            raise PolarsegError(f"max_depth must be >= 1 or None, got {self.max_depth}")
        if int(self.max_pixels_per_class) < 0:
            raise PolarsegError(
                f"max_pixels_per_class must be >= 0, got {self.max_pixels_per_class}"
            )
        if not (math.isfinite(self.smoothing) and self.smoothing >= 0):
            raise PolarsegError(f"smoothing must be >= 0, got {self.smoothing}")
        if not (math.isfinite(self.region_walk) and self.region_walk >= 0):
            raise PolarsegError(f"region_walk must be >= 0, got {self.region_walk}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> ClassifierParams:
        """Inverse of :meth:`to_dict`; unknown keys raise :class:`PolarsegError`."""
        known = set(cls.__dataclass_fields__)
        extra = sorted(set(values) - known)
        if extra:
            raise PolarsegError(f"unknown classifier parameters: {', '.join(extra)}")
        try:
            return cls(**values)
        except (TypeError, ValueError) as exc:
            raise PolarsegError(f"bad classifier parameters ({exc})") from None


@dataclass(frozen=True)
class PixelClassifier:
    """A trained pixel classifier and what it needs to be applied to another image.

    Attributes
    ----------
    model : scikit-learn classifier
        Fitted on the features named ``feature_names``; its classes are the scribble
        values ``classes``.
    classes : ndarray (K,) of int
        Scribble values of the materials, ascending; label k ↔ ``classes[k]``.
    feature_names : tuple of str
    feature_params : PixelFeatureParams
    params : ClassifierParams
    n_training_pixels : int
        Scribbled pixels the model was fitted on (after sampling).
    class_names : tuple of str
        The material name of each class (empty: unnamed; see :meth:`materials`).
    n_scribbled_pixels : int
        Scribbled (valid) pixels there were before sampling; 0 when not known (a
        loaded classifier). More than ``n_training_pixels`` when
        ``params.max_pixels_per_class`` sampled them (:attr:`subsampled`).
    """

    model: Any
    classes: np.ndarray
    feature_names: tuple[str, ...]
    feature_params: PixelFeatureParams
    params: ClassifierParams
    n_training_pixels: int
    class_names: tuple[str, ...] = ()
    n_scribbled_pixels: int = 0

    def materials(self) -> Materials:
        """The value and name of every class (unnamed ones: ``"material <value>"``)."""
        names = self.class_names if len(self.class_names) == self.classes.size else None
        return Materials.of(self.classes, names)

    def named(self, names: Mapping[int, str]) -> PixelClassifier:
        """This classifier with the materials renamed by ``names`` (value → name)."""
        return replace(self, class_names=self.materials().renamed(names).names)

    @property
    def subsampled(self) -> bool:
        """True when fewer pixels trained the model than were scribbled."""
        return self.n_scribbled_pixels > self.n_training_pixels

    def training_text(self) -> str:
        """``"1200 training pixels"``, or when sampled ``"10000 of 23456 scribbled pixels
        train (a sample: at most 5000 per material)"``."""
        if not self.subsampled:
            return f"{self.n_training_pixels} training pixels"
        return (
            f"{self.n_training_pixels} of {self.n_scribbled_pixels} scribbled pixels train "
            f"(a sample: at most {self.params.max_pixels_per_class} per material)"
        )

    def importances(self) -> dict[str, float]:
        """Feature name → importance (impurity decrease, summing to 1), largest first.

        Empty for a model without ``feature_importances_`` (boosting).
        """
        values = getattr(self.model, "feature_importances_", None)
        if values is None:
            return {}
        order = np.argsort(values)[::-1]
        return {self.feature_names[i]: float(values[i]) for i in order}

    def metadata(self) -> dict[str, Any]:
        """JSON-ready description (what a classifier file stores beside the model)."""
        return {
            "classes": [int(c) for c in self.classes],
            "class_names": list(self.materials().names),
            "feature_names": list(self.feature_names),
            "feature_params": self.feature_params.to_dict(),
            "training": {
                "n_pixels": int(self.n_training_pixels),
                "classifier_params": self.params.to_dict(),
            },
        }

    @classmethod
    def from_metadata(cls, model: Any, meta: dict[str, Any]) -> PixelClassifier:
        """Rebuild from a model and :meth:`metadata` (raises :class:`PolarsegError`)."""
        try:
            classes = np.asarray(meta["classes"], dtype=np.int64)
            names = tuple(str(n) for n in meta["feature_names"])
            # a trained classifier's scales are fixed, whatever a new image's object size
            fparams = PixelFeatureParams.from_dict(dict(meta["feature_params"]))
            fparams = replace(fparams, largest_scale_objects=0.0)
            training = dict(meta["training"])
            cparams = ClassifierParams.from_dict(dict(training["classifier_params"]))
            n_train = int(training["n_pixels"])
            class_names = tuple(str(n) for n in meta.get("class_names") or ())
        except (KeyError, TypeError, ValueError) as exc:
            raise PolarsegError(f"the classifier's description is incomplete ({exc})") from None
        model_classes = np.asarray(getattr(model, "classes_", []))
        if model_classes.shape != classes.shape or np.any(model_classes != classes):
            raise PolarsegError("the classifier's classes do not match its description")
        if getattr(model, "n_features_in_", len(names)) != len(names):
            raise PolarsegError("the classifier's features do not match its description")
        if class_names and len(class_names) != classes.size:
            raise PolarsegError("the classifier's class names do not match its classes")
        return cls(model, classes, names, fparams, cparams, n_train, class_names)


@dataclass(frozen=True)
class PixelPrediction:
    """Per-pixel output of :func:`predict_pixels`.

    Attributes
    ----------
    labels : ndarray (H, W) int32
        Index into ``classes`` of the most probable material.
    probabilities : ndarray (K, H, W) float32
        p_k per pixel (summing to 1 over k).
    uncertainty : ndarray (H, W) float32
        1 − (p_(1) − p_(2)) in [0, 1] (module docstring).
    classes : ndarray (K,) of int
        Scribble value of each label.
    n_predicted : int
        Pixels whose own features were predicted (all of them unless coarse to fine).
    """

    labels: np.ndarray
    probabilities: np.ndarray
    uncertainty: np.ndarray
    classes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    n_predicted: int = 0


def check_scribbles(
    scribbles: Any, shape: tuple[int, int] | None = None, convert: bool = True
) -> np.ndarray:
    """Validate a scribble image (of ``shape`` when given): one 2-D image of integers
    >= 0 (0 = unlabelled) → int64 (without ``convert``: an integer image whose values
    int64 holds as it is, no full-size copy). Raises :class:`PolarsegError` naming the
    problem."""
    s = np.asarray(scribbles)
    if s.ndim != 2:
        raise PolarsegError(f"scribbles must be one 2-D labels image, got shape {s.shape}")
    if shape is not None and s.shape != tuple(shape):
        raise PolarsegError(f"the scribbles are {s.shape} but the image is {tuple(shape)}")
    if s.dtype.kind == "f":
        if not np.all(np.isfinite(s)) or np.any(s != np.round(s)):
            raise PolarsegError("scribbles must hold integer labels")
    elif s.dtype.kind not in "biu":
        raise PolarsegError(f"scribbles must hold integer labels, got dtype {s.dtype}")
    if convert or not np.can_cast(s.dtype, np.int64):  # floats, uint64
        s = s.astype(np.int64)
    if s.dtype.kind == "i" and np.any(s < 0):
        raise PolarsegError("scribble labels must be >= 0 (0 = unlabelled)")
    return s


def training_pixels(
    scribbles: np.ndarray,
    params: ClassifierParams,
    valid: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices and scribble values (int64) of the pixels the model is fitted on.

    Scribbled pixels inside ``valid`` (all when None); at most
    ``max_pixels_per_class`` of each class, sampled evenly along the class's pixels in
    image order after a seeded shuffle. Raises :class:`PolarsegError` with fewer than
    two classes.
    """
    flat = scribbles.ravel()
    marked = flat > 0
    if not marked.any():
        raise PolarsegError("the scribbles label no pixel (0 = unlabelled everywhere)")
    if valid is not None:
        marked &= np.asarray(valid, dtype=bool).ravel()
    index = np.flatnonzero(marked)
    values = flat[index].astype(np.int64)
    classes = np.unique(values)
    if classes.size < 2:
        found = "none" if classes.size == 0 else f"only label {int(classes[0])}"
        raise PolarsegError(
            f"scribbles must mark at least 2 materials (non-zero labels), found {found}"
        )
    cap = int(params.max_pixels_per_class)
    if cap:
        rng = np.random.default_rng(params.seed)
        keep = []
        for c in classes:
            mine = index[values == c]
            keep.append(mine if mine.size <= cap else np.sort(rng.choice(mine, cap, False)))
        index = np.concatenate(keep)
        values = flat[index].astype(np.int64)
    return index, values


def make_model(params: ClassifierParams) -> Any:
    """An unfitted scikit-learn classifier for ``params``."""
    from sklearn.ensemble import (
        ExtraTreesClassifier,
        HistGradientBoostingClassifier,
        RandomForestClassifier,
    )

    weight = "balanced" if params.balance_classes else None
    if params.model == "hist_gradient_boosting":
        return HistGradientBoostingClassifier(
            max_iter=int(params.n_estimators),
            max_depth=params.max_depth,
            class_weight=weight,
            random_state=params.seed,
        )
    kind = RandomForestClassifier if params.model == "random_forest" else ExtraTreesClassifier
    return kind(
        n_estimators=int(params.n_estimators),
        max_depth=params.max_depth,
        class_weight=weight,
        n_jobs=-1,
        random_state=params.seed,
    )


def train_pixel_classifier(
    features: FeatureStack,
    scribbles: np.ndarray,
    params: ClassifierParams | None = None,
    valid: np.ndarray | None = None,
) -> PixelClassifier:
    """Fit the classifier on the scribbled pixels' features.

    Parameters
    ----------
    features : FeatureStack
        Features of the image the scribbles were painted on.
    scribbles : array (H, W) of int
        0 = unlabelled, 1, 2, … = materials (at least two).
    params : ClassifierParams, optional
    valid : array (H, W) of bool, optional
        Pixels that may train (e.g. not saturated); default all.

    Returns
    -------
    PixelClassifier
    """
    params = params or ClassifierParams()
    s = check_scribbles(scribbles, features.shape, convert=False)  # no int64 copy
    index, values = training_pixels(s, params, valid)
    marked = s.ravel() > 0
    if valid is not None:
        marked &= np.asarray(valid, dtype=bool).ravel()
    x = features.take(index)
    model = make_model(params)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        model.fit(x, values)
    return PixelClassifier(
        model=model,
        classes=np.asarray(model.classes_, dtype=np.int64),
        feature_names=features.names,
        feature_params=features.params,
        params=params,
        n_training_pixels=int(index.size),
        n_scribbled_pixels=int(np.count_nonzero(marked)),
    )


def box_mean(a: np.ndarray, radius: int) -> np.ndarray:
    """Mean over the (2r + 1)² window around each pixel (edges: nearest)."""
    return ndimage.uniform_filter(a, size=2 * radius + 1, mode="nearest")


def guided_filter(
    guide: np.ndarray, images: np.ndarray, radius: int, eps: float = 1e-3
) -> np.ndarray:
    """Edge-aware smoothing of ``images`` (K, H, W) steered by ``guide`` (H, W).

    He, Sun & Tang (2013), eq. 13–14: in every (2r + 1)² window the output is the
    linear function a·I + b of the guide I that best fits the input (a = cov(I, p) /
    (var I + ε), b = mean p − a·mean I), averaged over the windows covering the pixel.
    Written out because neither SciPy nor scikit-image has it (OpenCV's ximgproc does,
    which this project does not depend on); box means make it O(pixels) for any r.
    ``guide`` should be scaled to unit spread for ``eps`` to mean the same everywhere.
    """
    r = int(radius)
    i = guide.astype(np.float32)
    mean_i = box_mean(i, r)
    var_i = box_mean(i * i, r) - mean_i * mean_i
    out = np.empty_like(images, dtype=np.float32)
    for k, p in enumerate(images):
        mean_p = box_mean(p, r)
        a = (box_mean(i * p, r) - mean_i * mean_p) / (var_i + eps)
        b = mean_p - a * mean_i
        out[k] = box_mean(a, r) * i + box_mean(b, r)
    return out


def guide_stats(guide: np.ndarray) -> tuple[float, float]:
    """(mean, standard deviation) of a guide image (float32), what
    :func:`smooth_probabilities` scales it by (a deviation of 0 is taken as 1)."""
    g = np.asarray(guide, dtype=np.float32)
    return float(np.mean(g)), float(np.std(g)) or 1.0


def smooth_probabilities(
    probabilities: np.ndarray,
    guide: np.ndarray,
    radius: float,
    stats: tuple[float, float] | None = None,
) -> np.ndarray:
    """Guided-filter the probabilities with ``guide`` (e.g. log Î), scaled to
    (g − mean) / std (``stats``: that mean and std, default :func:`guide_stats` of
    ``guide``; a tile passes the whole image's), renormalised to sum 1. Reads
    2 ``radius`` pixels each way (two box means)."""
    if radius <= 0:
        return probabilities
    g = guide.astype(np.float32)
    centre, spread = guide_stats(g) if stats is None else stats
    out = guided_filter((g - centre) / spread, probabilities, max(1, round(radius)))
    np.clip(out, 0, None, out=out)
    total = out.sum(axis=0, keepdims=True)
    out /= np.where(total > 0, total, 1)
    return out


def most_probable(probabilities: np.ndarray) -> np.ndarray:
    """Index k of the largest p_k per pixel (the first on a tie), int32 — what
    ``np.argmax(probabilities, axis=0)`` gives, one plane at a time (several times
    faster than the strided reduction over a (K, H, W) stack)."""
    best = probabilities[0].copy()
    index = np.zeros(best.shape, dtype=np.int32)
    for k in range(1, probabilities.shape[0]):
        index[probabilities[k] > best] = k
        np.maximum(best, probabilities[k], out=best)
    return index


def margin_uncertainty(probabilities: np.ndarray) -> np.ndarray:
    """1 − (p_(1) − p_(2)) per pixel: one minus the margin of the two best classes
    (float32; the two largest kept while walking the planes)."""
    if probabilities.shape[0] < 2:
        return np.zeros(probabilities.shape[1:], dtype=np.float32)
    p = probabilities.astype(np.float32, copy=False)
    first, second = np.maximum(p[0], p[1]), np.minimum(p[0], p[1])
    for plane in p[2:]:
        np.maximum(second, np.minimum(first, plane), out=second)
        np.maximum(first, plane, out=first)
    first -= second
    return np.subtract(1.0, first, dtype=np.float32)


def check_feature_names(classifier: PixelClassifier, names: tuple[str, ...]) -> None:
    """Raise :class:`PolarsegError` unless the image's feature ``names`` are the
    classifier's, in order."""
    if tuple(names) != tuple(classifier.feature_names):
        missing = [n for n in classifier.feature_names if n not in names]
        detail = f"missing {', '.join(missing[:3])}" if missing else "in another order"
        raise PolarsegError(f"the image's features do not match the classifier's ({detail})")


def predict_pixels(
    classifier: PixelClassifier,
    features: FeatureStack,
    guide: np.ndarray | None = None,
    cancel: Any = None,
    stride: int = 1,
    coarse: np.ndarray | None = None,
) -> PixelPrediction:
    """Class probabilities, labels and uncertainty of every pixel.

    Parameters
    ----------
    classifier : PixelClassifier
    features : FeatureStack
        Must hold the classifier's features by name (same order).
    guide : array (H, W), optional
        Guide of the edge-aware smoothing (log Î); needed when the classifier's
        ``smoothing`` > 0.
    cancel : callable, optional
        Called between chunks; returning True raises :class:`Cancelled`.
    stride : int
        1: every pixel predicted on its own features; s > 1: coarse to fine, the
        samples of a grid of step s then every pixel of the grid cells on a border
        between classes (:mod:`.refined_prediction`).
    coarse : array (K, ⌈H/s⌉, ⌈W/s⌉), optional
        The grid's probabilities when already predicted (by this classifier).
    """
    check_feature_names(classifier, features.names)
    out = refined_probabilities(classifier.model, features, stride, cancel, coarse)
    proba = out.probabilities
    radius = classifier.params.smoothing
    if radius > 0:
        if guide is None:
            raise PolarsegError("edge-aware smoothing needs a guide image")
        proba = smooth_probabilities(proba, guide, radius)
    labels = most_probable(proba)
    return PixelPrediction(
        labels, proba, margin_uncertainty(proba), classifier.classes, out.n_predicted
    )
