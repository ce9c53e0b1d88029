"""Full-size arrays in memory, or in a temporary file when they do not fit the run's
memory limit (issue 39).

A run on a large image keeps a few arrays of the image's size: the fit's maps (Î, ρ, φ,
the residual and the invalid pixels, 33 bytes a pixel), the samples' flags, the
superpixels and the labels. Where they fit the work limit
(:func:`full_size_limit`: a share :data:`DISK_SHARE` of it for
:data:`FULL_SIZE_BYTES_PER_PIXEL` a pixel), :func:`empty` and :func:`zeros` give plain
NumPy arrays, as before. Where they do not, the same calls give arrays whose memory is a
shared mapping of a temporary file (:func:`disk_empty`): every caller still sees an
``ndarray`` (slicing, ``out=``, views and pickling work unchanged, and the values are
the same to the bit), but the pages it touches are the file's.

Such a page counts in the process's resident memory while it is mapped, so touched
pages are given back: a background thread calls ``madvise(MADV_DONTNEED)`` on every
live mapping whenever the resident memory grew by :data:`TRIM_BYTES` over its lowest
since the last release (it looks every :data:`TRIM_SECONDS`, up to
:data:`IDLE_SECONDS` apart while it does not grow; the pages stay in the file and the
page cache, and the next access maps them again), and :func:`release` does it at once.
The resident part of a disk array is then what was touched in the last few
milliseconds, not the whole image, so the peak follows the tiles and chunks being
worked on.

The file is opened with :func:`tempfile.TemporaryFile` in :func:`scratch_directory`
(``$POLARSEG_SCRATCH_DIR``, else the system's temporary directory): it has no name (or
loses it at once) and its space is given back when the last view of the array is
gone, whether the run ends, fails or is cancelled, or the process is killed. Its
blocks are reserved when it is made (``posix_fallocate``), so a full disk is a
:class:`~.errors.PolarsegError` then, never a crash while a page is written.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import mmap
import os
import tempfile
import threading
import time
import weakref
from collections.abc import Iterator
from contextvars import ContextVar
from typing import Any

import numpy as np

from .errors import PolarsegError
from .tiles import row_bands

#: Bytes a pixel of the full-size arrays a run keeps beside its stack: the pipeline's
#: kept maps (:data:`~.limits.KEPT_MAPS` = 6 float64; not imported: the limits module
#: reads the engine's features, which read this one) and the superpixels and labels.
FULL_SIZE_BYTES_PER_PIXEL = 8 * 6 + 24
#: The full-size arrays go to disk when theirs exceed this share of the work limit.
DISK_SHARE = 0.5
#: Seconds between two looks at the resident memory by the release thread (a pass over
#: a 100 MP map in memory takes ~0.07 s: at 0.05 s every map of a pass was resident).
TRIM_SECONDS = 0.005
#: Longest pause (seconds) of the release thread while the resident memory does not grow.
IDLE_SECONDS = 0.02
#: Growth of the resident memory (bytes) over its lowest since the last release that
#: makes the release thread release the disk arrays' pages again (idle, it only reads
#: ``/proc/self/statm``).
TRIM_BYTES = 16 * 2**20
#: Environment variable naming the directory of the temporary files.
SCRATCH_ENV = "POLARSEG_SCRATCH_DIR"
#: Whether a thread releases the disk arrays' resident pages (module docstring). Off,
#: the pages stay mapped until the kernel reclaims them under memory pressure: what a
#: memory limit enforced by the kernel (a cgroup) sees either way.
RELEASE_PAGES = True
#: Rows a band of :func:`copy_of` (bounds its temporaries).
BAND_ROWS = 512

#: The work limit (bytes) the full-size arrays made in this context are placed by
#: (None: always in memory).
_limit: ContextVar[int | None] = ContextVar("polarseg_full_size_limit", default=None)
_mapped: weakref.WeakSet[mmap.mmap] = weakref.WeakSet()
_state = threading.Lock()
_trimming = [False]


@contextlib.contextmanager
def full_size_limit(limit: int | None) -> Iterator[None]:
    """Place the full-size arrays made inside the block (in this thread or task) by the
    work limit ``limit`` (bytes; None: in memory): :func:`pixels_on_disk`."""
    token = _limit.set(None if limit is None else int(limit))
    try:
        yield
    finally:
        _limit.reset(token)


def on_disk_at(pixels: int, limit: int | None) -> bool:
    """True when a run's full-size arrays on an image of ``pixels`` pixels
    (:data:`FULL_SIZE_BYTES_PER_PIXEL` each) exceed :data:`DISK_SHARE` of the work limit
    ``limit`` (bytes; None: never)."""
    return limit is not None and pixels * FULL_SIZE_BYTES_PER_PIXEL > DISK_SHARE * limit


def pixels_on_disk(pixels: int) -> bool:
    """:func:`on_disk_at` the current work limit (:func:`full_size_limit`; none set:
    False)."""
    return on_disk_at(pixels, _limit.get())


def image_pixels(shape: tuple[int, ...]) -> int:
    """Pixels of the image an array of ``shape`` covers: its length when flat, else the
    product of its last two axes ((H, W) or (N, H, W))."""
    dims = tuple(int(s) for s in shape)
    return dims[0] if len(dims) == 1 else math.prod(dims[-2:])


def scratch_directory() -> str:
    """Directory of the temporary files: ``$POLARSEG_SCRATCH_DIR``, else the system's."""
    return os.environ.get(SCRATCH_ENV) or tempfile.gettempdir()


