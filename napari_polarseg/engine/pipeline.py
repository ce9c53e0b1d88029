"""The segmentation pipeline of thesis section 4.5, with a per-stage cache.

Stages, each a function of :mod:`.stages`, and the parameters each depends on::

    polarisation   (stack, angles)                       → Î, ρ, φ          polarimage.py
    normals        refractive_index, model, branch        → θ, azimuth       fresnel.py
    harmonics      window, degree, coefficients, ridge    → block a_lm       harmonics.py
    pca            features, variance                     → block features   features.py
    affinity       scale, scale_mode, spatial_*, graph    → S = exp(−D/s)    features.py
    cut            min_segment_blocks, ncut_threshold     → cut tree         ncut.py
    labels         n_segments                             → labels           ncut.py
    reconstruction window, degree, ridge (after normals)  → Î rebuilt, error harmonics.py

Every call takes the parameters of its own run (a snapshot: nothing a caller or another
thread does later changes them). A stage is recomputed only when one of its own
parameters or an upstream stage changed: running with another ``n_segments`` re-reads
the cached cut tree and never recomputes harmonics.
"""

from __future__ import annotations

import contextlib
import threading
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from . import disk_arrays
from .errors import Cancelled, PolarsegError
from .features import harmonics
from .graph import affinity, ncut
from .limits import memory_limit, work_bytes
from .matrix_pool import DenseDistances, MatrixPool
from .params import SegmentParams
from .physics import pixel_mask, polarimage
from .physics.pixel_mask import PixelMask
from .registered import computes_block_maps
from .result import SegmentationResult
from .stages import (
    STAGE_FUNCTIONS,
    STAGES,
    UPSTREAM,
    StageRun,
    block_valid,
    block_vectors,
    own_key,
)
from .timing import timed


