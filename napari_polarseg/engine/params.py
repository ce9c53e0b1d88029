"""Parameters of a segmentation: what every method shares (:class:`SegmentParams`) and
each method's own (:attr:`SegmentParams.method_params`, :mod:`.method_params`).

Angles inside the engine are radians; the refractive index is dimensionless; object sizes
are pixels. The presets (:data:`PRESETS`) are in :mod:`.presets`.
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from .errors import PolarsegError
from .method_params import (
    MISSING_VALUE,
    MethodParams,
    from_values,
    method_value,
    owner_of,
    params_class,
    route,
)
from .param_spec import (
    ParamSpec,
    attribute_docs,
    check_choice,
    is_int,
    is_number,
    param_field,
    specs_of,
)
from .registered import FINDS_K_METHODS, METHOD_CHOICES, METHOD_PARAMS

MODELS = ("diffuse", "specular")
SPECULAR_BRANCHES = ("below-brewster", "above-brewster")
COEFFICIENT_METHODS = ("thesis", "ridge")
SCALE_MODES = ("absolute", "median")
FEATURE_KINDS = ("thesis", "zonal", "energy", "polstats", "zonal+polstats")
CLUSTERING_METHODS = ("recursive", "kway")
FIT_METHODS = ("lsq", "robust")
AFFINITY_GRAPHS = ("auto", "dense", "sparse")
MAX_DEGREE = 60
#: The method of the default preset (``PRESETS["auto"]``), also ``SegmentParams().method``:
#: the engine's default is the CLI's and the plugin's.
DEFAULT_METHOD = "surface_superpixels"

# METHOD_CHOICES (the choices of ``method``), FINDS_K_METHODS and METHOD_PARAMS (each
# method's parameter class) are filled by napari_polarseg.engine.methods.register_method
# (this module cannot import the methods, which read these parameters); the built-in
# methods register on the first read of any (.registered).

__all__ = [
    "MethodParams",
    "PARAM_SPECS",
    "ParamSpec",
    "SegmentParams",
    "all_param_specs",
    "method_param_specs",
    "param_field",
]


@dataclass(frozen=True, init=False)
class SegmentParams:
    """The parameters every segmentation method shares, and each method's own.

    The shared fields are listed below: the method, the per-pixel polarisation fit and
    the Fresnel normals every method's run computes (:meth:`Scene.polarisation`), the
    number of segments and the object size. A method's own parameters (its
    ``params_class``, e.g. the thesis method's window and degree:
    :class:`~napari_polarseg.engine.methods.thesis.ThesisParams`) are kept by method name
    in :attr:`method_params`; :meth:`params_of` returns them.

    A method parameter may also be given and read by its name alone, as before the
    methods had their own: ``SegmentParams(window=10)``, ``params.replace(degree=8)``,
    ``params.window`` and a ``params.json`` with ``window`` at the top level name the
    parameter of the chosen method when it declares it, else of the first registered
    method that does (the thesis method for the block parameters, which the thesis maps
    of any run read). A name no method declares raises :class:`PolarsegError`. Given
    without ``method``, parameters that are all one method's own choose that method
    (``SegmentParams(window=10)`` is the thesis method's, as before; a ``params.json``
    without ``method`` likewise); without any, the method is the default one
    (:data:`DEFAULT_METHOD`, that of preset ``auto``).

    Each shared field's description, CLI flag and plugin control come from its
    :class:`ParamSpec` (:data:`PARAM_SPECS`); the attribute list below is made from them.
    """

    method: str = param_field(
        DEFAULT_METHOD,
        help="Segmentation method: the thesis block pipeline (thesis), edge-following "
        "superpixels clustered by their polarisation (superpixels), or any registered "
        "method (a pixel classifier runs when scribbles or a classifier are given)",
        flag="--method",
        label="method",
        registry=METHOD_CHOICES,
        effect="Which algorithm splits the image into materials: the superpixel methods follow "
        "object edges and are fastest; thesis works on a grid of square blocks",
    )
    refractive_index: float = param_field(
        1.45,
        help="Assumed refractive index n > 1 for the zenith from the degree of "
        "polarisation ρ (dimensionless)",
        flag="--refractive-index",
        metavar="N",
        label="refractive index",
        minimum=1.01,
        maximum=3.0,
        step=0.01,
        decimals=3,
        effect="The material's assumed refractive index (glass and most plastics about 1.5), "
        "used to turn polarisation into surface angle; moves the segments little",
    )
    model: str = param_field(
        "diffuse",
        help="Fresnel model for the zenith: diffuse (eq. 3.13, corrected) or specular (eq. 3.11)",
        flag="--model",
        label="model",
        choices=MODELS,
        effect="Whether surfaces are taken as matte (diffuse) or shiny (specular) when "
        "polarisation is turned into surface angle",
    )
    specular_branch: str = param_field(
        "below-brewster",
        help="Which zenith solution of the specular model to take: specular ρ takes each "
        "value twice, peaking at 1 at Brewster's angle",
        flag="--specular-branch",
        label="specular branch",
        choices=SPECULAR_BRANCHES,
        effect="Shiny surfaces only: which of the two surface angles that give the same "
        "polarisation to take",
    )
    n_segments: int = param_field(
        3,
        help="Number of segments k the method makes (the clusters of the superpixel "
        "methods, where the thesis cut stops); 0 (the CLI also takes auto) = found by the "
        "method itself (only a method that can, such as valid_superpixels)",
        flag="--segments",
        metavar="K",
        label="segments",
        minimum=0,
        maximum=256,
        words={"auto": 0},
        effect="How many segments (materials) the result has; 0 lets a method that can choose "
        "the number itself",
    )
    object_size: float = param_field(
        0.0,
        help="Typical size (diameter) of one object in pixels, as cellpose's diameter. "
        "The superpixel methods take superpixels of side size / 8 and a feature diffusion "
        "reaching half a size, never coarser than their share of the frame; the pixel "
        "classifier keeps the feature scales σ up to one size (at least 4 px). 0 (the CLI "
        "also takes auto) estimates the size from the scene: the classifier follows it, "
        "the superpixel methods keep their frame-share scales and report it",
        flag="--object-size",
        metavar="PX",
        label="object size (px)",
        minimum=0,
        maximum=100_000,
        step=1,
        decimals=0,
        words={"auto": 0},
        effect="How large one object is, in pixels across; 0 estimates it from the image. "
        "Smaller sizes give finer superpixels that do not blur small objects together",
    )
    fit: str = param_field(
        "lsq",
        help="Per-pixel sinusoid fit of the polarisation image: exact linear least squares "
        "(optimal for Gaussian noise), or robust IRLS (Tukey's biweight from a trimmed "
        "start) that resists outlying frames (needs 5 or more distinct angles to make a "
        "difference)",
        flag="--fit",
        label="fit",
        choices=FIT_METHODS,
        choice_names={"lsq": "least squares", "robust": "robust"},
        effect="How each pixel's polarisation is measured from the frames: robust ignores a "
        "frame that is off at a pixel (a glint, a moving edge) and takes longer",
    )
    #: Each method's own parameters, by method name (:class:`MethodParams`).
    method_params: MethodParams = field(default_factory=MethodParams)

    def __init__(self, method_params: Mapping[str, Any] | None = None, **values: Any) -> None:
        """Shared fields by name (missing: their defaults), ``method_params`` (method name
        → its parameters: an instance of its class or a mapping) and method parameters
        by name alone (routed to the method that declares them, see the class)."""
        if "method" not in values and values.keys() - set(PARAM_SPECS):
            owners = {owner_of(name, DEFAULT_METHOD) for name in values} - {None}
            if len(owners) == 1:  # a method's own parameters and no method: that method
                values["method"] = owners.pop()
        shared = {}
        for f in fields(SegmentParams):
            if f.name != "method_params":
                shared[f.name] = values.pop(f.name) if f.name in values else f.default
                object.__setattr__(self, f.name, shared[f.name])
        stored = method_params if isinstance(method_params, MethodParams) else None
        if stored is None:
            stored = MethodParams(method_params or {})
        if values:
            stored = route(str(shared["method"]), stored, values)
        object.__setattr__(self, "method_params", stored)
        self.validate()

    def __getattr__(self, name: str) -> Any:
        """A method parameter read by its name alone (see the class)."""
        if name.startswith("_") or name in ("method", "method_params"):
            raise AttributeError(name)
        value = method_value(self.method, self.method_params, name)
        if value is MISSING_VALUE:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return value

    def params_of(self, method: str | None = None) -> Any:
        """The parameters of ``method`` (default: the chosen one), an instance of its
        ``params_class`` (its defaults unless set); None for a method without any."""
        return self.method_params.of(self.method if method is None else method)

    def validate(self) -> None:
        """Raise :class:`PolarsegError` naming the first shared parameter that is out of
        range (a method's own parameters are checked by their class).

        ``method`` is checked against the registered methods where it is looked up
        (:func:`napari_polarseg.engine.methods.get_method`), so that a method
        registered later is accepted.
        """
        if not isinstance(self.method, str) or not self.method:
            raise PolarsegError(f"method must be a method's name, got {self.method!r}")
        n = self.refractive_index
        if not is_number(n) or n <= 1.0:
            raise PolarsegError(f"refractive index must be a finite number > 1, got {n!r}")
        check_choice("model", self.model, MODELS)
        check_choice("specular_branch", self.specular_branch, SPECULAR_BRANCHES)
        check_choice("fit", self.fit, FIT_METHODS)
        if not is_int(self.n_segments) or self.n_segments < 1:
            # only then are the registered methods read (0: a method that finds k)
            finds_k = self.method in FINDS_K_METHODS
            if not is_int(self.n_segments) or self.n_segments < (0 if finds_k else 1):
                raise PolarsegError(
                    f"number of segments must be a positive integer, got {self.n_segments!r}"
                    + ("" if finds_k else f" (0 = find it: not offered by {self.method!r})")
                )
        if not is_number(self.object_size) or self.object_size < 0:
            raise PolarsegError(
                f"object size must be a number of pixels >= 0 (0 = auto), got {self.object_size!r}"
            )

    def shared_values(self) -> dict[str, Any]:
        """The shared fields by name (without :attr:`method_params`)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "method_params"}

    def changed_names(self, other: SegmentParams) -> tuple[str, ...]:
        """The parameters whose values differ from ``other``'s: shared field names, then
        method parameter names (each method's own that differ, by name alone)."""
        names = [n for n, v in self.shared_values().items() if getattr(other, n) != v]
        for method in dict.fromkeys([*self.method_params, *other.method_params]):
            mine, theirs = asdict(self.params_of(method)), asdict(other.params_of(method))
            names += [n for n, v in mine.items() if theirs[n] != v and n not in names]
        return tuple(names)

    def replace(self, **changes: Any) -> SegmentParams:
        """Return a copy with some fields changed (validated); a method parameter may be
        named alone (see the class)."""
        return SegmentParams(
            **{**self.shared_values(), "method_params": self.method_params, **changes}
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the shared fields, then ``method_params``: every parameter of the
        chosen method, and those of any other method set to other than its defaults
        (e.g. the block parameters of the thesis maps), by method name."""
        own: dict[str, Any] = {}
        chosen = self.params_of()
        if chosen is not None:
            own[self.method] = asdict(chosen)
        for name, values in self.method_params.items():
            own.setdefault(name, asdict(values))
        return {**self.shared_values(), "method_params": own}

    def updated(self, data: Mapping[str, Any]) -> SegmentParams:
        """These parameters with the fields a mapping (``params.json``) gives: shared
        fields replaced, each method's entry of ``method_params`` merged into that
        method's parameters, and method parameters named at the top level (files written
        before the methods had their own) routed as in the class. A file written before
        the methods were peers says ``clustering: "superpixels"`` for the superpixel
        method: read as ``method: "superpixels"``; one without ``method`` whose
        parameters belong to one method is that method's."""
        data = dict(data)
        if data.get("clustering") == "superpixels" and "method" not in data:
            data = {**data, "clustering": "recursive", "method": "superpixels"}
        given = data.pop("method_params", None) or {}
        if not isinstance(given, Mapping):
            raise PolarsegError("method_params must be an object (method name → parameters)")
        shared_names = set(self.shared_values())
        loose = {k: v for k, v in data.items() if k not in shared_names}
        if loose and "method" not in data:
            owners = {owner_of(name, self.method) for name in loose} - {None}
            if len(owners) == 1 and self.method not in owners:
                data["method"] = owners.pop()
        items = dict(self.method_params.items())
        for method, values in given.items():
            if isinstance(values, Mapping) and method in items:
                values = {**asdict(items[method]), **values}
            items[method] = from_values(str(method), values)
        return self.replace(method_params=MethodParams(items), **data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SegmentParams:
        """Parameters from a mapping (``params.json``): the defaults, :meth:`updated`
        with ``data``."""
        return cls().updated(data)

    @classmethod
    def from_json(cls, text: str) -> SegmentParams:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise PolarsegError(f"parameters are not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise PolarsegError("parameters JSON must be an object")
        return cls.from_dict(data)


#: The presets defined in :mod:`.presets` (they hold the thesis method's parameters, so
#: they are made on first use: importing this module imports no method).
LAZY_PRESETS = ("RECOMMENDED", "AUTO", "PRESETS")


def __getattr__(name: str) -> Any:
    if name not in LAZY_PRESETS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    # by name, on first use (PEP 562): .presets imports the thesis method, which
    # imports this module
    value = getattr(importlib.import_module(".presets", __package__), name)
    globals()[name] = value  # later lookups skip this function
    return value


#: The preset a run starts from when none is chosen: ``segment``, ``demo``, ``batch``, the
#: plugin's preset menu and ``examples/segment_in_napari.py``.
DEFAULT_PRESET = "auto"


#: What each preset is: the CLI's ``--preset`` help and the plugin's preset tooltip.
PRESET_HELP: dict[str, str] = {
    "auto": "superpixels of the valid pixels, their polarisation features spread over the "
    "surface each lies on, clustered into one segment more than asked, the two whose "
    "shared border is weakest merged: the best unsupervised method "
    "measured on rendered and real frames (--segments 0: the number found by itself; a "
    "close-up of one smooth surface: by where its polarisation departs from the "
    "surface's trend)",
    "thesis": "the thesis pipeline as published",
    "recommended": "the thesis pipeline with the block parameters that score best on the "
    "synthetic scenes (docs/quality.md)",
}

#: The description of every shared SegmentParams field, by name, in field order (a
#: method's own: :func:`method_param_specs`).
PARAM_SPECS: dict[str, ParamSpec] = specs_of(SegmentParams)


def method_param_specs(method: str) -> dict[str, ParamSpec]:
    """The description of every parameter of the method registered as ``method``, by
    name, in field order (empty for a method without parameters of its own)."""
    cls = params_class(method)
    return {} if cls is None else specs_of(cls)


def all_param_specs() -> dict[str, dict[str, ParamSpec]]:
    """The parameter table of every registered method that has parameters of its own,
    by method name, in registration order."""
    return {name: specs_of(cls) for name, cls in METHOD_PARAMS.items()}


SegmentParams.__doc__ = (SegmentParams.__doc__ or "") + attribute_docs(SegmentParams)
