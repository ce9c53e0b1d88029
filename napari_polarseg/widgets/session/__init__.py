"""The widgets' headless session layer: everything they run that needs no Qt.

Imports neither ``qtpy`` nor ``napari`` nor ``magicgui`` (a test checks), so scripts
and tests can drive the same jobs without a window. The Qt side is thin:
:class:`~napari_polarseg.widgets._runner.WorkerSlot` runs these jobs off the GUI thread
and the widgets show what they return.

- :mod:`~napari_polarseg.widgets.session.runs`: what a job yields (:data:`Stage`,
  :class:`Partial`, :class:`Result`) and how it runs (:func:`guarded`).
- :mod:`~napari_polarseg.widgets.session.store`: :class:`PipelineStore`, one cached
  pipeline per angle-stack layer.
- :mod:`~napari_polarseg.widgets.session.classify`: the scribble mode on a stack's
  scene (:func:`classify_scene`, :class:`ClassifierOutput`).
- :mod:`~napari_polarseg.widgets.session.jobs`: the Segment widget's worker jobs
  (:func:`segment_job` for every method and the classifier, the classifier and export
  files).
- :mod:`~napari_polarseg.widgets.session.results`: what is shown and exported of a
  result (:func:`shown_result`, :class:`ExportRecord`).
- :mod:`~napari_polarseg.widgets.session.inputs` and
  :mod:`~napari_polarseg.widgets.session.text`: content digests, status texts, error
  messages, the angles field; :mod:`~napari_polarseg.widgets.session.files`: the
  parameters JSON.
"""

from .classify import (
    ClassifierOutput,
    LoadedClassifier,
    classifier_parts,
    classifier_segmentation,
    classifier_text,
    classify_scene,
    named_output,
    scribble_problem,
)
from .files import write_params_json
from .inputs import colour_stack_of, content_digest, input_info, region_digest
from .jobs import (
    FEATURES_JOB_STAGES,
    SegmentRequest,
    export_job,
    features_job,
    read_classifier_job,
    segment_job,
    segment_request,
    wants_maps,
    write_classifier_job,
)
from .results import NO_INPUTS, Delivery, ExportRecord, ShownResult, shown_result
from .runs import Job, Partial, Result, Stage, StageFailed, blas_share, guarded, relay
from .store import PipelineStore, stack_pipeline
from .text import (
    degenerate_text,
    error_message,
    format_angles,
    mask_text,
    stage_text,
)

__all__ = [
    "NO_INPUTS",
    "ClassifierOutput",
    "Delivery",
    "ExportRecord",
    "Job",
    "LoadedClassifier",
    "Partial",
    "PipelineStore",
    "Result",
    "SegmentRequest",
    "ShownResult",
    "Stage",
    "StageFailed",
    "blas_share",
    "FEATURES_JOB_STAGES",
    "features_job",
    "classifier_parts",
    "classifier_segmentation",
    "classifier_text",
    "classify_scene",
    "named_output",
    "colour_stack_of",
    "content_digest",
    "degenerate_text",
    "error_message",
    "export_job",
    "format_angles",
    "guarded",
    "input_info",
    "mask_text",
    "read_classifier_job",
    "region_digest",
    "relay",
    "scribble_problem",
    "segment_job",
    "segment_request",
    "shown_result",
    "stack_pipeline",
    "stage_text",
    "wants_maps",
    "write_classifier_job",
    "write_params_json",
]
