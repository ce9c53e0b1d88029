"""The scribble mode without Qt: the pixel classifier on a stack's
:class:`~napari_polarseg.engine.Scene`, trained on the user's strokes (or a loaded one
applied) in place of the unsupervised method, and its texts.

:func:`classify_scene` is the scribble mode's run: the scene runs the
``PixelClassification`` method (:mod:`napari_polarseg.engine.methods.pixel_classification`)
on its kept :class:`~napari_polarseg.engine.ScribbleSession` (the pixel features survive
new strokes), hands the labels of the classifier's coarser grid and then its final
labels over before the thesis maps and the error map (``on_partial``), and its result
comes wrapped as a :class:`ClassifierOutput`. A ``cancel`` callable that turns True when
a newer request or Cancel stops the run makes the prediction stop between chunks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...engine import SegmentationResult, SegmentParams
from ...engine.classifier.pixel_segmentation import PixelSegmentation
from ...engine.errors import ClassifierInputError
from ...engine.materials import default_name
from ...messages import feature_scales_text

if TYPE_CHECKING:
    from ...engine import Scene
    from ...engine.classifier.pixel_classifier import PixelClassifier, PixelPrediction
    from ...engine.methods import MethodOutput


def scribble_problem(scribbles: np.ndarray) -> str | None:
    """Why ``scribbles`` cannot train the classifier yet (None when they can).

    Checked in the GUI thread before a run: at least two distinct non-zero labels (the
    distinct values of the painted pixels only: a camera frame's strokes are a few
    thousand of its million pixels, and ``np.unique`` of all of them took 20-40 ms).
    """
    array = np.asarray(scribbles)
    if array.size and array.min() < 0:
        return "scribble labels must be >= 0 (0 = unlabelled)"
    marked = np.unique(array[array > 0])
    if marked.size >= 2:
        return None
    found = "none yet" if marked.size == 0 else f"only label {int(marked[0])}"
    return f"paint at least 2 materials (label 1 on one material, 2 on another, …); found {found}"


@dataclass(frozen=True)
class ShownParts:
    """What showing a classifier's output computes from its whole-image arrays, made
    in the worker (:func:`shown_parts`) so that the GUI thread's show does no
    whole-image numpy work (10-25 ms of each show): the result's summary, every pixel's
    probability of its class (``confidence``), the labels as the strokes' values and
    the mean probability and uncertainty. ``result`` and ``prediction`` are those they
    were made of (:meth:`fits`)."""

    result: SegmentationResult
    prediction: PixelPrediction
    summary: dict[str, Any]
    confidence: np.ndarray
    labels: np.ndarray
    mean_confidence: float
    mean_uncertainty: float

    def fits(self, result: SegmentationResult, prediction: PixelPrediction) -> bool:
        """Whether these parts were made of this very ``result`` and ``prediction``."""
        return self.result is result and self.prediction is prediction


def shown_parts(segmentation: PixelSegmentation) -> ShownParts:
    """The :class:`ShownParts` of a classifier's ``segmentation`` (any thread)."""
    result, prediction = segmentation.result, segmentation.prediction
    confidence = prediction.probabilities.max(axis=0).astype(np.float32)
    labels = np.asarray(prediction.classes, dtype=np.int32)[result.labels]
    return ShownParts(
        result,
        prediction,
        result.summary(),
        confidence,
        labels,
        float(confidence.mean()),
        float(prediction.uncertainty.mean()),
    )


@dataclass
class ClassifierOutput:
    """What a scribble-mode job returns (or yields as a :class:`Partial`).

    ``segmentation`` is the engine's
    :class:`~napari_polarseg.engine.classifier.pixel_segmentation.PixelSegmentation`: its
    ``result.labels`` hold the class index 0..K-1, ``prediction.classes[k]`` is the
    scribble value (label) of class k, ``prediction.probabilities`` is (K, H, W) and
    sums to 1 over K, ``prediction.uncertainty`` is (H, W) in [0, 1]. ``trained`` is
    False when a loaded classifier was applied. When the strokes cannot train the
    classifier (e.g. every pixel of a material is masked) or the classifier does not
    fit the stack, ``problem`` says why and ``segmentation`` is None. ``preview``: the
    labels of the classifier's grid alone, before the borders are predicted
    (:meth:`~napari_polarseg.engine.ScribbleSession.preview`). ``parts``: what
    showing it computes, made in the worker (:func:`shown_parts`; None: made when
    shown).
    """

    segmentation: PixelSegmentation | None
    trained: bool = True
    problem: str | None = None
    preview: bool = False
    parts: ShownParts | None = None

    @property
    def result(self) -> SegmentationResult:
        assert self.segmentation is not None
        return self.segmentation.result

    @property
    def prediction(self) -> PixelPrediction:
        assert self.segmentation is not None
        return self.segmentation.prediction

    @property
    def classifier(self) -> PixelClassifier:
        assert self.segmentation is not None
        return self.segmentation.classifier


