"""The registered segmentation methods.

Adding a method is one module with a class that follows
:class:`~.base.Segmenter` and one line in :data:`BUILT_IN` (or, from outside the
package, one call of :func:`register_method`): the CLI's ``--method``, the plugin's method
menu and ``params.json`` then offer it.
"""

from __future__ import annotations

import importlib

from ..errors import PolarsegError
from ..params import FINDS_K_METHODS, METHOD_CHOICES
from .base import Segmenter

#: The methods that come with the package: module (in this package) and class.
BUILT_IN: tuple[tuple[str, str], ...] = (
    ("superpixel_clustering", "SuperpixelClustering"),
    ("thesis", "ThesisBlocks"),
    ("pixel_classification", "PixelClassification"),
    ("valid_superpixels", "ValidSuperpixels"),
    ("surface_superpixels", "SurfaceSuperpixels"),
    ("superpixel_consensus", "SuperpixelConsensus"),
)

_METHODS: dict[str, Segmenter] = {}


def register_method(method: Segmenter) -> Segmenter:
    """Register ``method`` under its ``name`` (a later registration replaces it) and
    return it; a method that needs no inputs besides the image becomes a choice of
    ``SegmentParams.method`` (``--method``, the plugin's menu)."""
    for attr in ("name", "title", "reads", "inputs", "stages", "segment"):
        if not hasattr(method, attr):
            raise PolarsegError(f"a segmentation method needs {attr!r}: {method!r}")
    _METHODS[method.name] = method
    if not method.inputs:  # a method chosen by its inputs (scribbles) is no menu choice
        METHOD_CHOICES[method.name] = method.title
    if getattr(method, "finds_k", False):  # n_segments = 0: the method finds k
        FINDS_K_METHODS.add(method.name)
    return method


def unregister_method(name: str) -> None:
    """Forget the method registered as ``name`` (nothing if there is none)."""
    _METHODS.pop(name, None)
    METHOD_CHOICES.pop(name, None)
    FINDS_K_METHODS.discard(name)


def get_method(name: str) -> Segmenter:
    """The method registered as ``name``; PolarsegError naming the known ones else."""
    method = _METHODS.get(name)
    if method is None:
        known = ", ".join(_METHODS)
        raise PolarsegError(f"unknown segmentation method {name!r}; known: {known}")
    return method


def method_names() -> tuple[str, ...]:
    """Names of the registered methods, in registration order."""
    return tuple(_METHODS)


def unsupervised_names() -> tuple[str, ...]:
    """The methods that need no input besides the image (the plugin's method menu)."""
    return tuple(name for name, m in _METHODS.items() if not m.inputs)


def register_built_in() -> None:
    """Register the methods of :data:`BUILT_IN`."""
    for module, cls in BUILT_IN:
        register_method(getattr(importlib.import_module(f"{__package__}.{module}"), cls)())
