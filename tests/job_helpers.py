"""Helpers the tests of the plugin's jobs share (imported from this folder)."""

from __future__ import annotations

from collections.abc import Generator
from typing import Any


def drive(gen: Generator[Any, None, Any]) -> tuple[list[Any], Any]:
    """What a job yields, and what it returns (as the worker would run it)."""
    items = []
    while True:
        try:
            items.append(next(gen))
        except StopIteration as stop:
            return items, stop.value