def classifier_segmentation(result: SegmentationResult, out: MethodOutput) -> PixelSegmentation:
    """The classifier's run as the engine's :class:`PixelSegmentation`: the scene's
    ``result`` and what the method's output carries (prediction, classifier, seconds)."""
    extra = out.extra
    return PixelSegmentation(result, extra["prediction"], extra["classifier"], extra["seconds"])


def classify_scene(
    scene: Scene,
    params: SegmentParams,
    inputs: dict[str, Any],
    maps: bool = True,
    cancel: Callable[[], bool] | None = None,
    progress: Callable[[str, float, int], None] | None = None,
    partial: Callable[[ClassifierOutput], None] | None = None,
) -> ClassifierOutput:
    """The pixel classifier on ``scene``: trained on ``inputs["scribbles"]`` with
    ``inputs["settings"]`` (default the defaults), or ``inputs["classifier"]`` applied
    (and ``inputs["colour_stack"]`` of a colour-polarisation frame), with the thesis maps
    and the error map when ``maps``.

    The scene's cached stages and its session's feature stack are reused: once they are
    computed, a new stroke reruns only training and prediction. ``partial`` (None: no
    preview is computed) receives the labels of the classifier's coarser grid
    (``preview`` True), then, when the maps are still to be computed, the final labels
    without them. ``progress(stage, index, total)`` is the scene's; ``cancel`` stops the
    prediction between chunks (:class:`~napari_polarseg.engine.Cancelled`). Strokes that
    cannot train the classifier, or a classifier that does not fit the stack, give an
    output with the ``problem`` and no segmentation.
    """
    trained = inputs.get("classifier") is None

    def output(result: SegmentationResult, out: MethodOutput, final: bool) -> ClassifierOutput:
        seg = classifier_segmentation(result, out)
        return ClassifierOutput(seg, trained, preview=not final, parts=shown_parts(seg))

    def forward(result: SegmentationResult, out: MethodOutput, final: bool) -> None:
        assert partial is not None
        partial(output(result, out, final))

    try:
        result = scene.segment(
            params,
            inputs,
            maps=maps,
            reconstruction=maps,
            cancel=cancel,
            progress=progress,
            on_partial=None if partial is None else forward,
        )
    except ClassifierInputError as exc:
        return ClassifierOutput(None, trained, problem=str(exc))
    out = scene.method_output(params, inputs)  # kept by the scene: not computed again
    return output(result, out, True)


def named_output(out: ClassifierOutput, names: dict[int, str]) -> ClassifierOutput:
    """``out`` with its materials renamed by ``names`` (scribble value → name): the
    classifier (what *Save classifier…* writes) and the result (what the plots and
    *Export results…* show) both carry the names."""
    if out.segmentation is None or not names:
        return out
    seg = out.segmentation
    classifier = seg.classifier.named(names)
    result = replace(seg.result, materials=classifier.materials())
    parts = out.parts
    if parts is not None and parts.fits(seg.result, seg.prediction):
        parts = replace(parts, result=result)  # the names are not in what it holds
    segmentation = replace(seg, result=result, classifier=classifier)
    return replace(out, segmentation=segmentation, parts=parts)


def classifier_text(classifier: PixelClassifier) -> str:
    """``"random_forest, 3 classes (1, 2, 3), 30 features, trained on 273 pixels"``."""
    classes = ", ".join(str(int(c)) for c in classifier.classes)
    sample = f" of {classifier.n_scribbled_pixels} scribbled" if classifier.subsampled else ""
    return (
        f"{classifier.params.model}, {classifier.classes.size} classes ({classes}), "
        f"{len(classifier.feature_names)} features, "
        f"trained on {classifier.n_training_pixels}{sample} pixels"
    )


@dataclass(eq=False)
class LoadedClassifier:
    """A classifier read by *Load classifier…*, applied instead of training.

    ``strokes`` is the (layer key, content digest) of the chosen scribbles when it was
    loaded: once they differ (the user painted, or chose other strokes) the widget
    trains on the strokes again. ``serial`` tells one load from another in snapshots.
    """

    classifier: PixelClassifier
    path: Path
    strokes: tuple[str | None, str | None]
    serial: int


def classifier_parts(
    out: ClassifierOutput, confidence: np.ndarray, path: str | None = None
) -> list[str]:
    """The status line's first parts for labels from the pixel classifier."""
    classes = out.prediction.classes
    materials = out.result.materials
    if materials is not None and len(materials.values) == classes.size:
        pairs = zip(materials.values, materials.names, strict=True)
        names = ", ".join(str(v) if n == default_name(v) else f"{v} {n}" for v, n in pairs)
    else:
        names = ", ".join(str(int(c)) for c in classes)
    source = "from scribbles" if out.trained else f"from the classifier {Path(path or '').name}"
    parts = [f"{classes.size} materials {source} (labels {names})"]
    if out.trained:
        parts.append(out.classifier.training_text())
        scales_text = feature_scales_text(out.result.method_record)
        parts += [scales_text] if scales_text else []
    parts.append(f"mean class probability {float(confidence.mean()):.2f}")
    return parts
