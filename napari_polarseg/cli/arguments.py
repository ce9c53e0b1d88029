"""Argument parsing of ``polarseg``: the parser class, its usage error and the argument types.

The argument types turn one command-line word into a value or raise
:class:`argparse.ArgumentTypeError` (reported as ``polarseg: error: argument ...``).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import io as pio
from ..engine.errors import PolarsegError
from ..engine.physics.colour_mosaic import BAYER_ORDERS
from ..messages import PROG as PROG  # the parser's prog and the head of every message line


class UsageError(PolarsegError):
    """A command-line syntax error (reported like any bad input)."""


class CommandParser(argparse.ArgumentParser):
    """ArgumentParser that raises instead of printing usage and exiting."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(message)


def angles_arg(text: str) -> np.ndarray:
    """Comma-separated polariser angles in degrees, e.g. ``0,45,90,135``."""
    try:
        return pio.parse_angles(text)
    except PolarsegError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers in degrees (e.g. 0,45,90,135), got {text!r}"
        ) from None


def _number_or_word(text: str, words: tuple[str, ...], expected: str) -> float | str:
    """``text`` as one of ``words`` (any case, lower-cased) or a finite number; the error
    says what was ``expected``."""
    word = text.strip().lower()
    if word in words:
        return word
    try:
        return number_arg(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None


def level_arg(text: str) -> float | str:
    """A finite number, or the words ``auto`` / ``none`` (lower case)."""
    return _number_or_word(text, ("none", "auto"), "a number, 'auto' or 'none'")


def dark_level_arg(text: str) -> float | str:
    """A finite number, or the word ``none``."""
    return _number_or_word(text, ("none",), "a number or 'none'")


def number_arg(text: str) -> float:
    """A finite number."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


#: Binary units of ``--max-memory``, in GiB (``G``, ``GB`` and ``GiB`` all mean 2³⁰ bytes,
#: as in ``free -h``); a bare number is GiB.
MEMORY_UNITS = {"k": 2.0**-20, "m": 2.0**-10, "g": 1.0, "t": 2.0**10}


def gib_arg(text: str) -> float:
    """A positive amount of memory in GiB: a number of GiB, or a number with a unit of
    :data:`MEMORY_UNITS` (``20G``, ``512M``, ``1.5GiB``)."""
    number, unit = text.strip(), 1.0
    for suffix in ("ib", "b"):
        if number.lower().endswith(suffix) and number[: -len(suffix)][-1:].lower() in "kmgt":
            number = number[: -len(suffix)]
            break
    if number[-1:].lower() in MEMORY_UNITS:
        number, unit = number[:-1], MEMORY_UNITS[number[-1].lower()]
    try:
        value = number_arg(number) * unit
    except argparse.ArgumentTypeError:
        value = float("nan")
    if not value > 0:
        raise argparse.ArgumentTypeError(
            f"expected a positive amount of memory (GiB, or with a unit: 20G, 512M), got {text!r}"
        )
    return value


def out_folder_arg(text: str) -> str:
    """An output folder: a path that is a folder or does not exist yet (an existing file
    is bad input, exit 2, before anything is computed)."""
    if os.path.exists(text) and not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a file, not a folder")
    return text


def threshold_arg(text: str) -> float | str:
    """A number, or the word ``none`` (no threshold)."""
    if text.strip().lower() == "none":
        return "none"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'none', got {text!r}") from None


def worded_arg(kind: type, words: dict[str, int]) -> Callable[[str], Any]:
    """An argparse type: one of ``words`` (any case) for its number, else ``kind(text)``
    (``--segments auto`` for 0)."""

    def parse(text: str) -> Any:
        word = text.strip().lower()
        if word in words:
            return words[word]
        try:
            return kind(text)
        except ValueError:
            names = " or ".join(repr(w) for w in words)
            raise argparse.ArgumentTypeError(
                f"expected a number or {names}, got {text!r}"
            ) from None

    parse.__name__ = kind.__name__  # argparse names the type in its error messages
    return parse


def bayer_arg(text: str) -> str:
    """A Bayer colour order of :data:`BAYER_ORDERS` (any case)."""
    order = text.strip().upper()
    if order not in BAYER_ORDERS:
        raise argparse.ArgumentTypeError(
            f"a Bayer order is one of {', '.join(BAYER_ORDERS)}, got {text!r}"
        )
    return order


def number_list_arg(kind: type, what: str) -> Callable[[str], tuple]:
    """A parser of comma-separated finite numbers of ``kind`` (``what``: for the error).

    Parameters
    ----------
    kind
        ``int`` or ``float``.
    what
        What the numbers are, e.g. ``"window sizes in pixels"``.

    Returns
    -------
    Callable[[str], tuple]
        The argument type: text -> tuple of at least one number.
    """

    def parse(text: str) -> tuple:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        try:
            values = [kind(p) for p in parts]
        except ValueError:
            values = []
        if not values or not all(np.isfinite(v) for v in values):
            example = "8,10,12" if kind is int else "1.4,1.6"
            raise argparse.ArgumentTypeError(
                f"expected comma-separated {what} (e.g. {example}), got {text!r}"
            )
        return tuple(values)

    return parse
