"""Worker jobs and what they yield: no Qt, no napari, no magicgui.

A *job* is a generator function that calls the engine and yields ``(stage, index,
total)`` between stages (and, optionally, :class:`Partial` results to show before the
end, or a :class:`Result` before idle-time work). The Qt side
(:class:`~napari_polarseg.widgets._runner.WorkerSlot`) runs it off the GUI thread; a
script or a test can drive the same generator by hand.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...engine import PolarsegError, SegmentParams, get_method
from .classify import CLASSIFIER_STAGES, ClassifierOutput, classifier_stages
from .runs import Job, Partial, Result, Stage
from .store import PipelineStore

if TYPE_CHECKING:
    from ...engine.analysis.pixel_classifier import PixelClassifier


def segment_job(
    store: PipelineStore,
    key: str,
    data: Any,
    angles_rad: np.ndarray,
    params: SegmentParams,
    region: np.ndarray | None = None,
    mask_key: str | None = None,
    prefetch: bool = False,
    cancel: Callable[[], bool] | None = None,
    report: Callable[[str, float, int], None] | None = None,
) -> Generator[Any, None, Any]:
    """Worker job: the method ``params.method`` on the layer's kept
    :class:`~napari_polarseg.engine.Scene` (it reruns only when a parameter it reads
    changes), with the thesis maps, then the error map.

    ``region`` (H, W bool, True = use) restricts the segmentation; saturated and black
    samples are left out in any case (:meth:`PipelineStore.obtain`). Yields ``(stage,
    index, total)`` after the labels and after the error map; stopping the worker between
    two yields cancels the run and leaves the stages computed so far cached. When the
    reconstruction (error map)
    has to be recomputed, the result without it is yielded first as a
    :class:`~napari_polarseg.widgets.session.Partial`: the segments are shown while the
    last stage runs (after a change of n or w it is a third of the run).

    With ``prefetch``, the result is yielded as a
    :class:`~napari_polarseg.widgets.session.Result` and the job goes on in idle time
    with :meth:`Pipeline.prefetch <napari_polarseg.engine.Pipeline.prefetch>` (the
    eigensolves one more segment needs), stopping at the next request.

    ``cancel`` (the runner's stop request) is handed to the normalized cut, which checks
    it before every product of its eigensolvers and raises
    :class:`~napari_polarseg.engine.errors.Cancelled`: Cancel or a newer request stops a
    long cut (or a prefetch) at once instead of at the end of the stage.

    ``report`` (the runner's, ``WorkerSlot.submit(..., reports=True)``) receives the
    progress within the stages that loop in chunks (harmonics, reconstruction) as
    ``(stage, index, total)`` with a fractional ``index`` on the same scale as the
    yields (:meth:`Pipeline.run_iter <napari_polarseg.engine.Pipeline.run_iter>`).
    """
    pipe = store.obtain(key, data, angles_rad, params, region=region, mask_key=mask_key)
    scene = store.scene(key)
    assert scene is not None
    total = len(scene.stages(params, maps=True, reconstruction=True))

    def within(stage: str, index: float, _n: int) -> None:
        if report is not None and stage != "done":
            report(stage, index, total)

    result = scene.segment(params, maps=True, reconstruction=False, cancel=cancel, progress=within)
    yield "labels", total - 1, total
    if not pipe.is_fresh("reconstruction", params):
        # the segments are shown while the error map is computed
        yield Partial(result)
    result = scene.segment(params, maps=True, reconstruction=True, cancel=cancel, progress=within)
    yield "reconstruction", total, total
    if prefetch and params.method == "thesis":
        yield Result(result)
        for _ in pipe.prefetch(params, cancel):
            yield "prefetch", total, total
    return result


def classifier_job(
    store: PipelineStore,
    key: str,
    data: Any,
    angles_rad: np.ndarray,
    params: SegmentParams,
    scribbles: np.ndarray | None,
    classifier: PixelClassifier | None,
    region: np.ndarray | None = None,
    mask_key: str | None = None,
    colour_stack: np.ndarray | None = None,
    cancel: Callable[[], bool] | None = None,
) -> Generator[Any, None, ClassifierOutput]:
    """Worker job of the scribble mode: the cached pipeline's stages up to the block
    features, the stack's kept pixel features, then the pixel classifier trained on
    ``scribbles`` (or the loaded ``classifier`` applied) and the reconstruction
    (:func:`~napari_polarseg.widgets.session.classify.classifier_stages`). ``cancel`` stops the
    prediction between chunks. ``colour_stack`` (C, N, H, W): the colour stacks of a
    colour-polarisation frame whose luminance is ``data`` (the reader's
    ``metadata["colour_stack"]``), whose polarisation images add features."""
    pipe = store.obtain(key, data, angles_rad, params, region=region, mask_key=mask_key)
    segmenter = store.segmenter(key, colour_stack)
    assert segmenter is not None
    return (
        yield from classifier_stages(
            pipe, segmenter, params, scribbles, classifier, reconstruction=True, cancel=cancel
        )
    )


def read_classifier_job(path: Path) -> Generator[Stage, None, PixelClassifier]:
    """Worker job of *Load classifier…*: the checked classifier file (never runs code
    from it; a bad file raises a one-line :class:`PolarsegError`)."""
    from ...classifier_file import load_pixel_classifier

    yield "reading", 1, 1
    return load_pixel_classifier(path)


def write_classifier_job(path: Path, classifier: PixelClassifier) -> Generator[Stage, None, Path]:
    """Worker job of *Save classifier…*: the classifier file, written atomically."""
    from ...classifier_file import save_pixel_classifier

    yield "writing", 1, 1
    save_pixel_classifier(path, classifier)
    return path


def export_job(folder: Path, kwargs: dict[str, Any]) -> Generator[Stage, None, list[str]]:
    """Worker job of *Export results…*: :func:`~napari_polarseg.outputs.write_result_folder`
    (a file that cannot be written is reported as a :class:`PolarsegError`)."""
    from ...outputs import OutputError, write_result_folder

    yield "writing", 1, 1
    try:
        return write_result_folder(folder, **kwargs)
    except OutputError as exc:
        raise PolarsegError(str(exc)) from None


@dataclass(frozen=True)
class SegmentRequest:
    """The job of a Segment-widget run, its arguments, its number of stages, and whether
    it takes a ``report`` callable for progress within a stage."""

    job: Job
    args: tuple[Any, ...]
    total: int
    reports: bool


def segment_request(
    store: PipelineStore,
    key: str,
    data: Any,
    angles_rad: np.ndarray,
    params: SegmentParams,
    region: np.ndarray | None,
    mask_key: str | None,
    scribbles: np.ndarray | None = None,
    classifier: PixelClassifier | None = None,
    colour_stack: np.ndarray | None = None,
) -> SegmentRequest:
    """The job that segments ``data``: the normalized cut (:func:`segment_job`, then
    prefetching in idle time, with progress within the harmonics and reconstruction)
    without ``scribbles`` and ``classifier``, else the pixel classifier trained on the
    strokes or the loaded one applied (:func:`classifier_job`)."""
    if scribbles is None and classifier is None:
        args = (store, key, data, angles_rad, params, region, mask_key, True)
        total = 2 + len(get_method(params.method).stages(params)) + 1
        if params.method != "thesis":
            total += 2  # the thesis maps (harmonics, PCA) beside its labels
        return SegmentRequest(segment_job, args, total, reports=True)
    args = (store, key, data, angles_rad, params, scribbles, classifier)
    args += (region, mask_key, colour_stack)
    return SegmentRequest(classifier_job, args, len(CLASSIFIER_STAGES), reports=False)
