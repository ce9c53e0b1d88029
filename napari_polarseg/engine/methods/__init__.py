"""Segmentation methods as peers on one shared polarisation image.

:class:`Scene` holds an angle stack, its polarisation image and feature cache;
``Scene.segment(params)`` runs the method ``params.method`` names (or the one that
takes the given inputs, e.g. scribbles). Every method follows :class:`Segmenter`;
:func:`register_method` adds one (the CLI's ``--method`` and the plugin's menu offer
it at once).
"""

from .base import MethodOutput, MethodRun, Segmenter
from .registry import (
    get_method,
    method_names,
    register_built_in,
    register_method,
    unregister_method,
)
from .scene import Scene, segment

register_built_in()

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
