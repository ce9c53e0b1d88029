"""Segmentation methods as peers on one shared polarisation image.

:class:`Scene` holds an angle stack, its polarisation image and feature cache;
``Scene.segment(params)`` runs the method ``params.method`` names (or the one that
takes the given inputs, e.g. scribbles). Every method follows :class:`Segmenter`;
:func:`register_method` adds one (the CLI's ``--method`` and the plugin's menu offer
it at once). The method modules, and :class:`Scene` with the pipeline it holds, are
imported on first use: the built-in methods register on the first lookup.
"""

from __future__ import annotations

from ..lazy import lazy_attributes
from .base import MethodOutput, MethodRun, Segmenter
from .registry import (
    get_method,
    method_names,
    register_method,
    unregister_method,
)

#: Names imported on first use (PEP 562), and their module in this package.
LAZY: dict[str, str] = {"Scene": ".scene", "segment": ".scene"}

__all__ = [
    "MethodOutput",
    "MethodRun",
    "Scene",
    "Segmenter",
    "get_method",
    "method_names",
    "register_method",
    "segment",
    "unregister_method",
]


__getattr__, __dir__ = lazy_attributes(__name__, LAZY)
