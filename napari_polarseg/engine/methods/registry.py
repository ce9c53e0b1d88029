"""The registered segmentation methods.

Adding a method is one module with a class that follows
:class:`~.base.Segmenter` and one line in :data:`BUILT_IN` (or, from outside the
package, one call of :func:`register_method`): the CLI's ``--method``, the plugin's method
menu and ``params.json`` then offer it, and its own parameters (a dataclass of
:class:`~..param_spec.ParamSpec` fields, its ``params_class``) become flags of its own
group in ``--help``, controls the plugin shows while it is chosen, entries of
``params.json`` and axes of the parameter sweep.

The built-in methods register on the first lookup (:func:`get_method`,
:func:`method_names`, a read of the method choices; :mod:`..registered`), so
``import napari_polarseg.engine`` imports none of them. A method registered from outside
before that comes after them, as if registered later.
"""

from __future__ import annotations

import importlib
from dataclasses import fields, is_dataclass
from typing import Any

from ..errors import PolarsegError
from ..param_spec import specs_of
from ..params import PARAM_SPECS
from ..registered import (
    BLOCK_MAP_METHODS,
    FINDS_K_METHODS,
    METHOD_CHOICES,
    METHOD_PARAMS,
    load_methods,
    set_loader,
)
from .base import Segmenter

#: The methods that come with the package: module (in this package) and class.
BUILT_IN: tuple[tuple[str, str], ...] = (
    ("superpixel_clustering", "SuperpixelClustering"),
    ("thesis", "ThesisBlocks"),
    ("pixel_classification", "PixelClassification"),
    ("valid_superpixels", "ValidSuperpixels"),
    ("surface_superpixels", "SurfaceSuperpixels"),
    ("superpixel_consensus", "SuperpixelConsensus"),
    ("polarisation_borders", "PolarisationBorders"),
)

_METHODS: dict[str, Segmenter] = {}


def register_method(method: Segmenter) -> Segmenter:
    """Register ``method`` under its ``name`` (a later registration replaces it) and
    return it; a method that needs no inputs besides the image becomes a choice of
    ``SegmentParams.method`` (``--method``, the plugin's menu). Its optional
    ``finds_k`` and ``block_maps`` (False when absent) and ``params_class`` (its own
    parameters, :func:`checked_params_class`; None when absent) are read here."""
    for attr in ("name", "title", "reads", "inputs", "stages", "segment"):
        if not hasattr(method, attr):
            raise PolarsegError(f"a segmentation method needs {attr!r}: {method!r}")
    cls = getattr(method, "params_class", None)
    if cls is not None:
        checked_params_class(method.name, cls)
    load_methods()  # the built-in methods first (nothing while they register)
    _METHODS[method.name] = method
    if not method.inputs:  # a method chosen by its inputs (scribbles) is no menu choice
        METHOD_CHOICES[method.name] = method.title
    for names, attr in ((FINDS_K_METHODS, "finds_k"), (BLOCK_MAP_METHODS, "block_maps")):
        if getattr(method, attr, False):  # finds_k: n_segments = 0 lets it find k
            names.add(method.name)
        else:
            names.discard(method.name)
    if cls is None:
        METHOD_PARAMS.pop(method.name, None)
    else:
        METHOD_PARAMS[method.name] = cls
    return method


def checked_params_class(name: str, cls: Any) -> type:
    """``cls`` if it can be the ``params_class`` of the method ``name``: a frozen
    dataclass whose every field has a default and a
    :class:`~napari_polarseg.engine.param_spec.ParamSpec`, whose names are
    not shared SegmentParams fields and whose flags are not the shared flags."""
    if not (isinstance(cls, type) and is_dataclass(cls)) or not cls.__dataclass_params__.frozen:
        raise PolarsegError(f"method {name!r}: params_class must be a frozen dataclass")
    specs = specs_of(cls)
    names = [f.name for f in fields(cls)]
    if set(names) - set(specs):
        missing = ", ".join(sorted(set(names) - set(specs)))
        raise PolarsegError(f"method {name!r}: parameter(s) without a ParamSpec: {missing}")
    shared = set(PARAM_SPECS) | {"method_params"}
    flags = {spec.flag for spec in PARAM_SPECS.values()}
    clash = [n for n in names if n in shared] + [s.flag for s in specs.values() if s.flag in flags]
    if clash:
        raise PolarsegError(f"method {name!r}: parameter(s) named as shared ones: {clash}")
    try:
        cls()
    except TypeError:
        raise PolarsegError(f"method {name!r}: every parameter needs a default") from None
    return cls


def unregister_method(name: str) -> None:
    """Forget the method registered as ``name`` (nothing if there is none)."""
    load_methods()
    _METHODS.pop(name, None)
    METHOD_CHOICES.pop(name, None)
    METHOD_PARAMS.pop(name, None)
    FINDS_K_METHODS.discard(name)
    BLOCK_MAP_METHODS.discard(name)


def get_method(name: str) -> Segmenter:
    """The method registered as ``name``; PolarsegError naming the known ones else."""
    load_methods()
    method = _METHODS.get(name)
    if method is None:
        known = ", ".join(_METHODS)
        raise PolarsegError(f"unknown segmentation method {name!r}; known: {known}")
    return method


def method_names() -> tuple[str, ...]:
    """Names of the registered methods, in registration order."""
    load_methods()
    return tuple(_METHODS)


def unsupervised_names() -> tuple[str, ...]:
    """The methods that need no input besides the image (the plugin's method menu)."""
    load_methods()
    return tuple(name for name, m in _METHODS.items() if not m.inputs)


def register_built_in() -> None:
    """Register the methods of :data:`BUILT_IN` (importing their modules)."""
    for module, cls in BUILT_IN:
        register_method(getattr(importlib.import_module(f"{__package__}.{module}"), cls)())


set_loader(register_built_in)  # run on the first lookup (..registered.load_methods)
