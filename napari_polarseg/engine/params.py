"""Parameters of the segmentation pipeline, with the thesis defaults.

Angles inside the engine are radians; the refractive index is dimensionless; window sizes
are pixels and minimum segment sizes are blocks.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from .errors import PolarsegError
from .registered import FINDS_K_METHODS, METHOD_CHOICES

MODELS = ("diffuse", "specular")
SPECULAR_BRANCHES = ("below-brewster", "above-brewster")
COEFFICIENT_METHODS = ("thesis", "ridge")
SCALE_MODES = ("absolute", "median")
FEATURE_KINDS = ("thesis", "zonal", "energy", "polstats", "zonal+polstats")
CLUSTERING_METHODS = ("recursive", "kway")
FIT_METHODS = ("lsq", "robust")
AFFINITY_GRAPHS = ("auto", "dense", "sparse")
MAX_DEGREE = 60

# METHOD_CHOICES (the choices of ``method``) and FINDS_K_METHODS are filled by
# napari_polarseg.engine.methods.register_method (this module cannot import the methods,
# which read these parameters); the built-in methods register on the first read of
# either (.registered).


@dataclass(frozen=True)
class ParamSpec:
    """How one :class:`SegmentParams` field is described, asked for and shown.

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
        The control's range (the engine's own checks are :meth:`SegmentParams.validate`).
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

    def options(self) -> tuple[str, ...] | None:
        """The values a menu offers now: :attr:`choices`, or the names in
        :attr:`registry` (a live mapping name → text, e.g. :data:`METHOD_CHOICES`)."""
        if self.registry is not None:
            return tuple(self.registry)
        return self.choices

    def menu(self) -> list[tuple[str, str]]:
        """(text, value) pairs of a menu parameter, in the order of :meth:`options`."""
        names = {**(self.choice_names or {}), **(self.registry or {})}
        return [(names.get(c, c), c) for c in self.options() or ()]


def _param(default: Any, **spec: Any) -> Any:
    """A dataclass field whose metadata holds its :class:`ParamSpec`."""
    return field(default=default, metadata={"spec": ParamSpec(**spec)})