class Pipeline:
    """Cached pipeline over one angle stack.

    Parameters
    ----------
    stack : array (N, H, W)
        Angle stack.
    angles : array (N,)
        Polariser angles in radians.
    params : SegmentParams, optional
        Parameters of the calls that are given none (default ``PRESETS["thesis"]``); each
        :meth:`run`, :meth:`get`, :meth:`result`, … takes the parameters of its own run,
        and :attr:`params` is then the last run's.
    mask : array (H, W) or PixelMask, optional
        Which pixels the fit and the block features use. An (H, W) array is the user's
        region (non-zero = segment here), combined with the samples flagged by
        :func:`~napari_polarseg.engine.physics.pixel_mask.validity_mask` with its defaults
        (saturated at the integer dtype's maximum, black at or below 0, not finite). A
        :class:`~napari_polarseg.engine.PixelMask` is used as it is (e.g. with
        another saturation level, or found by the reader before dark subtraction). None:
        the default flags over the whole image. Fixed for the pipeline's lifetime.
        Excluded pixels still get values and labels (their block's), but are left out of
        the sinusoid fit of their own pixel where possible, of the block coefficients and
        of the reconstruction fit; counts are in :meth:`SegmentationResult.summary`.
    max_bytes : int, optional
        Memory limit of the runs on this stack, bytes (:attr:`max_bytes`; None:
        :func:`~.limits.memory_limit`, ``$POLARSEG_MAX_BYTES`` or its default). The
        methods that work tile by tile choose their tiles from it.

    The cache holds one value per stage, keyed on the stage's own parameters and its
    upstream stage's key; a re-entrant lock guards it, so runs from several threads
    compute one after the other and each gets the result of its own parameters.

    Examples
    --------
    >>> from napari_polarseg.engine import Pipeline, SegmentParams
    >>> pipe = Pipeline(stack, angles, SegmentParams(n_segments=3))  # doctest: +SKIP
    >>> result = pipe.run()                                          # doctest: +SKIP
    >>> pipe.run(pipe.params.replace(n_segments=4)).n_segments       # doctest: +SKIP
    4
    """

    def __init__(
        self,
        stack: np.ndarray,
        angles: np.ndarray,
        params: SegmentParams | None = None,
        mask: np.ndarray | PixelMask | None = None,
        max_bytes: int | None = None,
    ) -> None:
        raw = stack
        self.stack, self.angles = polarimage.check_stack(stack, angles)
        if params is None:  # the thesis block graph, as published
            from .params import PRESETS

            params = PRESETS["thesis"]
        if not isinstance(params, SegmentParams):
            raise PolarsegError("params must be a SegmentParams")
        self._params = params
        #: memory limit of the runs, bytes (None: :func:`~.limits.memory_limit`)
        self.max_bytes = None if max_bytes is None else memory_limit(max_bytes)
        if not isinstance(mask, PixelMask):
            # the flags (1 byte a sample) in a temporary file when the full-size
            # arrays do not fit the work limit (the stack's flags counted as made)
            limit = self.held_limit(self.stack.nbytes + self.stack.size)
            with disk_arrays.full_size_limit(limit):
                mask = pixel_mask.validity_mask(raw, region=mask)
        elif mask.flags.shape != self.stack.shape:
            raise PolarsegError(
                f"the pixel mask covers {mask.flags.shape} samples but the stack is "
                f"{self.stack.shape}"
            )
        self.mask: PixelMask = mask
        pixel_mask.check_usable(self.stack, self.mask)
        #: how often each stage was computed
        self.calls: Counter = Counter()
        #: memory for the dense n × n matrices, and the kept distances (stages.py)
        self.matrices = MatrixPool()
        self.distances: DenseDistances | None = None
        self._cache: dict[str, tuple[tuple, Any]] = {}
        self._seconds: dict[str, float] = {}
        #: (parameters, stages computed for them since their run began)
        self._recomputed: tuple[SegmentParams, list[str]] = (params, [])
        self._lock = threading.RLock()

    def work_limit(self) -> int:
        """The memory limit of the methods' work, bytes: :attr:`max_bytes` (or
        :func:`~.limits.memory_limit`) less the stack, the mask's flags and the
        libraries (:data:`~.limits.RUNTIME_BYTES`), which the methods' own estimates
        (over :data:`~.limits.KEPT_MAPS`) do not count; at least 1 byte."""
        return self.held_limit(self.stack.nbytes + self.mask.flags.nbytes)

    def held_limit(self, held: int) -> int:
        """:attr:`max_bytes` (or :func:`~.limits.memory_limit`) less ``held`` bytes and
        the libraries (:data:`~.limits.RUNTIME_BYTES`), bytes; at least 1."""
        return work_bytes(self.max_bytes, held)

    def full_size_arrays(self) -> contextlib.AbstractContextManager[None]:
        """The context in which the full-size arrays of a run (the fit's maps, the
        superpixels, the labels) are made: in memory, or in temporary files when they do
        not fit :meth:`work_limit` (:func:`~.disk_arrays.full_size_limit`)."""
        return disk_arrays.full_size_limit(self.work_limit())

    # -- parameters -------------------------------------------------------------------
    @property
    def params(self) -> SegmentParams:
        """The parameters of the last run (or those the pipeline was made with)."""
        return self._params

    def snapshot(self, params: SegmentParams | None) -> SegmentParams:
        """The parameters of a call: ``params`` (then the last run's), or the last run's."""
        if params is None:
            return self._params
        if not isinstance(params, SegmentParams):
            raise PolarsegError("params must be a SegmentParams")
        self._params = params
        return params

    def key(self, stage: str, params: SegmentParams | None = None) -> tuple:
        """Cache key of a stage: its own parameters plus its upstream stage's key."""
        p = self._params if params is None else params
        up = UPSTREAM[stage]
        own = own_key(stage, p)
        return own if up is None else (own, self.key(up, p))

    def cached(self, stage: str) -> Any | None:
        """The value cached for ``stage`` (for whichever parameters), or None."""
        entry = self._cache.get(stage)
        return None if entry is None else entry[1]

    def is_fresh(self, stage: str, params: SegmentParams | None = None) -> bool:
        """True if ``stage`` is cached for ``params`` (default: the last run's)."""
        entry = self._cache.get(stage)
        return entry is not None and entry[0] == self.key(stage, params)

    def stages(self, reconstruction: bool = True, params: SegmentParams | None = None) -> list[str]:
        """Stages a run computes, in order: every stage of :data:`STAGES` but the
        reconstruction when not asked for."""
        return list(STAGES if reconstruction else STAGES[:-1])

    def stale_stages(
        self, reconstruction: bool = True, params: SegmentParams | None = None
    ) -> list[str]:
        """The stages of :meth:`stages` not cached for ``params``."""
        names = self.stages(reconstruction, params)
        return [s for s in names if not self.is_fresh(s, params)]

    def recomputed_stages(self, params: SegmentParams | None = None) -> list[str]:
        """Stages computed for ``params`` since their last :meth:`run_iter` began."""
        p = self._params if params is None else params
        done_for, names = self._recomputed
        return list(names) if done_for == p else []

    def block_valid(self, params: SegmentParams | None = None) -> np.ndarray:
        """Blocks that enter the graph (flat, row-major): at least
        :data:`~.stages.MIN_VALID_BLOCK_FRACTION` of their pixels are used (not masked,
        saturated, black or invalid). The others are labelled from their nearest valid
        block."""
        return block_valid(self, StageRun(self.snapshot(params)))

    def block_vectors(
        self, standardise: bool = True, params: SegmentParams | None = None
    ) -> np.ndarray:
        """Feature vector of every block (rows·cols, F) for the ``features`` kind.

        What the ``pca`` stage reduces. With ``standardise=False`` the polarisation
        statistics are returned in their own units, so that a caller pooling several
        images (the time series' shared basis) can standardise them over all of them.
        """
        run = StageRun(self.snapshot(params))
        return block_vectors(self, run, self.stage_value("harmonics", run), standardise)

    # -- stages -----------------------------------------------------------------------
    def stage_value(self, stage: str, run: StageRun) -> Any:
        """Value of ``stage`` for ``run.params``, computed (and cached) if stale.

        The lock is held while the stage (and any stale upstream stage) computes, so a
        run from another thread cannot replace an entry in between; the key and every
        upstream value come from the same parameters.
        """
        with self._lock:
            key = self.key(stage, run.params)
            entry = self._cache.get(stage)
            if entry is not None and entry[0] == key:
                return entry[1]
            with timed(self._seconds, stage), self.full_size_arrays():
                value = STAGE_FUNCTIONS[stage](self, run)
                # kept in temporary files when the full-size arrays do not fit
                value = disk_arrays.kept(value, self.stack.shape[1:])
            self.calls[stage] += 1
            run.recomputed.append(stage)
            done_for, names = self._recomputed
            if done_for == run.params:
                names.append(stage)
            else:
                self._recomputed = (run.params, [stage])
            self._cache[stage] = (key, value)
            return value

    def get(
        self,
        stage: str,
        params: SegmentParams | None = None,
        progress: Callable[[float], None] | None = None,
        cancel: Callable[[], bool] | None = None,
    ) -> Any:
        """Value of a stage for ``params`` (default: the last run's), computing it if
        stale. ``progress`` is called with the share of ``stage`` done (0..1] by the
        stages that loop in chunks (harmonics, reconstruction), after each chunk (it may
        raise :class:`Cancelled` to stop the stage there); ``cancel`` is handed to the
        normalized cut (checked before every product of its eigensolvers).
        """
        run = StageRun(self.snapshot(params), cancel=cancel)
        if progress is not None:
            run.within = (stage, progress)
        return self.stage_value(stage, run)

    def stage_seconds(self, stage: str) -> float:
        """Seconds the last computation of ``stage`` took (0 if never computed)."""
        return self._seconds.get(stage, 0.0)

    # -- running ----------------------------------------------------------------------
    def run_iter(
        self,
        params: SegmentParams | None = None,
        reconstruction: bool = True,
        cancel: Callable[[], bool] | None = None,
        progress: Callable[[str, float, int], None] | None = None,
    ) -> Iterator[tuple[str, int, int]]:
        """Run stage by stage for ``params``, yielding ``(stage, index, total)`` after each.

        Stopping the iteration between yields cancels the run; cached stages stay valid.
        ``cancel`` also stops the labels stage's normalized cut from within: it is called
        before every product of its eigensolvers, and True raises :class:`Cancelled`
        (the splits made so far stay cached in the cut tree). ``progress`` is called
        *within* the stages that loop in chunks (harmonics, reconstruction) with
        ``(stage, index, total)``, ``index`` a float between the stage's boundaries: the
        stages done plus the share of this one done (e.g. 2.4 of 8 in the third stage).
        """
        p = self.snapshot(params)
        thesis_only(p)
        with self._lock:
            self._recomputed = (p, [])
        names = self.stages(reconstruction, p)
        n = len(names)
        for i, name in enumerate(names):
            run = StageRun(p, cancel=cancel)
            if progress is not None:

                def within(share: float, name: str = name, i: int = i) -> None:
                    progress(name, i + share, n)

                run.within = (name, within)
            self.stage_value(name, run)
            yield name, i + 1, n

    def run(
        self,
        params: SegmentParams | None = None,
        reconstruction: bool = True,
        progress: Callable[[str, int, int], None] | None = None,
        cancel: Callable[[], bool] | None = None,
    ) -> SegmentationResult:
        """Run every stale stage for ``params`` and return the result.

        Parameters
        ----------
        params : SegmentParams, optional
            The parameters of this run (default: the last run's).
        reconstruction : bool
            Also rebuild Î from the harmonics and compute the error map.
        progress : callable(stage, index, total), optional
            Called after each stage.
        cancel : callable() -> bool, optional
            Checked between stages, and by the normalized cut before every product of
            its eigensolvers; returning True raises :class:`Cancelled`.
        """
        p = self.snapshot(params)
        with self._lock:
            for name, i, n in self.run_iter(p, reconstruction, cancel):
                if progress is not None:
                    progress(name, i, n)
                if cancel is not None and cancel() and i < n:
                    raise Cancelled(f"cancelled after stage {name!r}")
            return self.result(p, reconstruction)

    def prefetch(
        self, params: SegmentParams | None = None, cancel: Callable[[], bool] | None = None
    ) -> Iterator[int]:
        """Precompute, in idle time, what one more segment would need.

        With recursive cuts whose labels are fresh for ``params`` and whose tree stops
        at their number of segments, solves the candidate split of every segment
        (:meth:`ncut.CutTree.prefetch`), yielding after each; a later run with
        ``n_segments`` k + 1 then costs only the split (milliseconds instead of one
        or two eigensolves). Then keeps a touched buffer for the next dense affinity
        (:meth:`MatrixPool.reserve`; yields −1). Does nothing otherwise. Stopping the
        iteration between yields is safe (the lock is taken per step, never held across
        a yield); ``cancel`` (called before every product of an eigensolve, True raises
        :class:`Cancelled`) stops it inside a solve.
        """
        p = self.snapshot(params)
        if p.clustering != "recursive" or not self.is_fresh("labels", p):
            return
        tree = self.cached("cut")
        if isinstance(tree, ncut.CutTree) and len(tree.ncut_values) + 1 <= p.n_segments:
            steps = tree.prefetch(cancel)
            while True:
                with self._lock:
                    if self.cached("cut") is not tree:
                        return  # another run replaced the tree
                    step = next(steps, None)
                if step is None:
                    break
                yield step
        with self._lock:
            W = self.cached("affinity")
            if not (isinstance(W, np.ndarray) and self.matrices.owns(W)):
                return
            # memory for the next affinity (a change of the scale, n or w): touched now
            # rather than while the user waits
            self.matrices.reserve(W.shape, W.dtype)
            del W
        yield -1

    def result(
        self, params: SegmentParams | None = None, reconstruction: bool = True
    ) -> SegmentationResult:
        """The result for ``params`` (default: the last run's), assembled from the
        cache (stale stages are computed first)."""
        p = self.snapshot(params)
        thesis_only(p)
        with self._lock:
            block, labels, ncut_values, limits, record = self.get("labels", p)
            names = self.stages(reconstruction, p)
            done = self.recomputed_stages(p)
            return self.assemble_result(
                block,
                labels,
                ncut_values,
                reconstruction,
                timings={s: self._seconds.get(s, 0.0) for s in names},
                recomputed=[s for s in names if s in done],
                cut_limits=limits,
                params=p,
                superpixels=record,
            )

    def assemble_result(
        self,
        block: np.ndarray,
        labels: np.ndarray,
        ncut_values: list[float],
        reconstruction: bool,
        timings: dict[str, float],
        recomputed: list[str],
        cut_limits: dict[str, int] | None = None,
        params: SegmentParams | None = None,
        superpixels: dict[str, Any] | None = None,
        maps: bool = True,
        *,
        method: str | None = None,
        method_record: dict[str, Any] | None = None,
        materials: Any = None,
        on_blocks: bool | None = None,
    ) -> SegmentationResult:
        """A :class:`SegmentationResult` of the cached stages for ``params`` and the
        given labels: the one place a result is put together (the thesis runs, every
        method's run in a :class:`~napari_polarseg.engine.Scene`, the classifiers).

        ``block`` (R, C) and ``labels`` (H, W) are the run's. ``maps``: with the thesis's
        harmonic coefficients and PCA features; ``reconstruction``: with the
        reconstruction and its error map. ``method`` (default ``params.method``),
        ``method_record`` and ``materials`` (a classifier's classes) name what made the
        labels; ``on_blocks`` (default: ``maps`` or ``reconstruction``) says the run
        worked on the block grid.
        """
        run = StageRun(self.snapshot(params))
        on_blocks = (maps or reconstruction) if on_blocks is None else on_blocks
        with self._lock:
            pol = self.stage_value("polarisation", run)
            nrm = self.stage_value("normals", run)
            coef = pca = None
            if maps:
                coef, pca = self.stage_value("harmonics", run), self.stage_value("pca", run)
            rec = self.stage_value("reconstruction", run) if reconstruction else None
        return SegmentationResult(
            params=run.params,
            intensity=pol.intensity,
            dop=pol.dop,
            phase=pol.phase,
            residual=pol.residual,
            zenith=nrm.zenith,
            azimuth=nrm.azimuth,
            clamped=nrm.clamped,
            coefficients=coef,
            features=None if pca is None else pca.features,
            explained_variance_ratio=None if pca is None else pca.explained_variance_ratio,
            block_labels=block,
            labels=labels,
            ncut_values=ncut_values,
            timings=timings,
            recomputed=recomputed,
            reconstruction=None if rec is None else rec.intensity,
            reconstruction_error=None if rec is None else rec.error,
            valid=~pol.invalid,
            mask_counts=self.mask.counts(),
            duplicate_angle_frames=polarimage.duplicate_angle_frames(self.angles),
            cut_limits=dict(cut_limits or {}),
            superpixels=dict(superpixels or {}),
            method=run.params.method if method is None else method,
            method_record=dict(method_record or {}),
            materials=materials,
            on_blocks=on_blocks,
        )


