"""One angle stack, its shared polarisation image and feature cache, and every method on it.

:class:`Scene` is what the CLI, the plugin and scripts segment: it holds the stack, the
pixel mask and one :class:`~napari_polarseg.engine.Pipeline` whose ``polarisation``
stage (Î, ρ, φ of thesis eq. 3.14, the invalid pixels) every method reads, and whose
block stages are the thesis method's and the thesis maps' (harmonic coefficients, PCA,
reconstruction error) when they are asked for. Each method's output is cached with the
values of the shared parameters it reads (:attr:`~.base.Segmenter.reads`), its own
parameters (all of them) and its inputs, so a change of any other parameter does not
rerun it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import disk_arrays
from ..features.harmonics import top_left_block_labels
from ..features.object_size import ObjectSize, scene_object_size
from ..limits import memory_limit
from ..params import DEFAULT_PRESET, PRESETS, SegmentParams
from ..physics import polarimage
from ..physics.pixel_mask import PixelMask
from ..pipeline import Pipeline
from ..result import SegmentationResult
from .base import MethodOutput, MethodRun, PartialOutput, Progress, Segmenter
from .registry import get_method, method_names

#: The thesis stages that give the maps of the result-folder contract beyond Î, ρ, φ, θ.
MAP_STAGES = ("harmonics", "pca")


def _input_key(inputs: dict[str, Any]) -> tuple:
    """A cache key of a method's inputs: arrays by content digest, others by identity."""
    key = []
    for name in sorted(inputs):
        value = inputs[name]
        if isinstance(value, np.ndarray):
            key.append((name, value.shape, value.dtype.str, hash(value.tobytes())))
        else:
            key.append((name, id(value)))
    return tuple(key)


