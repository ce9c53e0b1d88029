"""Wall-clock bookkeeping of the steps of a run: :func:`timed`.

The pipeline's stages, the pixel classifier's steps, a time series' steps and the
``segment`` job all record how long each step took in a dict of seconds by step name
(``summary.json``'s ``*_seconds``, ``SegmentationResult.timings``); :func:`timed` is that
bookkeeping, once.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def timed(seconds: dict[str, float], key: str) -> Iterator[None]:
    """Record in ``seconds[key]`` the wall-clock seconds the ``with`` block took.

    Parameters
    ----------
    seconds : dict
        Seconds by step name; ``key`` is set (replaced) when the block ends.
    key : str
        The step's name.

    Notes
    -----
    Nothing is recorded when the block raises: the step did not finish.

    Examples
    --------
    >>> seconds = {}
    >>> with timed(seconds, "read"):
    ...     pass
    >>> list(seconds)
    ['read']
    """
    t0 = time.perf_counter()
    yield
    seconds[key] = time.perf_counter() - t0
