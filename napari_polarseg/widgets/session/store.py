"""The pipelines the Segment widget keeps: one per angle-stack layer, no Qt.

:class:`PipelineStore` keeps one :class:`~napari_polarseg.engine.Pipeline` per
angle-stack layer so that a rerun only recomputes the stages a parameter change made
stale; a different mask (another region, an edited one, or none) builds a new one. A
lazy (Dask) stack layer is read into memory by its first pipeline, within the memory
limit (:mod:`.lazy_input`), and the array read is reused by the next.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...engine import Pipeline, Scene, SegmentParams, validity_mask
from ...engine.classifier.pixel_segmentation import PixelSegmenter
from ...engine.classifier.scribble_session import ScribbleSession
from ...engine.methods.pixel_classification import scribble_session
from ...io import is_lazy
from .lazy_input import read_whole


def stack_pipeline(
    data: Any, angles_rad: Any, params: SegmentParams, region: np.ndarray | None = None
) -> Pipeline:
    """A new pipeline of the stack ``data`` as the widgets segment it.

    Its mask is :func:`~napari_polarseg.engine.validity_mask`'s: saturated samples (at
    the integer dtype's maximum) and black ones (at or below 0) are left out and
    counted, and so is every pixel outside ``region`` ((H, W) bool, True = use; None:
    every pixel).
    """
    stack = np.asarray(read_whole(data))  # a lazy stack: read once, within the limit
    mask = validity_mask(stack, saturation="auto", dark_level=0, region=region)
    return Pipeline(stack, np.asarray(angles_rad, dtype=float), params, mask=mask)


@dataclass
class _Entry:
    """A kept pipeline, what it was built from and the scene around it."""

    data: Any
    angles: tuple[float, ...]
    mask_key: str | None
    region: np.ndarray | None
    pipeline: Pipeline
    stack: Any = None  # ``data`` in memory (a lazy stack read whole)
    scene: Scene | None = None

    def matches(
        self, data: Any, angles: tuple[float, ...], mask_key: str | None, region: Any
    ) -> bool:
        if self.data is not data or self.angles != angles or self.mask_key != mask_key:
            return False
        if self.region is None or region is None:
            return self.region is None and region is None
        return self.region.shape == region.shape and bool(np.array_equal(self.region, region))


class PipelineStore:
    """One cached :class:`Pipeline` per angle-stack layer (keyed by the layer's id).

    The pipeline is rebuilt when the layer's data object, the angles or the mask (its
    ``mask_key`` or the content of its ``region``) change; otherwise the same object is
    reused so cached stages survive parameter changes. Around each pipeline it keeps one
    :class:`~napari_polarseg.engine.Scene` (:meth:`scene`), whose feature cache holds the
    pixel classifier's :class:`~napari_polarseg.engine.ScribbleSession` (:meth:`session`),
    so the scribble mode computes the pixel features once per stack and a new stroke only
    retrains and predicts. Safe to call from a worker thread (the slot runs one worker at
    a time; a lock guards the dict).
    """

    def __init__(self) -> None:
        self._entries: dict[str, _Entry] = {}
        self._lock = threading.Lock()

    def get(self, key: str) -> Pipeline | None:
        """The pipeline kept for ``key``, if any."""
        with self._lock:
            entry = self._entries.get(key)
        return None if entry is None else entry.pipeline

    def obtain(
        self,
        key: str,
        data: Any,
        angles_rad: np.ndarray,
        params: SegmentParams,
        region: np.ndarray | None = None,
        mask_key: str | None = None,
    ) -> Pipeline:
        """The pipeline for ``key`` (made with ``params``), built if missing or out of date.

        ``region`` (H, W) bool (True = use the pixel) or None restricts the segmentation;
        a new pipeline gets the mask :func:`~napari_polarseg.engine.validity_mask` builds
        from the stack (saturated samples at the integer dtype's maximum and black ones at
        or below 0 are left out and counted) and the region. ``mask_key`` names where the
        region came from (e.g. the Labels layer's id); a change of either rebuilds.
        """
        angles = tuple(float(a) for a in np.asarray(angles_rad, dtype=float).ravel())
        if region is not None:
            region = np.asarray(region, dtype=bool)
        with self._lock:
            entry = self._entries.get(key)
        if entry is None or not entry.matches(data, angles, mask_key, region):
            # a lazy stack read for the layer's last pipeline is not read again
            held = entry is not None and entry.data is data
            stack = entry.stack if held else np.asarray(read_whole(data))
            pipeline = stack_pipeline(stack, angles, params, region)
            entry = _Entry(data, angles, mask_key, region, pipeline, stack)
            with self._lock:
                self._entries[key] = entry
        return entry.pipeline

    def stack_of(self, key: str) -> Any:
        """The stack in memory that ``key``'s pipeline was built from (a lazy layer's
        data read whole), or None without a pipeline."""
        with self._lock:
            entry = self._entries.get(key)
        return None if entry is None else entry.stack

    def needs_reading(self, key: str, data: Any) -> bool:
        """Whether a pipeline of ``key`` has to read ``data`` first: a lazy (Dask) stack
        no pipeline of ``key`` has read yet (:mod:`.lazy_input`)."""
        with self._lock:
            entry = self._entries.get(key)
        return is_lazy(data) and (entry is None or entry.data is not data)

    def scene(self, key: str) -> Scene | None:
        """The :class:`~napari_polarseg.engine.Scene` around ``key``'s pipeline (made at
        the first call, kept while the pipeline is; None without a pipeline): every
        method runs on it, each rerun only when a parameter it reads changes."""
        with self._lock:
            entry = self._entries.get(key)
            if entry is None:
                return None
            if entry.scene is None:
                entry.scene = Scene(pipeline=entry.pipeline)
            return entry.scene

    def session(self, key: str, colour_stack: np.ndarray | None = None) -> ScribbleSession | None:
        """The scribble session of ``key``'s scene (the one the pixel classifier method
        runs on, :func:`~napari_polarseg.engine.methods.pixel_classification.scribble_session`;
        None without a pipeline): it keeps the pixel features between strokes. A rebuilt
        pipeline, or another ``colour_stack`` (the colour stacks of a
        colour-polarisation frame, :class:`PixelSegmenter`), gets a new one."""
        scene = self.scene(key)
        return None if scene is None else scribble_session(scene, colour_stack)

    def segmenter(self, key: str, colour_stack: np.ndarray | None = None) -> PixelSegmenter | None:
        """The pixel segmenter of :meth:`session` (its kept feature stack)."""
        session = self.session(key, colour_stack)
        return None if session is None else session.segmenter

    def discard(self, keep: set[str]) -> None:
        """Forget the pipelines of every key not in ``keep`` (layers that were removed)."""
        with self._lock:
            for key in set(self._entries) - keep:
                del self._entries[key]

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)
