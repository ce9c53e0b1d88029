"""The scribble mode without Qt: the stages it runs, the pixel classifier trained on the
user's strokes (or a loaded one) in place of affinity and cut, and its texts.

:func:`classifier_stages` is the scribble mode's job body: the pipeline's stages up to
the block features, the pixel feature stack (kept by a
:class:`~napari_polarseg.engine.ScribbleSession` per pipeline), then the pixel
classifier (its grid preview first, then every pixel), assembled into a
:class:`~napari_polarseg.engine.SegmentationResult` like the cut's. A ``cancel``
callable that turns True when a newer request or Cancel stops the run makes the
prediction stop between chunks instead of at the next stage boundary.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Generator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...engine import Pipeline, PolarsegError, SegmentationResult, SegmentParams
from ...engine.analysis.classifier_settings import ClassifierSettings
from ...engine.materials import default_name
from .runs import Partial

if TYPE_CHECKING:
    from ...engine.analysis.pixel_classifier import PixelClassifier, PixelPrediction
    from ...engine.analysis.pixel_segmentation import PixelSegmentation
    from ...engine.analysis.scribble_session import ScribbleSession

#: Stages of the scribble mode: the polarisation image, the pixel features, the normals
#: (the result's zenith map), the classifier (training and prediction, or prediction
#: only for a loaded classifier), then the thesis's block features (for the result's
#: plots) and the error map, after the labels are shown. The cut's own stages
#: (affinity, cut, labels) are neither computed nor invalidated.
PIPELINE_STAGES = ("polarisation",)
MAP_STAGES = ("harmonics", "pca", "reconstruction")
CLASSIFIER_STAGES = (
    *PIPELINE_STAGES,
    "pixel features",
    "normals",
    "pixel classifier",
    *MAP_STAGES,
)
#: The session's seconds that make up the "pixel classifier" stage.
CLASSIFIER_SECONDS = ("train", "preview", "predict")


def scribble_problem(scribbles: np.ndarray) -> str | None:
    """Why ``scribbles`` cannot train the classifier yet (None when they can).

    Checked in the GUI thread before a run: at least two distinct non-zero labels.
    """
    values = np.unique(np.asarray(scribbles))
    if values.size and values[0] < 0:
        return "scribble labels must be >= 0 (0 = unlabelled)"
    marked = values[values > 0]
    if marked.size >= 2:
        return None
    found = "none yet" if marked.size == 0 else f"only label {int(marked[0])}"
    return f"paint at least 2 materials (label 1 on one material, 2 on another, …); found {found}"


@dataclass
class ClassifierOutput:
    """What a scribble-mode job returns (or yields as a :class:`Partial`).

    ``segmentation`` is the engine's
    :class:`~napari_polarseg.engine.analysis.pixel_segmentation.PixelSegmentation`: its
    ``result.labels`` hold the class index 0..K-1, ``prediction.classes[k]`` is the
    scribble value (label) of class k, ``prediction.probabilities`` is (K, H, W) and
    sums to 1 over K, ``prediction.uncertainty`` is (H, W) in [0, 1]. ``trained`` is
    False when a loaded classifier was applied. When the strokes cannot train the
    classifier (e.g. every pixel of a material is masked) or the classifier does not
    fit the stack, ``problem`` says why and ``segmentation`` is None. ``preview``: the
    labels of the classifier's grid alone, before the borders are predicted
    (:meth:`~napari_polarseg.engine.ScribbleSession.preview`).
    """

    segmentation: PixelSegmentation | None
    trained: bool = True
    problem: str | None = None
    preview: bool = False

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


def fit_session(
    session: ScribbleSession,
    params: SegmentParams,
    scribbles: np.ndarray | None,
    classifier: PixelClassifier | None,
    settings: ClassifierSettings | None,
) -> str | None:
    """Train ``session`` on ``scribbles`` with ``settings`` (default the defaults), or
    give it the loaded ``classifier`` (which brings its own features); the problem's
    text when that fails (e.g. strokes of one material), else None."""
    settings = settings or ClassifierSettings()
    if classifier is None:
        session.features_params = settings.features
        session.classifier_params = settings.classifier
    session.segment_params = params
    try:
        if classifier is None:
            session.train(scribbles)
        else:
            session.use(classifier)
    except PolarsegError as exc:
        return str(exc)
    return None


def classifier_stages(
    pipe: Pipeline,
    session: ScribbleSession,
    params: SegmentParams,
    scribbles: np.ndarray | None = None,
    classifier: PixelClassifier | None = None,
    reconstruction: bool = True,
    cancel: Callable[[], bool] | None = None,
    settings: ClassifierSettings | None = None,
) -> Generator[Any, None, ClassifierOutput]:
    """Run the stages the scribble mode needs (yielding after each), then classify.

    Trains the pixel classifier on ``scribbles`` with ``settings`` (default the
    defaults), or applies ``classifier`` (exactly one of them). Yields ``(stage, stages
    done, total)`` as each stage starts (at most ``len(CLASSIFIER_STAGES)``; without the
    reconstruction, none of :data:`MAP_STAGES`). The pipeline's cached stages and
    ``session``'s feature stack are reused: once they are computed, a new stroke reruns
    only training and prediction. The labels of the classifier's grid
    (:meth:`~napari_polarseg.engine.ScribbleSession.preview`) are yielded as a
    :class:`Partial` first, then every pixel's; when the thesis maps and the
    reconstruction still have to be computed, the output without them is yielded as a
    :class:`Partial` too (the segments are shown while they are computed). ``cancel``
    is handed to the prediction: it raises :class:`~napari_polarseg.engine.Cancelled`
    between chunks once ``cancel()`` is True.
    """
    labelled = CLASSIFIER_STAGES.index(MAP_STAGES[0])  # the stages up to the labels
    names = CLASSIFIER_STAGES if reconstruction else CLASSIFIER_STAGES[:labelled]
    total = len(names)
    timings: dict[str, float] = {}
    recomputed: list[str] = []
    partial = reconstruction and not pipe.is_fresh("reconstruction", params)

    def run_stage(name: str) -> None:
        before = pipe.calls[name]
        t0 = time.perf_counter()
        pipe.get(name, params)
        if pipe.calls[name] != before:
            timings[name] = time.perf_counter() - t0
            recomputed.append(name)

    # each stage is reported as it starts (index = stages done): the status names it
    for i, name in enumerate(PIPELINE_STAGES):
        yield name, i, total
        run_stage(name)
    yield "pixel features", CLASSIFIER_STAGES.index("pixel features"), total
    before = session.feature_runs
    problem = fit_session(session, params, scribbles, classifier, settings)
    if problem is not None:
        return ClassifierOutput(None, classifier is None, problem=problem)
    if session.feature_runs != before:
        timings["pixel features"] = session.seconds.get("features", 0.0)
        recomputed.append("pixel features")
    yield "normals", CLASSIFIER_STAGES.index("normals"), total
    run_stage("normals")
    recomputed.append("pixel classifier")

    def output(with_reconstruction: bool, preview: bool = False) -> ClassifierOutput:
        seg = session.segmentation(with_reconstruction)
        seconds = session.seconds
        timings["pixel classifier"] = sum(seconds.get(k, 0.0) for k in CLASSIFIER_SECONDS)
        stages = names if with_reconstruction else names[:labelled]
        result = replace(
            seg.result,
            params=params,
            timings={name: timings.get(name, 0.0) for name in stages},
            recomputed=[name for name in stages if name in recomputed],
        )
        return ClassifierOutput(replace(seg, result=result), classifier is None, None, preview)

    yield "pixel classifier", CLASSIFIER_STAGES.index("pixel classifier"), total
    session.preview(cancel)
    yield Partial(output(False, preview=True))
    session.refine(cancel)
    if not partial:
        return output(reconstruction)
    yield Partial(output(False))
    for i, name in enumerate(MAP_STAGES):
        yield name, labelled + i, total
        run_stage(name)
    return output(True)


def named_output(out: ClassifierOutput, names: dict[int, str]) -> ClassifierOutput:
    """``out`` with its materials renamed by ``names`` (scribble value → name): the
    classifier (what *Save classifier…* writes) and the result (what the plots and
    *Export results…* show) both carry the names."""
    if out.segmentation is None or not names:
        return out
    seg = out.segmentation
    classifier = seg.classifier.named(names)
    result = replace(seg.result, materials=classifier.materials())
    return replace(out, segmentation=replace(seg, result=result, classifier=classifier))


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
    parts.append(f"mean class probability {float(confidence.mean()):.2f}")
    return parts