class Scene:
    """An angle stack ready to be segmented by any registered method.

    Parameters
    ----------
    stack : array (N, H, W)
        Angle stack.
    angles : array (N,)
        Polariser angles in radians.
    mask : array (H, W) or PixelMask, optional
        The user's region (non-zero = segment here) or a whole
        :class:`~napari_polarseg.engine.PixelMask` (see
        :class:`~napari_polarseg.engine.Pipeline`). Every method honours the region:
        the labels inside it do not depend on the pixels outside.
    pipeline : Pipeline, optional
        An existing pipeline of the stack to share (its cache is reused).
    max_bytes : int, optional
        Memory limit of the runs, bytes (the pipeline's :attr:`~.Pipeline.max_bytes`;
        None: :func:`~..limits.memory_limit`). The methods that work tile by tile (the
        default method, the pixel classifier) choose their tiles from it; a shared
        ``pipeline`` takes it when given.

    Examples
    --------
    >>> from napari_polarseg.engine import Scene, PRESETS  # doctest: +SKIP
    >>> scene = Scene(stack, angles)                         # doctest: +SKIP
    >>> scene.segment(PRESETS["auto"].replace(n_segments=3)).labels  # doctest: +SKIP
    """

    def __init__(
        self,
        stack: np.ndarray | None = None,
        angles: np.ndarray | None = None,
        mask: np.ndarray | PixelMask | None = None,
        pipeline: Pipeline | None = None,
        max_bytes: int | None = None,
    ) -> None:
        if pipeline is None:
            pipeline = Pipeline(stack, angles, mask=mask, max_bytes=max_bytes)
        elif max_bytes is not None:
            pipeline.max_bytes = memory_limit(max_bytes)
        self.pipeline = pipeline
        #: how often each method ran (its labels were computed, not taken from the cache)
        self.method_calls: dict[str, int] = {}
        self._cache: dict[str, tuple[Any, Any]] = {}
        self._seconds: dict[str, float] = {}  # each stage's last computation
        self._lock = threading.RLock()

    @property
    def mask(self) -> PixelMask:
        return self.pipeline.mask

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.pipeline.stack.shape[1:])  # type: ignore[return-value]

    @property
    def max_bytes(self) -> int | None:
        """The memory limit of the runs, bytes (None: :func:`~..limits.memory_limit`)."""
        return self.pipeline.max_bytes

    def work_limit(self) -> int:
        """The memory limit of a method's work, bytes: the limit less the stack and its
        flags (:meth:`Pipeline.work_limit <napari_polarseg.engine.Pipeline.work_limit>`);
        the tiles of the methods that tile follow from it."""
        return self.pipeline.work_limit()

    @property
    def region(self) -> np.ndarray | None:
        """The user's region (H, W bool, True = segment here) or None (every pixel)."""
        region = self.mask.region
        return None if region is None or np.all(region) else np.asarray(region, dtype=bool)

    def polarisation(self, params: SegmentParams) -> polarimage.PolarisationImage:
        """The shared polarisation image (Î, ρ, φ, invalid pixels) for ``params.fit``."""
        return self.pipeline.get("polarisation", params)

    def object_size(self, params: SegmentParams) -> ObjectSize:
        """The object size a run uses: ``params.object_size`` px when it is set (> 0),
        else the scene's own estimate on the valid pixels of the region
        (:func:`~..features.object_size.scene_object_size`), made once per polarisation
        image and kept."""
        if params.object_size > 0:
            return ObjectSize.given(float(params.object_size))
        pol = self.polarisation(params)

        def estimate() -> ObjectSize:
            i, d, p = pol.intensity, pol.dop, pol.phase
            return scene_object_size(i, d, p, pol.invalid, 0.0, self.region)

        return self.cached("object_size", id(pol), estimate)

    def cached(self, name: str, key: Any, compute: Callable[[], Any]) -> Any:
        """The feature cache: the value kept under ``name`` if it was made for ``key``,
        else ``compute()`` (kept; one value per name)."""
        with self._lock:
            entry = self._cache.get(name)
            if entry is not None and entry[0] == key:
                return entry[1]
            value = compute()
            self._cache[name] = (key, value)
            return value

    # -- running ------------------------------------------------------------------------
    @staticmethod
    def method_for(params: SegmentParams, inputs: dict[str, Any] | None) -> Segmenter:
        """The method of a run: the one that takes the given inputs (scribbles, a
        classifier), else ``params.method``."""
        given = {k for k, v in (inputs or {}).items() if v is not None and k != "colour_stack"}
        if given:
            for name in method_names():
                method = get_method(name)
                if given & set(method.inputs):
                    return method
        return get_method(params.method)

    @staticmethod
    def stages(
        params: SegmentParams,
        inputs: dict[str, Any] | None = None,
        maps: bool = False,
        reconstruction: bool = False,
    ) -> list[str]:
        """The stages a run goes through, in order (the progress bar's total; no scene
        needed: ``Scene.stages(params, ...)`` before a stack's scene exists).

        The normals (θ, azimuth: what the result shows) come before the method's
        stages, or after them for a method that does not read them
        (:func:`early_stages`): they are then not in memory while it works."""
        method = Scene.method_for(params, inputs)
        names = [*early_stages(method), *method.stages(params)]
        if "normals" not in names:
            names.append("normals")
        if maps:
            names += [s for s in MAP_STAGES if s not in names]
        if reconstruction:
            names.append("reconstruction")
        return names

    def method_key(self, method: Segmenter, params: SegmentParams, inputs: dict) -> tuple:
        """What a method's labels depend on: the shared parameters it reads, all of its
        own parameters (its ``params_class``; whether it names them in ``reads`` or not)
        and its inputs."""
        shared = tuple(getattr(params, f) for f in method.reads)
        return (method.name, shared, params.params_of(method.name), _input_key(inputs))

    def segment(
        self,
        params: SegmentParams | None = None,
        inputs: dict[str, Any] | None = None,
        maps: bool | None = None,
        reconstruction: bool | None = None,
        cancel: Callable[[], bool] | None = None,
        progress: Progress | None = None,
        on_partial: Callable[[SegmentationResult, MethodOutput, bool], None] | None = None,
    ) -> SegmentationResult:
        """Segment with ``params.method`` (or the method that takes ``inputs``).

        Parameters
        ----------
        params : SegmentParams, optional
            Default ``PRESETS["auto"]`` (the default preset of the CLI and the
            plugin: ``SegmentParams().method``, with the recommended block parameters of
            the thesis maps).
        inputs : dict, optional
            ``scribbles`` (H, W int, 0 = unlabelled) or ``classifier`` (a trained
            pixel classifier), and ``colour_stack`` of a colour-polarisation frame.
        maps, reconstruction : bool, optional
            Also the thesis maps (harmonic coefficients and PCA features) and the
            reconstruction-error map. Default: True for a method that declares
            ``block_maps`` (the thesis method: they are its stages), False for the
            others.
        cancel : callable() -> bool, optional
            Checked before every stage and inside the long ones; True raises
            :class:`~napari_polarseg.engine.errors.Cancelled`.
        progress : callable(stage, index, total), optional
            Called when a stage starts (``index`` = stages done) and within it.
        on_partial : callable(result, output, final), optional
            Called (in the running thread) with what the method hands over before the
            run ends (:meth:`~.base.MethodRun.partial`): the result around its output,
            without the maps, and the output itself; ``final`` False for a preview
            (the pixel classifier's coarse labels), True for the method's final labels
            while the maps are computed (only when some are left to compute).
        """
        p = params or PRESETS[DEFAULT_PRESET]
        inputs = {k: v for k, v in (inputs or {}).items() if v is not None}
        method = self.method_for(p, inputs)
        blocks = bool(getattr(method, "block_maps", False))  # the thesis method's maps
        maps = blocks if maps is None else maps
        reconstruction = blocks if reconstruction is None else reconstruction
        run = MethodRun(self.stages(p, inputs, maps, reconstruction), cancel, progress)
        timings: dict[str, float] = {}  # the stages computed in this call
        if on_partial is not None:
            run.on_partial = self._forward(p, method, run, timings, on_partial)
        with self._lock, self.pipeline.full_size_arrays():
            self.pipeline.snapshot(p)
            for stage in early_stages(method):
                self._thesis_stage(stage, p, run, timings)
            out = self._method_output(method, p, inputs, run, timings)
            for stage in run.names[run.names.index(run.current) + 1 :]:
                self._thesis_stage(stage, p, run, timings)
            run.finish()
            self._seconds.update(timings)
            return self._result(p, out, maps, reconstruction, timings, method, run.names)

    def method_output(
        self, params: SegmentParams, inputs: dict[str, Any] | None = None
    ) -> MethodOutput:
        """The kept output of the method of the last :meth:`segment` with ``params`` and
        ``inputs`` (computed now if it is not kept): labels, record and the method's
        extra objects (a classifier's prediction)."""
        inputs = {k: v for k, v in (inputs or {}).items() if v is not None}
        method = self.method_for(params, inputs)
        run = MethodRun(list(method.stages(params)))
        with self._lock, self.pipeline.full_size_arrays():
            return self._method_output(method, params, inputs, run, {})

    def _thesis_stage(
        self, stage: str, p: SegmentParams, run: MethodRun, timings: dict[str, float]
    ) -> Any:
        run.begin(stage)
        fresh = self.pipeline.is_fresh(stage, p)
        value = self.pipeline.get(stage, p, progress=run.within, cancel=run.cancel)
        if not fresh:
            timings[stage] = self.pipeline.stage_seconds(stage)
        return value

    def _method_output(
        self,
        method: Segmenter,
        p: SegmentParams,
        inputs: dict[str, Any],
        run: MethodRun,
        timings: dict[str, float],
    ) -> MethodOutput:
        key = (self.method_key(method, p, inputs), id(self.polarisation(p)))
        name = f"method:{method.name}"
        entry = self._cache.get(name)
        if entry is not None and entry[0] == key:
            for stage in method.stages(p):
                run.begin(stage)
            return entry[1]
        t0 = time.perf_counter()
        out = method.segment(self, p, inputs, run)
        timings.update(out.seconds or {method.name: time.perf_counter() - t0})
        self.method_calls[method.name] = self.method_calls.get(method.name, 0) + 1
        self._cache[name] = (key, out)
        return out

    def _forward(
        self,
        p: SegmentParams,
        method: Segmenter,
        run: MethodRun,
        timings: dict[str, float],
        on_partial: Callable[[SegmentationResult, MethodOutput, bool], None],
    ) -> PartialOutput:
        """The receiver of the method's partial outputs in :meth:`segment`: each goes to
        ``on_partial`` with the result around it (no maps); the final labels only when
        stages are left after the method's (else the whole result follows at once)."""
        last = max((run.names.index(s) for s in method.stages(p)), default=1)  # normals
        done, left = run.names[: last + 1], run.names[last + 1 :]
        left = [s for s in left if s != "normals"]  # part of any result, no maps

        def forward(out: MethodOutput, final: bool) -> None:
            if final and all(self.pipeline.is_fresh(s, p) for s in left):
                return
            on_partial(self._result(p, out, False, False, timings, method, done), out, final)

        return forward

    def _result(
        self,
        p: SegmentParams,
        out: MethodOutput,
        maps: bool,
        reconstruction: bool,
        timings: dict[str, float],
        method: Segmenter,
        names: list[str],
    ) -> SegmentationResult:
        """The result of a run (:meth:`Pipeline.assemble_result
        <napari_polarseg.engine.Pipeline.assemble_result>` around the method's output)."""
        # int64, in a temporary file when the full-size arrays do not fit the limit
        labels = disk_arrays.copy_of(np.asarray(out.labels), np.int64)
        stages = [*names, method.name]
        seconds = {**self._seconds, **timings}  # this call's too (a partial result's)
        # the block labels from the method's own labels, the same values (a strided
        # read maps most pages of an array on disk: of the int32 labels, not the copy)
        blocks = top_left_block_labels(np.asarray(out.labels), p.window).astype(np.int64)
        return self.pipeline.assemble_result(
            blocks.astype(np.int32),
            labels,
            list(out.ncut_values),
            reconstruction,
            timings={s: seconds[s] for s in stages if s in seconds},
            recomputed=list(dict.fromkeys(s for s in stages if s in timings)),
            cut_limits=dict(out.cut_limits),
            params=p,
            superpixels=dict(out.record) if "close_up" in out.record else {},
            maps=maps,
            method=method.name,
            method_record=dict(out.record),
            materials=out.extra.get("materials"),  # a classifier's classes: value and name
            on_blocks=maps or bool(getattr(method, "block_maps", False)),
        )


