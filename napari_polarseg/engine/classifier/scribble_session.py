"""The scribble loop as an object: paint, update, look, paint again.

:class:`ScribbleSession` holds one image (an angle stack), its pixel features
(:mod:`..features.pixel_features`, computed once and kept between updates), the
superpixel graph of the region walk (:mod:`.region_walk`, drawn beside the features)
and the classifier trained on the last scribbles. Each :meth:`~ScribbleSession.update`
retrains on the strokes (:func:`~.pixel_classifier.train_pixel_classifier`), predicts
the samples of a grid of stride s and spreads the strokes and the grid's class
probabilities over the superpixel graph by a random walk with priors
(:func:`~.region_walk.walked_prediction`): every pixel takes its region's class. With
``region_walk`` = 0 the classifier labels every pixel alone, coarse to fine
(:mod:`.refined_prediction`: the grid, then every pixel of the cells on a border between
classes, smoothed edge-aware as in :func:`~.pixel_classifier.predict_pixels`).

:meth:`~ScribbleSession.preview` is the answer of a coarser grid: what an interactive
front end shows first, while :meth:`~ScribbleSession.refine` predicts the finer grid
(and, without the walk, the borders). The plugin's scribble mode runs on a session per
stack.

Labels from :meth:`~ScribbleSession.update` are the scribbles' own values (a pixel
painted 3 is labelled 3 where the classifier agrees); :attr:`~ScribbleSession.prediction`
keeps the class index 0..K−1 of the segmentation contract.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..chunks import in_background
from ..errors import PolarsegError
from ..features.pixel_features import FeatureStack, PixelFeatureParams
from ..params import SegmentParams
from ..pipeline import Pipeline
from ..timing import timed
from .pixel_classifier import (
    PREDICTION_STRIDE,
    ClassifierParams,
    PixelClassifier,
    PixelPrediction,
    margin_uncertainty,
    most_probable,
    smooth_probabilities,
)
from .pixel_segmentation import PixelSegmentation, PixelSegmenter
from .refined_prediction import grid_index, grid_probabilities, upsampled
from .region_walk import preview_prediction
from .tiled_features import TiledFeatures


@dataclass(frozen=True)
class PredictionParams:
    """How a session predicts every pixel.

    Attributes
    ----------
    stride : int
        Step s of the grid predicted first, pixels (:mod:`.refined_prediction`);
        1 = predict every pixel on its own features.
    preview_stride : int
        Step of the coarser grid :meth:`ScribbleSession.preview` predicts (its labels
        are shown first, while the borders are refined).
    """

    stride: int = PREDICTION_STRIDE
    preview_stride: int = 2 * PREDICTION_STRIDE

    def __post_init__(self) -> None:
        for name in ("stride", "preview_stride"):
            if int(getattr(self, name)) < 1:
                raise PolarsegError(f"{name} must be >= 1, got {getattr(self, name)}")


@dataclass
class ScribbleSession:
    """A scribble-trained pixel classifier on one image, features kept between updates.

    Parameters
    ----------
    stack : array (N, H, W)
        Frames through a polariser at ``angles_deg``.
    angles_deg : sequence of float
        Polariser angle of every frame, degrees.
    features : PixelFeatureParams, optional
        What the feature stack holds (default ``PixelFeatureParams()``).
    classifier : ClassifierParams, optional
        How the classifier trains (default ``ClassifierParams()``).
    prediction : PredictionParams, optional
        How every pixel is predicted (default ``PredictionParams()``).
    segment : SegmentParams, optional
        The polarisation image's fit (default ``SegmentParams()``).

    pipeline : Pipeline, optional
        A pipeline of this stack whose cached stages to share (:meth:`on_pipeline`).
    colour_stack : array (C, N, H, W), optional
        The colour stacks of a colour-polarisation frame whose luminance is ``stack``
        (:class:`~.pixel_segmentation.PixelSegmenter`).

    Examples
    --------
    >>> from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes
    >>> scene = make_scene("leaves", shape=(96, 96), angles_deg=[0, 45, 90, 135])
    >>> strokes = 10 * scribble_strokes(scene.labels, seed=0)  # values 10, 20, ...
    >>> session = ScribbleSession(scene.stack, [0, 45, 90, 135])
    >>> labels = session.update(strokes)
    >>> labels.shape, set(labels.ravel()) <= set(strokes.ravel()), session.feature_runs
    ((96, 96), True, 1)
    """

    stack: Any = field(repr=False)
    angles_deg: Any
    features_params: PixelFeatureParams | None = None
    classifier_params: ClassifierParams | None = None
    prediction_params: PredictionParams = field(default_factory=PredictionParams)
    segment_params: SegmentParams | None = None
    pipeline: Pipeline | None = field(default=None, repr=False)
    colour_stack: np.ndarray | None = field(default=None, repr=False)
    #: Feature stacks computed so far (1 after the first update, while the image stays).
    feature_runs: int = field(default=0, init=False)
    classifier: PixelClassifier | None = field(default=None, init=False, repr=False)
    prediction: PixelPrediction | None = field(default=None, init=False, repr=False)
    #: Seconds of the last update: ``features``, ``train``, ``predict``.
    seconds: dict[str, float] = field(default_factory=dict, init=False)
    #: Pixels whose own features the last prediction read (grid samples + borders).
    n_predicted: int = field(default=0, init=False)
    segmenter: PixelSegmenter = field(init=False, repr=False)
    _coarse: tuple[int, np.ndarray] | None = field(default=None, init=False, repr=False)
    _scribbles: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.pipeline is None:
            angles = np.deg2rad(np.asarray(self.angles_deg, dtype=float))
            self.pipeline = Pipeline(np.asarray(self.stack), angles, self.segment_params)
        self.segment_params = self.segment_params or self.pipeline.params
        stride = int(self.prediction_params.stride)
        self.segmenter = PixelSegmenter(self.pipeline, self.colour_stack, stride=stride)

    @classmethod
    def on_pipeline(
        cls, pipeline: Pipeline, colour_stack: np.ndarray | None = None, **kwargs: Any
    ) -> ScribbleSession:
        """A session on an existing pipeline's image (its cached stages are shared)."""
        angles = np.rad2deg(np.asarray(pipeline.angles))
        return cls(pipeline.stack, angles, pipeline=pipeline, colour_stack=colour_stack, **kwargs)

    # -- features ---------------------------------------------------------------------
    def features(
        self,
        params: PixelFeatureParams | None = None,
        colour: bool = True,
        progress: Any = None,
    ) -> FeatureStack:
        """The pixel features (computed at the first call, then kept while the
        polarisation image and the parameters stay; :attr:`feature_runs` counts the
        computations). ``colour``: with a colour stack, every colour's features too.
        ``progress(share)`` is called while they are computed (it may raise to stop).
        Meanwhile a second thread draws the region walk's superpixel graph (with the walk
        on, ``classifier_params``) and computes the normals the result shows (the
        watershed and numpy release the GIL)."""
        params = params or self.features_params
        before = self.segmenter.cached_features
        self.pipeline.get("polarisation", self.segment_params)  # shared by both threads
        walk = (self.classifier_params or ClassifierParams()).region_walk > 0

        def beside() -> None:
            if walk:
                self.segmenter.graph(self.segment_params)
            self.pipeline.get("normals", self.segment_params)

        done = in_background(beside)
        feats = self.segmenter.features(params, colour, self.segment_params, progress)
        done()
        if feats is not before:
            self.feature_runs += 1
        return feats

    @property
    def cached_features(self) -> FeatureStack | None:
        """The kept feature stack (None before the first :meth:`features`)."""
        return self.segmenter.cached_features

    # -- the loop ---------------------------------------------------------------------
    def train(self, scribbles: Any, valid: np.ndarray | None = None) -> PixelClassifier:
        """Fit the classifier on ``scribbles`` (H, W ints, 0 = none; at least two
        materials) over the valid pixels of the polarisation image."""
        self.seconds = {}
        with timed(self.seconds, "features"):
            self.features()
        with timed(self.seconds, "train"):
            self.classifier = self.segmenter.train(
                scribbles,
                self.cached_features.params,
                self.classifier_params,
                self.segment_params,
            )
        self._coarse, self._scribbles = None, np.asarray(scribbles)
        return self.classifier

    def use(self, classifier: PixelClassifier) -> None:
        """Apply a trained (e.g. loaded) classifier instead of training: its own feature
        parameters are computed."""
        self.seconds = {"train": 0.0}
        colours = self.segmenter.colours
        colour = any(name.split(":", 1)[0] in colours for name in classifier.feature_names)
        with timed(self.seconds, "features"):
            self.features(classifier.feature_params, colour)
        self.classifier, self._coarse, self._scribbles = classifier, None, None

    def preview(self, cancel: Any = None) -> PixelPrediction:
        """The prediction of the grid of ``preview_stride`` (module docstring): walked
        over the superpixel graph, or without the walk interpolated to every pixel
        (probabilities smoothed on the grid, the uncertainty taken there and
        interpolated too; no border predicted yet)."""
        clf, feats = self._ready()
        if isinstance(feats, TiledFeatures):  # no whole-image grid: the tiles' answer
            return self.refine(cancel)
        s = int(self.prediction_params.preview_stride)
        with timed(self.seconds, "preview"):
            coarse = grid_probabilities(clf.model, feats, s, cancel)
            if s == self.prediction_params.stride:
                self._coarse = (id(clf), coarse)
            if clf.params.region_walk > 0:
                graph = self.segmenter.graph(self.segment_params)
                self.prediction = preview_prediction(
                    clf, feats, graph, s, self._scribbles, cancel, coarse
                )
                self.n_predicted = self.prediction.n_predicted
                return self.prediction
            if clf.params.smoothing > 0:
                rows, cols = grid_index(feats.shape, s)
                guide = self.segmenter.guide(self.segment_params)[rows[:, None], cols[None, :]]
                radius = max(1.0, clf.params.smoothing / s)
                coarse = smooth_probabilities(coarse, guide, radius)
            proba = upsampled(coarse, s, feats.shape)
            labels = most_probable(proba)
            uncertainty = upsampled(margin_uncertainty(coarse)[None], s, feats.shape)[0]
        self.n_predicted = int(coarse[0].size)
        self.prediction = PixelPrediction(labels, proba, uncertainty, clf.classes, self.n_predicted)
        return self.prediction

    def refine(self, cancel: Any = None) -> PixelPrediction:
        """Every pixel: the grid (reused from :meth:`preview`) and the border cells
        predicted, then smoothed at full resolution."""
        clf, feats = self._ready()
        coarse = self._coarse[1] if self._coarse and self._coarse[0] == id(clf) else None
        with timed(self.seconds, "predict"):
            s = int(self.prediction_params.stride)
            self.prediction = self.segmenter.predict(
                clf, feats, self._scribbles, cancel, self.segment_params, s, coarse
            )
        self.n_predicted = self.prediction.n_predicted
        return self.prediction

    def update(self, scribbles: Any, cancel: Any = None) -> np.ndarray:
        """Retrain on ``scribbles`` and label every pixel: (H, W) int64 of the
        scribbles' own values (features kept from the previous update)."""
        self.train(scribbles)
        self.refine(cancel)
        return self.labels

    # -- what the last update gave ------------------------------------------------------
    @property
    def labels(self) -> np.ndarray:
        """(H, W) int64: the scribble value of every pixel's most probable material."""
        prediction = self._predicted()
        return prediction.classes[prediction.labels]

    @property
    def probabilities(self) -> np.ndarray:
        """(K, H, W) float32 p_k per pixel, summing to 1 over k; k follows
        :attr:`classes`."""
        return self._predicted().probabilities

    @property
    def uncertainty(self) -> np.ndarray:
        """(H, W) float32: 1 − (p_(1) − p_(2)), 0 = sure, 1 = a tie."""
        return self._predicted().uncertainty

    @property
    def classes(self) -> np.ndarray:
        """(K,) the scribble value of each probability plane, ascending."""
        return self._predicted().classes

    def segmentation(self, reconstruction: bool = True) -> PixelSegmentation:
        """The last prediction as the segmentation contract's result (labels = class
        index 0..K−1; the pipeline's maps, and with ``reconstruction`` the error map)."""
        prediction = self._predicted()
        assert self.classifier is not None
        result = self.segmenter.result(
            prediction.labels, reconstruction, self.seconds, self.segment_params
        )
        result = replace(result, materials=self.classifier.materials())
        return PixelSegmentation(result, prediction, self.classifier, dict(self.seconds))

    def _ready(self) -> tuple[PixelClassifier, FeatureStack]:
        if self.classifier is None:
            raise PolarsegError("no classifier yet: update the session with scribbles first")
        feats = self.cached_features
        if feats is None or tuple(feats.names) != tuple(self.classifier.feature_names):
            raise PolarsegError("the image's features do not match the classifier's")
        return self.classifier, feats

    def _predicted(self) -> PixelPrediction:
        if self.prediction is None:
            raise PolarsegError("nothing predicted yet: update the session with scribbles")
        return self.prediction