@dataclass(frozen=True)
class SegmentParams:
    """Every tunable of the pipeline (thesis section 4.5 defaults).

    Each field's description, CLI flag and plugin control come from its
    :class:`ParamSpec` (:data:`PARAM_SPECS`); the attribute list below is made from them.
    """

    method: str = _param(
        "thesis",
        help="Segmentation method: the thesis block pipeline (thesis), edge-following "
        "superpixels clustered by their polarisation (superpixels), or any registered "
        "method (a pixel classifier runs when scribbles or a classifier are given)",
        flag="--method",
        label="method",
        registry=METHOD_CHOICES,
    )
    window: int = _param(
        10,
        help="Side w of the non-overlapping w x w pixel blocks, in pixels",
        flag="--window",
        metavar="W",
        label="window size",
        minimum=2,
        maximum=4096,
    )
    degree: int = _param(
        12,
        help="Highest spherical-harmonic degree L; the block vector has (L+1)² entries",
        flag="--degree",
        metavar="L",
        label="harmonic degree",
        minimum=0,
        maximum=MAX_DEGREE,
    )
    refractive_index: float = _param(
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
    )
    model: str = _param(
        "diffuse",
        help="Fresnel model for the zenith: diffuse (eq. 3.13, corrected) or specular (eq. 3.11)",
        flag="--model",
        label="model",
        choices=MODELS,
    )
    specular_branch: str = _param(
        "below-brewster",
        help="Which zenith solution of the specular model to take: specular ρ takes each "
        "value twice, peaking at 1 at Brewster's angle",
        flag="--specular-branch",
        label="specular branch",
        choices=SPECULAR_BRANCHES,
    )
    coefficients: str = _param(
        "thesis",
        help="Block coefficient estimator: the thesis mean estimator (eq. 4.21) or a "
        "per-block ridge least-squares fit",
        flag="--coefficients",
        label="coefficients",
        choices=COEFFICIENT_METHODS,
    )
    ridge: float = _param(
        1e-3,
        help="Ridge penalty of the 'ridge' estimator, relative to the mean diagonal of the "
        "block Gram matrix",
        flag="--ridge",
    )
    features: str = _param(
        "thesis",
        help="Block features for the PCA: every coefficient (thesis), the "
        "azimuth-invariant m = 0 coefficients (zonal), the energy per degree (energy), "
        "polarisation statistics of the block: the distributions of ρ, θ and Î and "
        "their relation (polstats), or the zonal coefficients and the statistics "
        "together (zonal+polstats)",
        flag="--features",
        label="features",
        choices=FEATURE_KINDS,
    )
    variance: float = _param(
        0.95,
        help="Share of the variance the PCA keeps, in (0, 1]",
        flag="--variance",
        label="PCA variance",
        minimum=0.05,
        maximum=1.0,
        step=0.01,
        decimals=3,
    )
    scale: float = _param(
        1.0,
        help="Affinity scale s in S = exp(-D / s)",
        flag="--scale",
        label="affinity scale",
        minimum=0.001,
        maximum=1e6,
        step=0.1,
        decimals=3,
    )
    scale_mode: str = _param(
        "absolute",
        help="absolute: s as given (thesis); median: s relative to the median squared "
        "Mahalanobis distance between blocks, which keeps the graph connected whatever "
        "the number of PCA components",
        flag="--scale-mode",
        label="scale mode",
        choices=SCALE_MODES,
    )
    spatial_radius: float = _param(
        0.0,
        help="Radius, in blocks, of Shi & Malik's spatial term in the affinity; 0 switches "
        "it off and connects every pair of blocks",
        flag="--spatial-radius",
        metavar="R",
    )
    spatial_sigma: float = _param(
        2.0,
        help="Width σ_X, in blocks, of the spatial term exp(−‖X_i − X_j‖² / σ_X²)",
        flag="--spatial-sigma",
        metavar="S",
    )
    n_segments: int = _param(
        3,
        help="Number of segments the normalized cut stops at (k of the k-way clustering "
        "and of the superpixel clustering); 0 (the CLI also takes auto) = found by the "
        "method itself (only a method that can, such as valid_superpixels)",
        flag="--segments",
        metavar="K",
        label="segments",
        minimum=0,
        maximum=256,
        words={"auto": 0},
    )
    object_size: float = _param(
        0.0,
        help="Typical size (diameter) of one object in pixels, as cellpose's diameter. "
        "The superpixel methods take superpixels of side size / 8 and a feature diffusion "
        "reaching half a size, never coarser than their share of the frame; 0 (the CLI "
        "also takes auto) keeps those frame-share scales and only estimates the size from "
        "the scene and reports it",
        flag="--object-size",
        metavar="PX",
        label="object size (px)",
        minimum=0,
        maximum=100_000,
        step=1,
        decimals=0,
        words={"auto": 0},
    )
    ncut_threshold: float | None = _param(
        None,
        help="Stop splitting earlier when the best cut's Ncut value exceeds this (none: never)",
        flag="--ncut-threshold",
        metavar="T",
        optional=True,
    )
    min_segment_blocks: int = _param(
        1,
        help="Smallest segment, in blocks, a cut may produce",
        flag="--min-segment-blocks",
        metavar="B",
        label="min segment (blocks)",
        minimum=1,
        maximum=100_000,
    )
    clustering: str = _param(
        "recursive",
        help="How the thesis method splits the block graph into segments: recursive "
        "two-way normalized cuts (thesis section 4.4.1) or k-way spectral clustering "
        "(the first k generalized eigenvectors, rows normalised, k-means; Ng, Jordan & "
        "Weiss 2002)",
        flag="--clustering",
        label="clustering",
        choices=CLUSTERING_METHODS,
        choice_names={
            "recursive": "recursive two-way",
            "kway": "k-way spectral",
        },
    )
    fit: str = _param(
        "lsq",
        help="Per-pixel sinusoid fit of the polarisation image: exact linear least squares "
        "(optimal for Gaussian noise), or robust IRLS (Tukey's biweight from a trimmed "
        "start) that resists outlying frames (needs 5 or more distinct angles to make a "
        "difference)",
        flag="--fit",
        label="fit",
        choices=FIT_METHODS,
        choice_names={"lsq": "least squares", "robust": "robust"},
    )
    affinity_graph: str = _param(
        "auto",
        help="How the block affinity is stored: every pair of blocks (dense, the thesis); "
        "the pairs within spatial_radius, or without a spatial term each block's k "
        "nearest neighbours in feature space (sparse); sparse with a spatial term or "
        "above 6000 blocks, else dense (auto)",
        flag="--affinity-graph",
        choices=AFFINITY_GRAPHS,
    )

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`PolarsegError` naming the first parameter that is out of range.

        ``method`` is checked against the registered methods where it is looked up
        (:func:`napari_polarseg.engine.methods.get_method`), so that a method
        registered later is accepted.
        """
        if not isinstance(self.method, str) or not self.method:
            raise PolarsegError(f"method must be a method's name, got {self.method!r}")
        if not _is_int(self.window) or self.window < 1:
            raise PolarsegError(f"window must be a positive integer, got {self.window!r}")
        if not _is_int(self.degree) or not 0 <= self.degree <= MAX_DEGREE:
            raise PolarsegError(
                f"degree must be an integer in 0..{MAX_DEGREE}, got {self.degree!r}"
            )
        n = self.refractive_index
        if not _is_number(n) or n <= 1.0:
            raise PolarsegError(f"refractive index must be a finite number > 1, got {n!r}")
        _check_choice("model", self.model, MODELS)
        _check_choice("specular_branch", self.specular_branch, SPECULAR_BRANCHES)
        _check_choice("coefficients", self.coefficients, COEFFICIENT_METHODS)
        _check_choice("scale_mode", self.scale_mode, SCALE_MODES)
        _check_choice("features", self.features, FEATURE_KINDS)
        _check_choice("fit", self.fit, FIT_METHODS)
        _check_choice("clustering", self.clustering, CLUSTERING_METHODS)
        _check_choice("affinity_graph", self.affinity_graph, AFFINITY_GRAPHS)
        if not _is_number(self.ridge) or self.ridge <= 0:
            raise PolarsegError(f"ridge must be a positive number, got {self.ridge!r}")
        if not _is_number(self.variance) or not 0 < self.variance <= 1:
            raise PolarsegError(f"variance share must be in (0, 1], got {self.variance!r}")
        if not _is_number(self.scale) or self.scale <= 0:
            raise PolarsegError(f"affinity scale must be a positive number, got {self.scale!r}")
        if not _is_number(self.spatial_radius) or self.spatial_radius < 0:
            raise PolarsegError(
                f"spatial_radius must be a number >= 0, got {self.spatial_radius!r}"
            )
        if not _is_number(self.spatial_sigma) or self.spatial_sigma <= 0:
            raise PolarsegError(f"spatial_sigma must be a number > 0, got {self.spatial_sigma!r}")
        if not _is_int(self.n_segments) or self.n_segments < 1:
            # only then are the registered methods read (0: a method that finds k)
            finds_k = self.method in FINDS_K_METHODS
            if not _is_int(self.n_segments) or self.n_segments < (0 if finds_k else 1):
                raise PolarsegError(
                    f"number of segments must be a positive integer, got {self.n_segments!r}"
                    + ("" if finds_k else f" (0 = find it: not offered by {self.method!r})")
                )
        if not _is_number(self.object_size) or self.object_size < 0:
            raise PolarsegError(
                f"object size must be a number of pixels >= 0 (0 = auto), got {self.object_size!r}"
            )
        if self.ncut_threshold is not None and (
            not _is_number(self.ncut_threshold) or self.ncut_threshold <= 0
        ):
            raise PolarsegError(
                f"ncut_threshold must be positive or None, got {self.ncut_threshold!r}"
            )
        if not _is_int(self.min_segment_blocks) or self.min_segment_blocks < 1:
            raise PolarsegError(
                f"min_segment_blocks must be a positive integer, got {self.min_segment_blocks!r}"
            )

    def replace(self, **changes: Any) -> SegmentParams:
        """Return a copy with some fields changed (validated)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise PolarsegError(f"unknown parameter(s): {', '.join(sorted(unknown))}")
        return SegmentParams(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SegmentParams:
        """Parameters from a mapping (``params.json``). A file written before the
        methods were peers says ``clustering: "superpixels"`` for the superpixel
        method: read as ``method: "superpixels"``."""
        if data.get("clustering") == "superpixels" and "method" not in data:
            data = {**data, "clustering": "recursive", "method": "superpixels"}
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise PolarsegError(f"unknown parameter(s): {', '.join(sorted(unknown))}")
        return cls(**data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> SegmentParams:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise PolarsegError(f"parameters are not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise PolarsegError("parameters JSON must be an object")
        return cls.from_dict(data)


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _is_number(v: Any) -> bool:
    return (
        isinstance(v, (int, float, np.integer, np.floating))
        and not isinstance(v, (bool, np.bool_))
        and math.isfinite(float(v))
    )


def _check_choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if not isinstance(value, str) or value not in choices:
        raise PolarsegError(f"{name} must be one of {', '.join(choices)}; got {value!r}")


#: Parameters that beat the thesis defaults on the bundled synthetic scenes (chosen with
#: ``benchmarks/evaluate.py --sweep``; docs/quality.md has the table).
#: The thesis's absolute affinity scale s = 1 with 10-20 PCA components gives affinities
#: near e^-30: the graph falls apart and the cut peels off single blocks, so the scale is
#: relative to the median distance here; the azimuth-invariant zonal coefficients drop
#: the surface-azimuth variation that dominates the raw coefficients; a minimum segment
#: size stops the cut from isolating a few odd blocks.
RECOMMENDED = SegmentParams(
    window=12,
    degree=8,
    features="zonal",
    scale=2.0,
    scale_mode="median",
    min_segment_blocks=4,
)


#: The default of ``segment``, ``demo`` and the plugin (preset ``auto``): the superpixel
#: method on the valid pixels, k + 1 clusters merged to k across the weakest border,
#: the node features diffused over whole surfaces (``method="surface_superpixels"``),
#: the best unsupervised method measured on the rendered development scenes and the
#: hand-labelled real frames together (``benchmarks/evaluate_unsupervised.py``, figures
#: in ``docs/quality.md``; it replaced ``"valid_superpixels"``, which replaced
#: ``"superpixels"``); the recommended block parameters give the thesis maps when
#: asked for.
AUTO = RECOMMENDED.replace(method="surface_superpixels")

#: The named starting points of the CLI's ``--preset`` and the plugin's preset menu.
PRESETS: dict[str, SegmentParams] = {
    "auto": AUTO,
    "thesis": SegmentParams(),
    "recommended": RECOMMENDED,
}


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

#: The description of every SegmentParams field, by name, in field order.
PARAM_SPECS: dict[str, ParamSpec] = {f.name: f.metadata["spec"] for f in fields(SegmentParams)}


def _attribute_docs() -> str:
    """The numpydoc *Attributes* section of :class:`SegmentParams`, from its specs."""
    lines = ["", "    Attributes", "    ----------"]
    for f in fields(SegmentParams):
        spec = PARAM_SPECS[f.name]
        kind = (
            "{" + ", ".join(f'"{c}"' for c in spec.choices) + "}"
            if spec.choices
            else (f.type if isinstance(f.type, str) else f.type.__name__)
        )
        lines.append(f"    {f.name} : {kind}")
        lines.append(f"        {spec.help} (``{spec.flag}``; thesis: {f.default!r}).")
    return "\n".join(lines) + "\n"


SegmentParams.__doc__ = (SegmentParams.__doc__ or "") + _attribute_docs()
