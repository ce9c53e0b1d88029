"""The pixel classifier as a method: trained on the user's scribbles, or a saved one
applied (:mod:`napari_polarseg.engine.classifier.pixel_classifier`).

Multi-scale pixel features of the shared polarisation image, a random forest on the
scribbled pixels, a prediction for every pixel. Selected by its inputs: ``scribbles``
or ``classifier`` (and ``settings``, a
:class:`~napari_polarseg.engine.classifier.classifier_settings.ClassifierSettings`: the
features and model a training uses; default the defaults).

It runs on the scene's :class:`~napari_polarseg.engine.ScribbleSession`
(:func:`scribble_session`, kept in the scene's feature cache): the features and the
region walk's superpixel graph stay while the polarisation image does, so a new stroke
only retrains and predicts. When someone receives partial results
(:attr:`~.base.MethodRun.wants_partials`: the plugin), the labels of the session's
coarser grid (:meth:`~napari_polarseg.engine.ScribbleSession.preview`) are handed over
first, then the final ones (:meth:`~.base.MethodRun.partial`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..classifier.classifier_settings import ClassifierSettings
from ..classifier.pixel_segmentation import PixelSegmenter
from ..classifier.scribble_session import ScribbleSession
from ..errors import ClassifierInputError, PolarsegError
from ..features.pixel_feature_params import PixelFeatureParams
from ..params import SegmentParams
from ..physics.pixel_mask import fill_from_nearest
from ..timing import timed
from .base import MethodOutput, MethodRun, SceneView

if TYPE_CHECKING:
    from .scene import Scene

#: The session's seconds that make up the ``classifier`` stage.
CLASSIFIER_SECONDS = ("train", "preview", "predict")


def scribble_session(scene: SceneView, colour_stack: np.ndarray | None = None) -> ScribbleSession:
    """The scene's scribble session (kept in its feature cache; another ``colour_stack``,
    the colour stacks of a colour-polarisation frame, gets a new one): the method's
    features, superpixel graph and classifier, which a front end may also fill ahead of
    the first strokes (:meth:`~napari_polarseg.engine.ScribbleSession.features`)."""
    return scene.cached(
        "scribble_session",
        id(colour_stack),
        lambda: ScribbleSession.on_pipeline(scene.pipeline, colour_stack),
    )


def fit_session(
    session: ScribbleSession,
    params: SegmentParams,
    inputs: dict[str, Any],
    progress: Any = None,
) -> float:
    """Give ``session`` its classifier: trained on ``inputs["scribbles"]`` with
    ``inputs["settings"]``, or ``inputs["classifier"]`` applied (it brings its own
    features). Returns the seconds of the features (0 when they were kept); a problem
    of the strokes or of the classifier raises :class:`ClassifierInputError`."""
    classifier = inputs.get("classifier")
    session.segment_params = params
    if classifier is None:
        settings = inputs.get("settings") or ClassifierSettings()
        session.features_params = settings.features
        session.classifier_params = settings.classifier
        features, colour = settings.features, True
    else:
        features = classifier.feature_params
        colour = any(
            n.split(":", 1)[0] in session.segmenter.colours for n in classifier.feature_names
        )
    before, seconds = session.feature_runs, {}
    with timed(seconds, "features"):
        session.features(features, colour, progress)
    try:
        if classifier is None:
            session.train(inputs.get("scribbles"))
        else:
            session.use(classifier)
    except PolarsegError as exc:
        raise ClassifierInputError(str(exc)) from None
    return seconds["features"] if session.feature_runs != before else 0.0


class PixelClassification:
    """The scribble-trained pixel classifier as a :class:`~.base.Segmenter`."""

    name = "classifier"
    title = "pixel classifier (scribbles)"
    reads = ("fit", "object_size")
    inputs = ("scribbles", "classifier")

    def stages(self, params: SegmentParams) -> tuple[str, ...]:
        return ("features", "classifier")

    def segmenter(self, scene: Scene, colour_stack: np.ndarray | None = None) -> PixelSegmenter:
        """The scene's pixel segmenter: its scribble session's (:func:`scribble_session`;
        kept: its feature stack survives new strokes)."""
        return scribble_session(scene, colour_stack).segmenter

    def segment(
        self, scene: Scene, params: SegmentParams, inputs: dict[str, Any], run: MethodRun
    ) -> MethodOutput:
        run.begin("features")
        session = scribble_session(scene, inputs.get("colour_stack"))
        features = fit_session(session, params, inputs, run.within)
        run.begin("classifier")
        trained = inputs.get("classifier") is None
        if run.wants_partials:  # the coarser grid's labels first: shown while refining
            session.preview(run.cancel)
            run.partial(self.output(scene, session, features, trained))
        session.refine(run.cancel)
        out = self.output(scene, session, features, trained)
        run.partial(out, final=True)
        return out

    def output(
        self, scene: Scene, session: ScribbleSession, features: float, trained: bool = True
    ) -> MethodOutput:
        """The session's last prediction as the method's output (labels outside the
        scene's region from the nearest pixel inside; ``features``: their seconds, 0
        when they were kept). ``extra`` holds the prediction, the classifier, its
        materials and the session's seconds; the record the seconds and, for a
        classifier ``trained`` here, the object size its feature scales followed
        (:func:`size_record`)."""
        prediction, classifier = session.prediction, session.classifier
        assert prediction is not None and classifier is not None
        labels = prediction.labels
        if scene.region is not None:
            (labels,) = fill_from_nearest(scene.region, labels)
        seconds = {**session.seconds, "features": features}
        stages = {"classifier": sum(seconds.get(k, 0.0) for k in CLASSIFIER_SECONDS)}
        if features:
            stages = {"features": features, **stages}
        extra = {"prediction": prediction, "classifier": classifier, "seconds": seconds}
        extra["materials"] = classifier.materials()
        record = {"seconds": seconds, **(size_record(session) if trained else {})}
        return MethodOutput(labels, seconds=stages, record=record, extra=extra)


def size_record(session: ScribbleSession) -> dict[str, Any]:
    """``feature_scales`` (σ, px) of the session's trained classifier, the scales its
    features kept at the scene's object size
    (:meth:`~napari_polarseg.engine.features.pixel_feature_params.PixelFeatureParams.at_object_size`),
    and ``object_size_applied`` (the scales followed it); with the size they followed
    ``object_size`` (px) and ``object_size_found`` (estimated, not given), or, where no
    estimate on this image could drop a scale and none was made,
    ``object_size_at_least`` (px: the smallest the estimate can give here)."""
    assert session.classifier is not None
    scales = [float(s) for s in session.classifier.feature_params.scales]
    followed = (session.features_params or PixelFeatureParams()).follows_object_size
    record: dict[str, Any] = {"feature_scales": scales, "object_size_applied": followed}
    if not followed:
        return record
    segmenter, params = session.segmenter, session.segment_params
    size = segmenter.known_object_size(params)
    if size is None:
        record["object_size_at_least"] = round(segmenter.smallest_object_size(params), 1)
        return record
    return {**record, "object_size": round(size.size_px, 1), "object_size_found": size.estimated}
