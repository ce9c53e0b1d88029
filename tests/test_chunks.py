"""Chunked and stoppable work (engine/chunks.py)."""

from __future__ import annotations

import threading

import pytest

from napari_polarseg.engine.chunks import call_stoppable
from napari_polarseg.engine.errors import Cancelled


def test_a_stop_leaves_a_running_call_behind():
    release = threading.Event()
    looks = []

    def work() -> int:
        release.wait(30)  # blocked until the test lets it go
        return 1

    def check() -> None:
        looks.append(1)
        if len(looks) >= 3:
            raise Cancelled("stop")

    with pytest.raises(Cancelled):
        call_stoppable(work, check)
    assert not release.is_set()  # the stop came while the call was still blocked
    release.set()


def test_result_and_error_of_the_call_come_back():
    assert call_stoppable(lambda: 42, lambda: None) == 42

    def fails() -> None:
        raise ValueError("bad input")

    with pytest.raises(ValueError, match="bad input"):
        call_stoppable(fails, lambda: None)
