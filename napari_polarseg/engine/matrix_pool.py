"""Memory kept between pipeline runs for the n × n matrices of the dense affinity.

:class:`MatrixPool` hands out reusable buffers; :class:`DenseDistances` keeps the squared
Mahalanobis distances (thesis eq. 4.27) and their median with the key of the features
they were computed from.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np


class MatrixPool:
    """Memory for the n × n matrices a pipeline recomputes (distances, affinity).

    :meth:`take` hands out a view of a kept flat buffer when no array made from that
    buffer is alive any more (its reference count shows only the pool), else a new one;
    so an array a caller still holds (e.g. an affinity from ``get("affinity")``) is never
    overwritten. Reusing memory this way spares a rerun the fresh pages of each new
    matrix (90 MB at 4,752 blocks in float32): on the reference VM those cost 0.02–0.2 s
    each, depending on where the kernel found them. At most ``keep`` buffers are kept.
    """

    def __init__(self, keep: int = 3) -> None:
        self.keep = keep
        self._buffers: list[np.ndarray] = []
        # the references a buffer with no view has when _free looks at it (the list, the
        # loop variable, the arguments), counted on a probe taken the same way; every
        # live view or reshape of a buffer adds one (its ``base``)
        probe = [np.empty(0)]
        self._unused = min(self._references(b) for b in probe)

    @staticmethod
    def _references(buffer: np.ndarray) -> int:
        return sys.getrefcount(buffer)

    def _free(self, buffer: np.ndarray) -> bool:
        return self._references(buffer) <= self._unused + 1  # + _free's own argument

    def reserve(self, shape: tuple[int, ...], dtype: np.dtype | type) -> None:
        """Make sure a free buffer of ``shape`` and ``dtype`` is kept, its pages touched
        (idle-time preparation: the next :meth:`take` of that size then writes into
        memory the process already has)."""
        dtype = np.dtype(dtype)
        size = int(np.prod(shape))
        if any(b.dtype == dtype and b.size == size and self._free(b) for b in self._buffers):
            return
        spare = self.take(shape, dtype)
        if self.owns(spare):
            spare.fill(0)  # touch every page now

    def owns(self, array: np.ndarray) -> bool:
        """True if ``array`` was handed out from a buffer the pool keeps."""
        return any(array.base is b for b in self._buffers)

    def take(self, shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
        """An uninitialised array of ``shape`` and ``dtype``."""
        dtype = np.dtype(dtype)
        size = int(np.prod(shape))
        for buffer in self._buffers:
            if buffer.dtype == dtype and buffer.size == size and self._free(buffer):
                return buffer.reshape(shape)
        # make room: forget free buffers (of other sizes first) beyond the limit
        free = [b for b in self._buffers if self._free(b)]
        free.sort(key=lambda b: b.size == size)
        while len(self._buffers) >= self.keep and free:
            drop = free.pop(0)
            self._buffers = [b for b in self._buffers if b is not drop]
        buffer = np.empty(size, dtype=dtype)
        if len(self._buffers) < self.keep:
            self._buffers.append(buffer)
        return buffer.reshape(shape)


@dataclass
class DenseDistances:
    """The dense squared distances D of one set of block features (the ``pca`` stage's
    cache key), and their off-diagonal median once computed (None before)."""

    key: tuple
    matrix: np.ndarray
    median: float | None = None