def early_stages(method: Segmenter) -> tuple[str, ...]:
    """The shared stages a run computes before ``method``'s: the polarisation fit, and
    the normals unless the method declares ``reads_normals = False`` (the superpixel
    methods; the scene then computes them after the method, for the result)."""
    if getattr(method, "reads_normals", True):
        return ("polarisation", "normals")
    return ("polarisation",)


def segment(
    stack: np.ndarray,
    angles: np.ndarray,
    params: SegmentParams | None = None,
    mask: np.ndarray | PixelMask | None = None,
    **changes: Any,
) -> SegmentationResult:
    """One-shot convenience: segment a stack (angles in radians) with ``params.method``
    (default: ``PRESETS["auto"]``, as the CLI and the plugin), ``changes`` applied to
    ``params``."""
    params = params or PRESETS[DEFAULT_PRESET]
    if changes:
        params = params.replace(**changes)
    return Scene(stack, angles, mask).segment(params)


def pipeline_labels(pipeline: Pipeline, params: SegmentParams) -> np.ndarray:
    """Pixel labels of ``params.method`` on a pipeline's stack (a :class:`Scene` on it,
    no thesis maps): the ``day_labels`` of
    :func:`~napari_polarseg.engine.analysis.timeseries.segment_timeseries`."""
    return Scene(pipeline=pipeline).segment(params, maps=False, reconstruction=False).labels