def empty(shape: tuple[int, ...], dtype: np.typing.DTypeLike = np.float64) -> np.ndarray:
    """An uninitialised array of ``shape``: in memory (``np.empty``), or on disk
    (:func:`disk_empty`) when :func:`pixels_on_disk` says so for its image."""
    if pixels_on_disk(image_pixels(shape)):
        return disk_empty(shape, dtype)
    return np.empty(shape, dtype=dtype)


def zeros(shape: tuple[int, ...], dtype: np.typing.DTypeLike = np.float64) -> np.ndarray:
    """:func:`empty` filled with zeros (a new file reads as zeros)."""
    if pixels_on_disk(image_pixels(shape)):
        return disk_empty(shape, dtype)
    return np.zeros(shape, dtype=dtype)


def disk_empty(
    shape: tuple[int, ...], dtype: np.typing.DTypeLike = np.float64, directory: str | None = None
) -> np.ndarray:
    """An array of ``shape`` and ``dtype`` (zeros) mapped from a new temporary file in
    ``directory`` (default :func:`scratch_directory`), its resident pages released
    every :data:`TRIM_SECONDS` (module docstring).

    Raises :class:`~.errors.PolarsegError` when the file cannot be made or its blocks
    reserved (a full disk)."""
    dtype = np.dtype(dtype)
    count = math.prod(int(s) for s in shape)
    size = max(count * dtype.itemsize, 1)
    where = directory or scratch_directory()
    try:
        with tempfile.TemporaryFile(dir=where) as f:
            if hasattr(os, "posix_fallocate"):
                os.posix_fallocate(f.fileno(), 0, size)
            else:  # pragma: no cover - other systems: a sparse file
                f.truncate(size)
            mapping = mmap.mmap(f.fileno(), size)  # the mapping keeps the file
    except OSError as exc:
        raise PolarsegError(
            f"no room for a {size / 2**30:.2f} GiB temporary array in {where} ({exc}); "
            f"free some disk space, set {SCRATCH_ENV} to another directory or give the "
            "run more memory (--max-memory)"
        ) from None
    _watch(mapping)
    return np.frombuffer(mapping, dtype=dtype, count=count).reshape(shape)


def mapping_of(array: np.ndarray) -> mmap.mmap | None:
    """The file mapping under ``array`` (a view of a :func:`disk_empty` array), or None."""
    base = array
    while base is not None:
        if isinstance(base, mmap.mmap):
            return base
        if isinstance(base, memoryview):
            base = base.obj
        else:
            base = getattr(base, "base", None)
    return None


def is_on_disk(array: np.ndarray) -> bool:
    """True when ``array`` lives in a temporary file (:func:`disk_empty`)."""
    return mapping_of(array) is not None


def release(*arrays: np.ndarray | None) -> None:
    """Give back the resident pages of the disk arrays among ``arrays`` now (their
    values stay); arrays in memory are left alone (all of them while
    :data:`RELEASE_PAGES` is False)."""
    if not RELEASE_PAGES:
        return
    for array in arrays:
        mapping = None if array is None else mapping_of(array)
        if mapping is not None:
            _release(mapping)


