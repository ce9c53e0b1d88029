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

from ...engine import PolarsegError, Scene, SegmentParams
from ...engine.registered import computes_block_maps
from .classify import classify_scene
from .lazy_input import reading_stage
from .results import ExportRecord
from .runs import Job, Partial, Result, Stage
from .store import PipelineStore

if TYPE_CHECKING:
    from ...engine.classifier.classifier_settings import ClassifierSettings
    from ...engine.classifier.pixel_classifier import PixelClassifier


def wants_maps(params: SegmentParams, thesis_maps: bool = False) -> bool:
    """Whether a run computes the thesis maps (harmonic coefficients, PCA features) and
    the reconstruction-error map: always for a method that declares ``block_maps`` (the
    thesis method: its window, degree and refractive index are tuned with the error
    map), else when ``thesis_maps`` asks."""
    return computes_block_maps(params.method) or bool(thesis_maps)


def segment_job(
    store: PipelineStore,
    key: str,
    data: Any,
    angles_rad: np.ndarray,
    params: SegmentParams,
    region: np.ndarray | None = None,
    mask_key: str | None = None,
    prefetch: bool = False,
    maps: bool = True,
    inputs: dict[str, Any] | None = None,
    cancel: Callable[[], bool] | None = None,
    report: Callable[[str, float, int], None] | None = None,
    partial: Callable[[Any], None] | None = None,
) -> Generator[Any, None, Any]:
    """Worker job: the method ``params.method`` on the layer's kept
    :class:`~napari_polarseg.engine.Scene` (it reruns only when a parameter it reads
    changes); with ``maps`` also the thesis maps and then the error map. With
    ``inputs`` holding ``scribbles`` or a ``classifier``, the scene's pixel classifier
    instead (:func:`~napari_polarseg.widgets.session.classify.classify_scene`, with the
    maps and the error map; ``colour_stack``, ``settings``): it returns a
    :class:`~napari_polarseg.widgets.session.ClassifierOutput` and hands its preview and
    final labels to ``partial`` (the runner's: shown in the GUI thread as a
    :class:`~napari_polarseg.widgets.session.Partial`) while it runs.

    ``region`` (H, W bool, True = use) restricts the segmentation; saturated and black
    samples are left out in any case (:meth:`PipelineStore.obtain`). The progress is the
    run's own stage list (``Scene.stages``): ``report`` (the runner's,
    ``WorkerSlot.submit(..., reports=True)``) receives ``(stage, index, total)`` when a
    stage starts (``index`` = stages done, fractional within the chunked stages), so the
    status line names the stage that runs and the total is what runs. When the
    reconstruction (error map) has to be recomputed, the result without it is yielded
    first as a :class:`~napari_polarseg.widgets.session.Partial`: the segments are shown
    while the last stage runs. Without ``maps`` the result has no coefficients, features
    or error map (``None``).

    With ``prefetch`` (a method that cuts the block graph: the thesis method), the
    result is yielded as a :class:`~napari_polarseg.widgets.session.Result` and the job
    goes on in idle time with
    :meth:`Pipeline.prefetch <napari_polarseg.engine.Pipeline.prefetch>` (the
    eigensolves one more segment needs), stopping at the next request.

    ``cancel`` (the runner's stop request) is checked by the scene before every stage and
    inside the long ones (:class:`~napari_polarseg.engine.errors.Cancelled`).

    A lazy (Dask) stack layer no pipeline has read yet is read whole first, its own stage
    in the status line, or refused when it does not fit the memory limit
    (:mod:`~napari_polarseg.widgets.session.lazy_input`).
    """
    inputs = {k: v for k, v in (inputs or {}).items() if v is not None}
    classify = "scribbles" in inputs or "classifier" in inputs
    maps = maps or classify
    total = len(Scene.stages(params, inputs, maps=maps, reconstruction=maps))
    yield from reading_stage(store, key, data, total)  # a lazy stack: read whole first
    pipe = store.obtain(key, data, angles_rad, params, region=region, mask_key=mask_key)
    scene = store.scene(key)
    assert scene is not None

    def within(stage: str, index: float, _n: int) -> None:
        # the first call of a run with maps lists every stage but the last: the same
        # order, so its indexes count on the whole run's scale
        if report is not None and stage != "done":
            report(stage, index, total)

    if classify:
        return classify_scene(scene, params, inputs, True, cancel, within, partial)
    if not maps:
        return scene.segment(
            params, maps=False, reconstruction=False, cancel=cancel, progress=within
        )
    result = scene.segment(params, maps=True, reconstruction=False, cancel=cancel, progress=within)
    if not pipe.is_fresh("reconstruction", params):
        yield Partial(result)  # the segments are shown while the error map is computed
    result = scene.segment(params, maps=True, reconstruction=True, cancel=cancel, progress=within)
    if prefetch and computes_block_maps(params.method):
        yield Result(result)
        for _ in pipe.prefetch(params, cancel):
            yield "prefetch", total, total
    return result


