"""How a parameter is described: :class:`ParamSpec`, the dataclass field that carries it
(:func:`param_field`), the table of a parameter dataclass (:func:`specs_of`) and the value
checks its ``validate`` uses.

:class:`~napari_polarseg.engine.params.SegmentParams` (what every method shares) and each
method's own parameter dataclass (``params_class`` of a method, e.g.
:class:`~napari_polarseg.engine.methods.thesis.ThesisParams`) are written with it: the CLI
flags, the plugin's controls, ``params.json`` and the sweep are all made from these
tables.
"""

from __future__ import annotations

import math
import typing
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from functools import cache
from typing import Any

import numpy as np

from .errors import PolarsegError


@dataclass(frozen=True)
class ParamSpec:
    """How one parameter is described, asked for and shown.

    The one description of each parameter: the CLI flags (``--help``), the plugin's
    controls (label, range, tooltip) and the class docstring are all made from it.

    Attributes
    ----------
    help : str
        What the parameter is, with its unit (one or more sentences).
    flag : str
        The CLI option, e.g. ``"--window"``.
    metavar : str or None
        The CLI metavar of a numeric option.
    label : str or None
        The plugin control's label; None: no control (the preset sets it).
    minimum, maximum : float or None
        The control's range (the engine's own checks are the dataclass's ``validate``).
    step : float or None
        The float control's step.
    decimals : int or None
        Decimals a float control shows.
    choices : tuple of str or None
        The values a menu offers.
    choice_names : dict or None
        Text shown in the menu for some of the choices.
    optional : bool
        The value may be None (the CLI takes ``none``).
    registry : Mapping or None
        A live mapping name → menu text whose names are the choices (the registered
        segmentation methods); None: :attr:`choices`.
    words : dict or None
        Words the CLI takes for a number (``auto`` for 0 segments: find the number).
    effect : str or None
        What the control does to the result, in plain words: the first line of the
        plugin's tooltip (None: the plugin's own table, or only :attr:`help`).
    """

    help: str
    flag: str
    metavar: str | None = None
    label: str | None = None
    minimum: float | None = None
    maximum: float | None = None
    step: float | None = None
    decimals: int | None = None
    choices: tuple[str, ...] | None = None
    choice_names: dict[str, str] | None = None
    optional: bool = False
    registry: Mapping[str, str] | None = None
    words: dict[str, int] | None = None
    effect: str | None = None

    def options(self) -> tuple[str, ...] | None:
        """The values a menu offers now: :attr:`choices`, or the names in
        :attr:`registry` (a live mapping name → text, e.g. the registered methods)."""
        if self.registry is not None:
            return tuple(self.registry)
        return self.choices

    def menu(self) -> list[tuple[str, str]]:
        """(text, value) pairs of a menu parameter, in the order of :meth:`options`."""
        names = {**(self.choice_names or {}), **(self.registry or {})}
        return [(names.get(c, c), c) for c in self.options() or ()]


def param_field(default: Any, **spec: Any) -> Any:
    """A dataclass field whose metadata holds its :class:`ParamSpec` (keywords: the
    spec's attributes)."""
    return field(default=default, metadata={"spec": ParamSpec(**spec)})


@cache
def specs_of(cls: type) -> dict[str, ParamSpec]:
    """The :class:`ParamSpec` of every field of the dataclass ``cls`` that has one, by
    field name, in field order (kept: do not change the returned table)."""
    if not is_dataclass(cls):
        raise PolarsegError(f"parameters must be a dataclass, got {cls!r}")
    return {f.name: f.metadata["spec"] for f in fields(cls) if "spec" in f.metadata}


@cache
def defaults_of(cls: type) -> dict[str, Any]:
    """The default of every field of the dataclass ``cls`` that has a plain one."""
    return {f.name: f.default for f in fields(cls) if f.default is not MISSING}


@cache
def types_of(cls: type) -> dict[str, Any]:
    """The resolved type of every field of the dataclass ``cls``."""
    return typing.get_type_hints(cls)


def is_int(v: Any) -> bool:
    """Whether ``v`` is an integer (not a bool)."""
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def is_number(v: Any) -> bool:
    """Whether ``v`` is a finite real number (not a bool)."""
    return (
        isinstance(v, (int, float, np.integer, np.floating))
        and not isinstance(v, (bool, np.bool_))
        and math.isfinite(float(v))
    )


def check_choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    """Raise :class:`PolarsegError` unless ``value`` is one of ``choices``."""
    if not isinstance(value, str) or value not in choices:
        raise PolarsegError(f"{name} must be one of {', '.join(choices)}; got {value!r}")


def attribute_docs(cls: type, default_word: str = "default") -> str:
    """The numpydoc *Attributes* section of the parameter dataclass ``cls``, made from
    its specs (each line ends with the flag and ``default_word: <default>``)."""
    lines = ["", "    Attributes", "    ----------"]
    for f in fields(cls):
        spec = specs_of(cls).get(f.name)
        if spec is None:
            continue
        kind = (
            "{" + ", ".join(f'"{c}"' for c in spec.choices) + "}"
            if spec.choices
            else (f.type if isinstance(f.type, str) else f.type.__name__)
        )
        lines.append(f"    {f.name} : {kind}")
        lines.append(f"        {spec.help} (``{spec.flag}``; {default_word}: {f.default!r}).")
    return "\n".join(lines) + "\n"
