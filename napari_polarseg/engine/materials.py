"""Named materials: the value and the name of each label of a classifier's result.

A scribble classifier's label k (0..K−1, the index into its classes) stands for the
material the user painted with the scribble value ``values[k]`` (1, 2, …) and called
``names[k]``. :class:`Materials` carries both beside a
:class:`~napari_polarseg.engine.SegmentationResult`, so every output numbers and names a
class as the strokes did: the viewer's segments, ``labels.tif``, ``segments.csv`` and the
overview's legend. A material without a name is called ``"material <value>"``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import PolarsegError

#: Longest material name kept (longer ones are cut).
MAX_NAME_LENGTH = 64


def default_name(value: int) -> str:
    """The name of a material nobody named: ``"material <value>"``."""
    return f"material {int(value)}"


def clean_name(name: Any, value: int) -> str:
    """``name`` on one line, without commas or surrounding spaces, at most
    :data:`MAX_NAME_LENGTH` characters; the default name when nothing is left."""
    text = " ".join(str(name if name is not None else "").replace(",", " ").split())
    return text[:MAX_NAME_LENGTH] or default_name(value)


@dataclass(frozen=True)
class Materials:
    """The scribble value and the name of every class of a classifier, in label order.

    Attributes
    ----------
    values : tuple of int
        ``values[k]`` is the scribble value (≥ 1, ascending) of label k.
    names : tuple of str
        ``names[k]`` is its name (:func:`clean_name`).
    """

    values: tuple[int, ...]
    names: tuple[str, ...]

    def __post_init__(self) -> None:
        values = tuple(int(v) for v in self.values)
        if len(values) != len(self.names):
            raise PolarsegError(f"{len(values)} material values but {len(self.names)} names")
        if any(v < 1 for v in values) or list(values) != sorted(set(values)):
            raise PolarsegError(f"material values must be distinct, ascending and >= 1: {values}")
        object.__setattr__(self, "values", values)
        names = tuple(clean_name(n, v) for n, v in zip(self.names, values, strict=True))
        object.__setattr__(self, "names", names)

    @classmethod
    def of(
        cls, values: Iterable[int], names: Mapping[int, str] | Iterable[str] | None = None
    ) -> Materials:
        """The materials of the scribble ``values``, named by ``names`` (value → name,
        or one name per value; missing ones get :func:`default_name`)."""
        values = tuple(int(v) for v in values)
        if names is None:
            names = {}
        if isinstance(names, Mapping):
            given = {int(k): v for k, v in names.items()}
            listed = [given.get(v, "") for v in values]
        else:
            listed = list(names)
        return cls(values, tuple(listed))

    def renamed(self, names: Mapping[int, str]) -> Materials:
        """These materials with the names of ``names`` (value → name) where it has one."""
        given = {int(k): v for k, v in names.items()}
        pairs = zip(self.values, self.names, strict=True)
        return Materials(self.values, tuple(given.get(v, n) for v, n in pairs))

    def label_values(self, labels: np.ndarray) -> np.ndarray:
        """Labels 0..K−1 as the materials' scribble values (H × W, int64)."""
        return np.asarray(self.values, dtype=np.int64)[np.asarray(labels)]

    def name_of(self, value: int) -> str:
        """The name of the material of scribble value ``value``."""
        return dict(zip(self.values, self.names, strict=True)).get(int(value), default_name(value))

    def to_dict(self) -> dict[str, str]:
        """JSON-ready ``{"<value>": name}``."""
        return {str(v): n for v, n in zip(self.values, self.names, strict=True)}


def display_values(n_labels: int, materials: Materials | None) -> np.ndarray:
    """The value each label 0..n−1 is shown as in the viewer (and coloured by): the
    scribble value of a classifier's class, else k + 1 (napari's label 0 is no label)."""
    if materials is not None:
        return np.asarray(materials.values, dtype=np.int64)
    return np.arange(1, n_labels + 1, dtype=np.int64)


def file_values(n_labels: int, materials: Materials | None) -> np.ndarray:
    """The value each label 0..n−1 has in ``labels.tif`` and ``segments.csv``: the
    scribble value of a classifier's class, else k (0 = first segment)."""
    if materials is not None:
        return np.asarray(materials.values, dtype=np.int64)
    return np.arange(n_labels, dtype=np.int64)