#: Stages :func:`features_job` reports: the polarisation image and the pixel features
#: (the session computes the normals beside them).
FEATURES_JOB_STAGES = 2


def features_job(
    store: PipelineStore,
    key: str,
    data: Any,
    angles_rad: np.ndarray,
    params: SegmentParams,
    region: np.ndarray | None = None,
    mask_key: str | None = None,
    colour_stack: np.ndarray | None = None,
) -> Generator[Any, None, int]:
    """Worker job run when a scribbles layer is chosen before it holds strokes: the
    polarisation image and the stack's pixel features, kept by the scene's
    :class:`~napari_polarseg.engine.ScribbleSession` (:meth:`PipelineStore.session`), so
    the first strokes only train and predict. Returns the number of features."""
    total = FEATURES_JOB_STAGES
    yield from reading_stage(store, key, data, total)  # a lazy stack: read whole first
    pipe = store.obtain(key, data, angles_rad, params, region=region, mask_key=mask_key)
    yield "polarisation", 0, total
    pipe.get("polarisation", params)
    session = store.session(key, colour_stack)
    assert session is not None
    session.segment_params = params
    yield "pixel features", total - 1, total
    return session.features().n_features


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


def export_job(
    folder: Path, record: ExportRecord, options: dict[str, Any]
) -> Generator[Stage, None, list[str]]:
    """Worker job of *Export results…*: :func:`~napari_polarseg.outputs.write_result_folder`
    of ``record`` (``options``: ``overview``, ``plots``). A result without the thesis
    maps gets them first when the folder has them (:meth:`ExportRecord.complete`: the
    thesis method, or plots asked for), so the folder is the one ``polarseg segment --out``
    writes for the same method and options. A file that cannot be written is reported as
    a :class:`PolarsegError`."""
    from ...outputs import OutputError, write_result_folder

    plots = bool(options.get("plots"))
    if record.needs(plots):
        yield "thesis maps and error map", 0, 2
        record = record.complete(plots)
    yield "writing", 1, 2
    try:
        return write_result_folder(folder, **record.kwargs(), **options)
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
    maps: bool = True,
    settings: ClassifierSettings | None = None,
) -> SegmentRequest:
    """The job that segments ``data`` (:func:`segment_job`): the method of ``params``
    (with the thesis maps and error map when ``maps``; prefetching in idle time for the
    thesis method) without ``scribbles`` and ``classifier``, else the pixel classifier
    trained on the strokes (with ``settings``) or the loaded one applied.

    ``total`` is the number of stages the run goes through (:meth:`Scene.stages
    <napari_polarseg.engine.Scene.stages>`; the job reports the same total with every
    stage)."""
    inputs = {"scribbles": scribbles, "classifier": classifier}
    if scribbles is not None or classifier is not None:
        inputs |= {"colour_stack": colour_stack, "settings": settings}
        maps = True  # the classifier's result has the thesis maps and the error map
    total = len(Scene.stages(params, inputs, maps=maps, reconstruction=maps))
    args = (store, key, data, angles_rad, params, region, mask_key, True, maps, inputs)
    return SegmentRequest(segment_job, args, total, True)