def thesis_only(params: SegmentParams) -> None:
    """Raise :class:`PolarsegError` unless ``params`` name a method that cuts the block
    graph (declares ``block_maps``: the thesis method): a :class:`Pipeline` runs the
    thesis block graph; every method (the superpixel default too) runs through
    :class:`napari_polarseg.engine.Scene`."""
    if not computes_block_maps(params.method):
        raise PolarsegError(
            f"a Pipeline cuts the thesis block graph; method {params.method!r} runs "
            "through napari_polarseg.engine.Scene(stack, angles).segment(params)"
        )


def intensity_baseline(
    intensity: np.ndarray,
    window: int,
    n_segments: int,
    scale: float = 1.0,
    min_segment_blocks: int = 1,
) -> np.ndarray:
    """Intensity-only baseline: the same Mahalanobis affinity and recursive normalized
    cuts on block mean and standard deviation of Î (no polarisation at all).

    Returns pixel labels (H, W) covering the whole image.
    """
    nby, nbx = harmonics.block_grid(intensity.shape, window)
    blocks = harmonics.blockify(intensity, window)  # (nby, nbx, w*w)
    x = np.stack([blocks.mean(-1), blocks.std(-1)], axis=-1).reshape(-1, 2)
    if not np.all(x.var(axis=0) > 0):
        x = x + 1e-12 * np.arange(x.shape[0])[:, None]
    W = affinity.affinity_matrix(x, scale)
    block = ncut.recursive_ncut(W, n_segments, min_size=min_segment_blocks).reshape(nby, nbx)
    return harmonics.upsample_block_labels(block, intensity.shape, window)
