"""Parameters of the segmentation pipeline, with the thesis defaults.

Angles inside the engine are radians; the refractive index is dimensionless; window sizes
are pixels and minimum segment sizes are blocks.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from typing import Any

from .errors import PolarsegError

MODELS = ("diffuse", "specular")
SPECULAR_BRANCHES = ("below-brewster", "above-brewster")
COEFFICIENT_METHODS = ("thesis", "ridge")
SCALE_MODES = ("absolute", "median")
MAX_DEGREE = 60


@dataclass(frozen=True)
class SegmentParams:
    """Every tunable of the pipeline (thesis section 4.5 defaults).

    Attributes
    ----------
    window : int
        Side w of the non-overlapping w x w pixel blocks (thesis: 10).
    degree : int
        Highest spherical-harmonic degree L; the block vector has (L+1)^2 entries
        (thesis: 12).
    refractive_index : float
        Assumed refractive index n for zenith from degree of polarisation (thesis: 1.45).
    model : {"diffuse", "specular"}
        Fresnel model for the zenith: diffuse eq. 3.13 (corrected) or specular eq. 3.11.
    specular_branch : {"below-brewster", "above-brewster"}
        Which of the two specular zenith solutions to take (specular rho is not
        monotonic; it peaks at 1 at Brewster's angle).
    coefficients : {"thesis", "ridge"}
        Block coefficient estimator: the thesis mean estimator eq. 4.21 or a per-block
        ridge least-squares fit.
    ridge : float
        Ridge penalty, relative to the mean diagonal of the block Gram matrix.
    variance : float
        Share of variance the PCA keeps, in (0, 1] (thesis: 0.95).
    scale : float
        Affinity scale s in S = exp(-D / s) (thesis: 1).
    scale_mode : {"absolute", "median"}
        ``"absolute"``: s as given (thesis). ``"median"``: s is relative to the median
        squared Mahalanobis distance between blocks, which keeps the graph connected
        whatever the number of PCA components.
    n_segments : int
        Number of segments the recursive normalized cut stops at.
    ncut_threshold : float or None
        Stop splitting earlier when the best cut's Ncut value exceeds this.
    min_segment_blocks : int
        Smallest segment, in blocks, a cut may produce.
    """

    window: int = 10
    degree: int = 12
    refractive_index: float = 1.45
    model: str = "diffuse"
    specular_branch: str = "below-brewster"
    coefficients: str = "thesis"
    ridge: float = 1e-3
    variance: float = 0.95
    scale: float = 1.0
    scale_mode: str = "absolute"
    n_segments: int = 3
    ncut_threshold: float | None = None
    min_segment_blocks: int = 1

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`PolarsegError` naming the first parameter that is out of range."""
        if not isinstance(self.window, int) or isinstance(self.window, bool) or self.window < 1:
            raise PolarsegError(f"window must be a positive integer, got {self.window!r}")
        if not isinstance(self.degree, int) or not 0 <= self.degree <= MAX_DEGREE:
            raise PolarsegError(
                f"degree must be an integer in 0..{MAX_DEGREE}, got {self.degree!r}"
            )
        n = self.refractive_index
        if not isinstance(n, (int, float)) or not math.isfinite(n) or n <= 1.0:
            raise PolarsegError(f"refractive index must be a finite number > 1, got {n!r}")
        if self.model not in MODELS:
            raise PolarsegError(f"model must be one of {MODELS}, got {self.model!r}")
        if self.specular_branch not in SPECULAR_BRANCHES:
            raise PolarsegError(
                f"specular_branch must be one of {SPECULAR_BRANCHES}, got {self.specular_branch!r}"
            )
        if self.coefficients not in COEFFICIENT_METHODS:
            raise PolarsegError(
                f"coefficients must be one of {COEFFICIENT_METHODS}, got {self.coefficients!r}"
            )
        if not math.isfinite(self.ridge) or self.ridge <= 0:
            raise PolarsegError(f"ridge must be a positive number, got {self.ridge!r}")
        if not (0 < self.variance <= 1):
            raise PolarsegError(f"variance share must be in (0, 1], got {self.variance!r}")
        if not math.isfinite(self.scale) or self.scale <= 0:
            raise PolarsegError(f"affinity scale must be a positive number, got {self.scale!r}")
        if self.scale_mode not in SCALE_MODES:
            raise PolarsegError(f"scale_mode must be one of {SCALE_MODES}, got {self.scale_mode!r}")
        if not isinstance(self.n_segments, int) or self.n_segments < 1:
            raise PolarsegError(
                f"number of segments must be a positive integer, got {self.n_segments!r}"
            )
        if self.ncut_threshold is not None and not (self.ncut_threshold > 0):
            raise PolarsegError(
                f"ncut_threshold must be positive or None, got {self.ncut_threshold!r}"
            )
        if not isinstance(self.min_segment_blocks, int) or self.min_segment_blocks < 1:
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
