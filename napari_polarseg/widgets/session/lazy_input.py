"""A lazy (Dask) stack layer read into memory for a run, no Qt.

The plugin's reader opens a big stack lazily (:func:`napari_polarseg.io.read_stack`,
``lazy="auto"``): the layer's data is a Dask array that napari reads tile by tile as it
draws. The engine segments a stack in memory, so the Segment dock's worker reads the
whole stack once, when a run (or the scribbles' pixel features) first needs it, after
checking that it fits the memory limit (:func:`~napari_polarseg.engine.limits.memory_limit`:
``$POLARSEG_MAX_BYTES``, else 8 GiB); the status line says so while it reads
(:func:`loading_stage`). :class:`~napari_polarseg.widgets.session.store.PipelineStore`
keeps the array read beside the layer's pipeline, so a new mask does not read it again.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

import numpy as np

from ...engine.errors import PolarsegError
from ...engine.limits import ENV_VAR, format_bytes, memory_limit
from ...io import is_lazy

#: Bytes a stack value needs once read: its own, and the float64 copy the fit makes.
FLOAT_COPY_BYTES = 8


def stack_text(data: Any) -> str:
    """``"4 x 8192 x 8192 uint16, 512.0 MiB"``: a stack's shape, dtype and size."""
    shape = " x ".join(str(int(n)) for n in data.shape)
    size = float(np.prod(data.shape)) * np.dtype(data.dtype).itemsize
    return f"{shape} {np.dtype(data.dtype).name}, {format_bytes(size)}"


def load_bytes(data: Any) -> float:
    """Memory a run needs to hold the stack ``data`` read whole, with its float64 copy."""
    return float(np.prod(data.shape)) * (np.dtype(data.dtype).itemsize + FLOAT_COPY_BYTES)


def check_load(data: Any, limit: int | None = None) -> None:
    """Raise PolarsegError, naming the stack and the limit, when reading ``data`` whole
    for a run needs more than the memory limit."""
    cap = memory_limit(limit)
    needed = load_bytes(data)
    if needed > cap:
        raise PolarsegError(
            f"the stack ({stack_text(data)}) is shown from disk; a run reads it into memory "
            f"and would need {format_bytes(needed)}, more than the limit of "
            f"{format_bytes(cap)} (set {ENV_VAR}, e.g. {ENV_VAR}=32G, before starting "
            "napari to allow more, or segment it with `polarseg segment`)"
        )


def read_whole(data: Any) -> Any:
    """``data`` in memory (NumPy): a lazy stack read once, after :func:`check_load`; any
    other array as it is."""
    if not is_lazy(data):
        return data
    check_load(data)
    try:
        return np.asarray(data.compute())
    except PolarsegError:
        raise
    except Exception as exc:  # a file removed or damaged since it was opened
        raise PolarsegError(f"cannot read the stack from disk ({exc})") from exc


def loading_stage(data: Any) -> str:
    """The status of the stage that reads a lazy stack into memory."""
    return f"reading the stack ({stack_text(data)}) from disk into memory"


def reading_stage(store: Any, key: str, data: Any, total: int) -> Generator[Any, None, None]:
    """A job's first stage when ``store`` (a
    :class:`~napari_polarseg.widgets.session.store.PipelineStore`) has yet to read the
    lazy stack ``data`` of ``key``: refused at once beyond the limit (:func:`check_load`),
    else the status of the reading (:func:`loading_stage`); nothing otherwise."""
    if store.needs_reading(key, data):
        check_load(data)
        yield loading_stage(data), 0, total
