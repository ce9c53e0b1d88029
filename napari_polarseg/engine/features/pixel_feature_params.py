"""What the pixel feature stack of the scribble classifier holds, and how its scales
follow the scene's object size.

:class:`PixelFeatureParams` names the Gaussian scales σ (pixels) and the feature groups
of :func:`~.pixel_features.pixel_features`. Its scales are a candidate set: on a scene
whose typical object diameter is D px (:mod:`.object_size`, like cellpose's diameter),
the scribble methods keep the scales σ ≤ max(c · D, :data:`MIN_LARGEST_SCALE`) with c =
``largest_scale_objects`` (:meth:`PixelFeatureParams.at_object_size`). A Gaussian
window wider than an object averages the object with its neighbours, so on a scene of
10 px leaves the σ = 16 features describe the neighbourhood, not the leaf, and a few
strokes teach the classifier where they were painted rather than what they covered.

Measured on the development halves of the family bench (``benchmarks/evaluate_families.py
--halves dev``, docs/quality.md): the cap changes only scenes whose estimated objects are
under 16 px.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from ..errors import PolarsegError
from .superpixels import auto_region_area

#: Feature groups (:mod:`.pixel_features`), in the order their features appear.
GROUPS = ("intensity", "polarisation", "zenith", "filters", "invariant", "regions")
#: Automatic superpixel area: the image's pixels / this, within the two bounds below
#: (a 1224 × 1024 frame: ~420 px regions; a 120 × 130 scene: 64 px).
PIXELS_PER_REGION_SEED = 3000
MIN_REGION_AREA = 64
MAX_REGION_AREA = 1024
#: The largest feature scale kept at any object size, σ in pixels (every candidate
#: scale up to this stays, however small the objects).
MIN_LARGEST_SCALE = 4.0


@dataclass(frozen=True)
class PixelFeatureParams:
    """What the pixel feature stack holds.

    Attributes
    ----------
    scales : tuple of float
        Gaussian σ of every scale, pixels (> 0): the candidates, of which a scene keeps
        those its object size allows (``largest_scale_objects``).
    groups : tuple of str
        Feature groups from :data:`GROUPS`. The default is the set that measured best
        on the rendered scenes and the hand-labelled real frames together
        (``benchmarks/evaluate.py``); ``filters`` helped a real frame and hurt the
        rendered scenes, ``zenith`` is redundant for trees.
    refractive_index : float
        n of the diffuse Fresnel model (eq. 3.13) for the zenith feature θ.
    region_area : int
        Mean superpixel area of the ``regions`` group, pixels; 0 = one region per
        :data:`PIXELS_PER_REGION_SEED`-th of the image, within
        [:data:`MIN_REGION_AREA`, :data:`MAX_REGION_AREA`].
    largest_scale_objects : float
        c: the largest σ kept on a scene of object diameter D px is max(c · D,
        :data:`MIN_LARGEST_SCALE`) (:meth:`at_object_size`; dimensionless, ≥ 0). 0 =
        every scale whatever the objects' size: the parameters of a trained
        classifier, whose scales are the ones it was trained on.
    """

    scales: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0, 16.0)
    groups: tuple[str, ...] = ("intensity", "polarisation", "invariant", "regions")
    refractive_index: float = 1.45
    region_area: int = 0
    largest_scale_objects: float = 1.0

    def __post_init__(self) -> None:
        scales = tuple(float(s) for s in self.scales)
        if not scales or not all(math.isfinite(s) and s > 0 for s in scales):
            raise PolarsegError(f"feature scales must be positive numbers, got {self.scales!r}")
        groups = tuple(str(g) for g in self.groups)
        unknown = [g for g in groups if g not in GROUPS]
        if not groups or unknown:
            raise PolarsegError(
                f"feature groups must be some of {', '.join(GROUPS)}; got {self.groups!r}"
            )
        if not (math.isfinite(self.refractive_index) and self.refractive_index > 1):
            raise PolarsegError(f"refractive_index must be > 1, got {self.refractive_index}")
        object.__setattr__(self, "scales", scales)
        object.__setattr__(self, "groups", groups)
        object.__setattr__(self, "refractive_index", float(self.refractive_index))
        if int(self.region_area) < 0 or (0 < int(self.region_area) < 4):
            raise PolarsegError(f"region_area must be 0 (auto) or >= 4, got {self.region_area}")
        object.__setattr__(self, "region_area", int(self.region_area))
        c = float(self.largest_scale_objects)
        if not (math.isfinite(c) and c >= 0):
            raise PolarsegError(f"largest_scale_objects must be a number >= 0, got {c}")
        object.__setattr__(self, "largest_scale_objects", c)

    @property
    def follows_object_size(self) -> bool:
        """True while the scales still depend on a scene's object size."""
        return self.largest_scale_objects > 0

    def at_object_size(self, size_px: float) -> PixelFeatureParams:
        """These parameters on a scene of object diameter D = ``size_px`` px: the scales
        σ ≤ max(c · D, :data:`MIN_LARGEST_SCALE`) (at least the smallest candidate),
        fixed (``largest_scale_objects`` = 0). Unchanged when c = 0."""
        if not self.follows_object_size:
            return self
        top = max(self.largest_scale_objects * float(size_px), MIN_LARGEST_SCALE)
        kept = tuple(s for s in self.scales if s <= top) or (min(self.scales),)
        return replace(self, scales=kept, largest_scale_objects=0.0)

    def regions_of(self, shape: tuple[int, int]) -> int:
        """Superpixel area (pixels) used on an image of ``shape``."""
        if self.region_area:
            return self.region_area
        return auto_region_area(shape, PIXELS_PER_REGION_SEED, MIN_REGION_AREA, MAX_REGION_AREA)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (lists for tuples)."""
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PixelFeatureParams:
        """Inverse of :meth:`to_dict`; unknown keys raise :class:`PolarsegError`."""
        extra = sorted(set(values) - {f.name for f in fields(cls)})
        if extra:
            raise PolarsegError(f"unknown pixel feature parameters: {', '.join(extra)}")
        try:
            return cls(
                scales=tuple(values.get("scales", cls.scales)),
                groups=tuple(values.get("groups", cls.groups)),
                refractive_index=float(values.get("refractive_index", cls.refractive_index)),
                region_area=int(values.get("region_area", cls.region_area)),
                largest_scale_objects=float(
                    values.get("largest_scale_objects", cls.largest_scale_objects)
                ),
            )
        except (TypeError, ValueError) as exc:
            raise PolarsegError(f"bad pixel feature parameters ({exc})") from None
