"""The pixel classifier as a method: trained on the user's scribbles, or a saved one
applied (:mod:`napari_polarseg.engine.analysis.pixel_classifier`).

Multi-scale pixel features of the shared polarisation image (kept in the scene while
the image stays: a new stroke only retrains and predicts), a random forest on the
scribbled pixels, a prediction for every pixel. Selected by its inputs: ``scribbles``
or ``classifier``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.pixel_segmentation import PixelSegmenter
from ..params import SegmentParams
from ..physics.pixel_mask import fill_from_nearest
from .base import MethodOutput, MethodRun

if TYPE_CHECKING:
    from .scene import Scene


class PixelClassification:
    """The scribble-trained pixel classifier as a :class:`~.base.Segmenter`."""

    name = "classifier"
    title = "pixel classifier (scribbles)"
    reads = ("fit",)
    inputs = ("scribbles", "classifier")

    def stages(self, params: SegmentParams) -> tuple[str, ...]:
        return ("features", "classifier")

    def segmenter(self, scene: Scene, colour_stack: np.ndarray | None = None) -> PixelSegmenter:
        """The scene's pixel segmenter (kept: its feature stack survives new strokes)."""
        return scene.cached(
            "pixel_segmenter",
            id(colour_stack),
            lambda: PixelSegmenter(scene.pipeline, colour_stack=colour_stack),
        )

    def segment(
        self, scene: Scene, params: SegmentParams, inputs: dict[str, Any], run: MethodRun
    ) -> MethodOutput:
        run.begin("features")
        seg = self.segmenter(scene, inputs.get("colour_stack"))
        classifier = inputs.get("classifier")
        if classifier is None:
            seg.features(segment_params=params, progress=run.within)
        else:
            colour = any(n.split(":", 1)[0] in seg.colours for n in classifier.feature_names)
            seg.features(classifier.feature_params, colour, params, progress=run.within)
        run.begin("classifier")
        prediction, classifier, seconds = seg.classify(
            inputs.get("scribbles"),
            classifier,
            cancel=run.cancel,
            segment_params=params,
        )
        labels = prediction.labels
        if scene.region is not None:
            (labels,) = fill_from_nearest(scene.region, labels)
        extra = {"prediction": prediction, "classifier": classifier, "seconds": seconds}
        extra["materials"] = classifier.materials()
        return MethodOutput(labels, record={"seconds": seconds}, extra=extra)
