"""What the Segment widget shows and exports of a result, made without Qt.

:func:`shown_result` turns a run's result (a
:class:`~napari_polarseg.engine.SegmentationResult`, or the scribble mode's
:class:`~napari_polarseg.widgets.session.classify.ClassifierOutput`) into the labels of
the ``segments`` layer, the metadata of every output layer and the status line;
:class:`ExportRecord` is what *Export results…* writes for it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ...engine import SegmentationResult
from ...engine.registered import computes_block_maps
from .classify import ClassifierOutput, classifier_parts, shown_parts
from .text import close_up_text, degenerate_text, k_choice_text, mask_text, object_size_text

#: The inputs of a run without mask, scribbles or classifier file.
NO_INPUTS: dict[str, Any] = {"mask": None, "scribbles": None, "classifier": None}


@dataclass(frozen=True)
class Delivery:
    """What a Segment-widget run's result is checked against and shown with: the stack
    layer, its angles, the snapshot of the inputs when it was requested, the mask,
    scribbles and classifier file used, and its start time (``time.perf_counter``)."""

    layer: Any
    angles_deg: np.ndarray
    snap: Any
    inputs: dict[str, Any]
    t0: float

    def seconds(self) -> float:
        """Seconds since the run was requested."""
        return time.perf_counter() - self.t0


@dataclass
class ShownResult:
    """A run's result as the Segment widget shows it.

    ``labels`` are the ``segments`` layer's data: segment k of the engine is label k + 1
    (napari draws label 0 as transparent background); with the pixel classifier, the
    scribble value of the chosen class, so segments and strokes share their colours.
    ``confidence`` is the classifier's probability of the chosen class (None after the
    cut); ``meta`` the metadata of every output layer; ``inputs`` the mask, scribbles and
    classifier file the run used; ``partial`` is True for the segments a worker yields
    before its last stage (the error map).
    """

    result: SegmentationResult
    out: ClassifierOutput | None
    summary: dict[str, Any]
    meta: dict[str, Any]
    labels: np.ndarray
    confidence: np.ndarray | None
    inputs: dict[str, Any]
    partial: bool = False

    def masked(self) -> np.ndarray:
        """1 where a pixel was left out of the fit and the features (uint8, H x W)."""
        masked = np.zeros(self.labels.shape, dtype=np.uint8)
        if self.result.valid is not None:
            masked = (~np.asarray(self.result.valid, dtype=bool)).astype(np.uint8)
        return masked

    def status(self, seconds: float) -> str:
        """The status line: labels, then (once complete) PCA and error (when the run
        computed the thesis maps), mask and time."""
        summary = self.summary
        if self.out is not None:
            assert self.confidence is not None
            parts = classifier_parts(self.out, self.confidence, self.inputs.get("classifier"))
        else:
            parts = [k_choice_text(summary) or f"{summary['n_segments']} segments"]
            notes = (object_size_text(summary), close_up_text(summary), degenerate_text(summary))
            parts += [t for t in notes if t]
        if self.partial:
            busy = "refining the borders…" if self.out is not None and self.out.preview else None
            return " · ".join([*parts, f"{seconds:.2f} s", busy or "computing the error map…"])
        if summary.get("n_components") is not None:
            parts.append(
                f"{summary['n_components']} PCA components "
                f"({summary['explained_variance']:.0%} variance)"
            )
        if summary.get("mean_reconstruction_error") is not None:
            parts.append(f"mean reconstruction error {summary['mean_reconstruction_error']:.3g}")
        masked_text = mask_text(self.result.mask_counts)
        if masked_text:
            parts.append(masked_text)
        parts.append(f"{seconds:.2f} s")
        return " · ".join(parts)


def shown_result(
    value: SegmentationResult | ClassifierOutput,
    angles_deg: np.ndarray,
    inputs: dict[str, Any] | None = None,
    partial: bool = False,
) -> ShownResult:
    """The labels, metadata and summary the Segment widget shows of ``value``
    (``partial``: the segments before the error map)."""
    inputs = inputs or dict(NO_INPUTS)
    out = value if isinstance(value, ClassifierOutput) else None
    result = out.result if out is not None else value
    assert isinstance(result, SegmentationResult)
    confidence = None
    if out is None:
        summary = result.summary()
    else:
        parts = out.parts
        if parts is None or not parts.fits(result, out.prediction):
            parts = shown_parts(out.segmentation)  # not made in the worker
        summary, confidence = dict(parts.summary), parts.confidence
        summary["classifier"] = {
            "labels_from": "scribbles" if out.trained else "classifier",
            "classes": [int(c) for c in out.prediction.classes],
            "training_pixels": out.classifier.n_training_pixels,
            "mean_class_probability": parts.mean_confidence,
            "mean_uncertainty": parts.mean_uncertainty,
        }
    meta = {
        "polarseg_params": {**result.params.to_dict(), "angles_deg": angles_deg.tolist()},
        "polarseg_summary": summary,
        "polarseg_inputs": inputs,
    }
    if out is not None:  # the scribble value of the chosen class: strokes' colours
        labels = parts.labels
    else:
        labels = np.asarray(result.labels, dtype=np.int32) + 1  # a copy: painting is safe
    return ShownResult(result, out, summary, meta, labels, confidence, inputs, partial)


@dataclass
class ExportRecord:
    """What *Export results…* writes for a stack layer: its last result and inputs.

    The keyword arguments of :func:`napari_polarseg.outputs.write_result_folder` but the
    folder (and ``overview``/``plots``), captured when the result was shown. ``scene``
    (the :class:`~napari_polarseg.engine.Scene` that made an unsupervised result) and
    ``params`` (the parameters the folder records; default the result's) let
    :meth:`complete` add what the folder's contract has and a run without the thesis
    maps did not compute (harmonic coefficients, PCA features, the error map).
    """

    stack: Any
    angles_deg: np.ndarray
    result: SegmentationResult
    mask: Any = None
    source: str | None = None
    probabilities: np.ndarray | None = None
    uncertainty: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    scene: Any = None
    params: Any = None

    @property
    def incomplete(self) -> bool:
        """True when the folder needs what the result lacks (computed by
        :meth:`complete`): the maps of parameters changed since (that the method does not
        read), or the thesis maps of a result of a method that declares ``block_maps``
        (the thesis method) — as ``polarseg segment`` writes them for such a method only
        (or with ``--thesis-maps``, ``--plots``)."""
        return self.needs(plots=False)

    def needs(self, plots: bool) -> bool:
        """:attr:`incomplete`, and with ``plots`` also a result without the thesis maps
        (the plots are drawn from them)."""
        result = self.result
        stale = self.params is not None and self.params != result.params
        lacking = result.features is None or result.reconstruction_error is None
        wanted = plots or computes_block_maps(result.method)
        return self.scene is not None and (stale or (lacking and wanted))

    def complete(self, plots: bool = False) -> ExportRecord:
        """This record with a result that has every map of the folder (a worker's job:
        the scene reruns no method, only the maps that are missing)."""
        if not self.needs(plots):
            return self
        params = self.params if self.params is not None else self.result.params
        maps = plots or self.result.features is not None or computes_block_maps(params.method)
        result = self.scene.segment(params, maps=maps, reconstruction=maps)
        # the same method and values: the same segments, numbered as the viewer shows
        # them (``stable_labels``: a rerun may have renumbered them)
        kept = {"labels": self.result.labels, "block_labels": self.result.block_labels}
        return replace(self, result=replace(result, **kept))

    def named(self, names: dict[int, str]) -> ExportRecord:
        """This record with the classifier's materials renamed by ``names`` (scribble
        value → name): a rename after the run reaches the exported folder."""
        materials = self.result.materials
        if materials is None or not names:
            return self
        result = replace(self.result, materials=materials.renamed(names))
        summary = dict(self.summary)
        if "materials" in summary:
            summary["materials"] = result.materials.to_dict()
        return replace(self, result=result, summary=summary)

    def kwargs(self) -> dict[str, Any]:
        """The keyword arguments of :func:`~napari_polarseg.outputs.write_result_folder`."""
        return {
            "stack": self.stack,
            "angles_deg": self.angles_deg,
            "result": self.result,
            "mask": self.mask,
            "source": self.source,
            "command": "napari",
            "probabilities": self.probabilities,
            "uncertainty": self.uncertainty,
            "info": self.info,
            "summary": self.summary,
        }

    @classmethod
    def of(
        cls,
        shown: ShownResult,
        stack: Any,
        angles_deg: np.ndarray,
        mask: Any,
        source: str | None,
        layer_name: str,
        scene: Any = None,
    ) -> ExportRecord:
        """What *Export results…* needs of ``shown`` (a complete result) of the stack
        layer ``layer_name`` (``stack`` its data, ``mask`` the pipeline's pixel mask,
        ``source`` the file it was read from; ``scene`` the scene of an unsupervised
        result, see :meth:`complete`)."""
        from ...outputs import classifier_summary

        out, inputs = shown.out, shown.inputs
        summary: dict[str, Any] = {}
        if out is not None:
            labels_from = "scribbles" if out.trained else "classifier"
            summary = classifier_summary(out.segmentation, labels_from)
        return cls(
            stack=stack,
            angles_deg=np.asarray(angles_deg, dtype=float),
            result=shown.result,
            mask=mask,
            source=source,
            probabilities=None if out is None else out.prediction.probabilities,
            uncertainty=None if out is None else out.prediction.uncertainty,
            info={
                "napari": {
                    "stack_layer": layer_name,
                    "mask_layer": inputs.get("mask"),
                    "scribbles_layer": inputs.get("scribbles"),
                    "classifier_file": inputs.get("classifier"),
                }
            },
            summary=summary,
            scene=scene if out is None else None,
        )