def copy_of(array: np.ndarray, dtype: np.typing.DTypeLike | None = None) -> np.ndarray:
    """``array.astype(dtype)`` as a new array placed by :func:`empty`, copied
    :data:`BAND_ROWS` rows at a time (no full-size temporary)."""
    out = empty(array.shape, array.dtype if dtype is None else dtype)
    if out.ndim < 2:
        out[...] = array
        return out
    for band in row_bands(out.shape[0], BAND_ROWS):
        out[band] = array[band]
        release(out)  # a band's pages at a time, faster than the background release
    return out


def kept(value: Any, shape: tuple[int, int]) -> Any:
    """``value`` with its full-size arrays in temporary files when the run's full-size
    arrays do not fit (:func:`pixels_on_disk`): a dataclass (e.g. the normals' θ and
    clamped pixels) whose (…, H, W) arrays of ``shape`` held in memory are replaced by
    copies on disk (:func:`copy_of`, the same values); anything else as it is."""
    if not (dataclasses.is_dataclass(value) and not isinstance(value, type)):
        return value
    if not pixels_on_disk(int(shape[0]) * int(shape[1])):
        return value
    moved = {
        f.name: copy_of(a)
        for f in dataclasses.fields(value)
        if isinstance(a := getattr(value, f.name), np.ndarray)
        and a.ndim >= 2
        and tuple(a.shape[-2:]) == tuple(shape)
        and not is_on_disk(a)
    }
    return dataclasses.replace(value, **moved) if moved else value


def _release(mapping: mmap.mmap) -> None:
    if hasattr(mmap, "MADV_DONTNEED"):
        with contextlib.suppress(ValueError, OSError):  # closed, or not supported
            mapping.madvise(mmap.MADV_DONTNEED)


def _watch(mapping: mmap.mmap) -> None:
    """Release ``mapping``'s pages every :data:`TRIM_SECONDS` while it lives (one
    daemon thread for every mapping, ending when none is left; none while
    :data:`RELEASE_PAGES` is False)."""
    with _state:
        _mapped.add(mapping)
        if RELEASE_PAGES and not _trimming[0]:
            _trimming[0] = True
            threading.Thread(target=_trim_loop, name="polarseg-trim", daemon=True).start()


def _release_live(release_them: bool) -> bool:
    """Release every live mapping's pages (when ``release_them``); False, with the
    release thread marked as ended, when none is left. (No mapping is held after it
    returns: the last view's end still gives its file back.)"""
    with _state:
        live = list(_mapped)
        if not live:
            _trimming[0] = False
            return False
    if release_them:
        for mapping in live:
            _release(mapping)
    return True


def resident_bytes(statm: int | None = None) -> int | None:
    """This process's resident memory, bytes, read from ``/proc/self/statm`` (or the
    open file descriptor ``statm`` of it); None where it cannot be read."""
    try:
        if statm is not None:
            return int(os.pread(statm, 128, 0).split()[1]) * mmap.PAGESIZE
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * mmap.PAGESIZE
    except (OSError, ValueError, IndexError):  # pragma: no cover - not Linux
        return None


def _trim_loop() -> None:
    """Release the live mappings' pages whenever the resident memory grew by
    :data:`TRIM_BYTES` over its lowest since the last release (where it cannot be
    read: every time), looking every :data:`TRIM_SECONDS`, or up to
    :data:`IDLE_SECONDS` apart while it does not grow (the pause doubles each time);
    end when no mapping is left."""
    try:
        statm: int | None = os.open("/proc/self/statm", os.O_RDONLY)
    except OSError:  # pragma: no cover - not Linux
        statm = None
    last, pause = 0, TRIM_SECONDS
    try:
        while True:
            time.sleep(pause)
            now = resident_bytes(statm)
            grown = now is None or now >= last + TRIM_BYTES
            if not _release_live(grown):
                return
            if grown:
                last, pause = resident_bytes(statm) or 0, TRIM_SECONDS
            else:  # from its lowest since: freed memory is no room for pages
                last, pause = min(last, now), min(2 * pause, IDLE_SECONDS)
    finally:
        if statm is not None:
            os.close(statm)
