"""The pixel classifier's settings a user chooses: feature groups and scales, model, trees
and the region walk.

:class:`ClassifierSettings` pairs the two parameter dataclasses the classifier is trained
with (:class:`~napari_polarseg.engine.features.pixel_feature_params.PixelFeatureParams`,
:class:`~napari_polarseg.engine.classifier.pixel_classifier.ClassifierParams`);
:data:`SETTINGS` names the fields a user sets and :func:`setting_help` gives each one's
description from the ``Attributes`` section of its dataclass's docstring, so every
parameter is described once (the plugin's tooltips are made from it).
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass, field, replace
from typing import Any

from ..errors import PolarsegError
from ..features.pixel_feature_params import GROUPS, PixelFeatureParams
from .pixel_classifier import MODELS, ClassifierParams

#: The settings a user chooses: name → (the dataclass holding it, its field).
SETTINGS: dict[str, tuple[type, str]] = {
    "groups": (PixelFeatureParams, "groups"),
    "scales": (PixelFeatureParams, "scales"),
    "model": (ClassifierParams, "model"),
    "n_estimators": (ClassifierParams, "n_estimators"),
    "region_walk": (ClassifierParams, "region_walk"),
}

#: The choices of the settings that have a fixed set of values.
CHOICES: dict[str, tuple[str, ...]] = {"groups": GROUPS, "model": MODELS}


def setting_help(name: str) -> str:
    """The description of the setting ``name`` (one paragraph, plain text): the text
    under its field in the ``Attributes`` section of its dataclass's docstring."""
    cls, attr = SETTINGS[name]
    doc = inspect.getdoc(cls) or ""
    match = re.search(rf"^{attr} :[^\n]*\n((?:[ \t]+[^\n]*\n?)+)", doc, flags=re.MULTILINE)
    if match is None:
        raise KeyError(f"{cls.__name__} does not describe {attr}")
    text = " ".join(match.group(1).split())
    return re.sub(r":\w+:`~?([^`]+)`|``([^`]+)``", lambda m: m.group(1) or m.group(2), text)


@dataclass(frozen=True)
class ClassifierSettings:
    """How the scribble classifier is trained: its features and its model.

    Attributes
    ----------
    features : PixelFeatureParams
    classifier : ClassifierParams
    """

    features: PixelFeatureParams = field(default_factory=PixelFeatureParams)
    classifier: ClassifierParams = field(default_factory=ClassifierParams)

    @classmethod
    def of(
        cls,
        groups: tuple[str, ...] | None = None,
        scales: tuple[float, ...] | str | None = None,
        model: str | None = None,
        n_estimators: int | None = None,
        region_walk: float | None = None,
    ) -> ClassifierSettings:
        """The defaults with the given settings (``scales`` may be text: ``"1, 2, 4"``);
        raises :class:`PolarsegError` naming a bad value."""
        changes: dict[str, Any] = {}
        if groups is not None:
            changes["groups"] = tuple(groups)
        if scales is not None:
            changes["scales"] = parse_scales(scales) if isinstance(scales, str) else scales
        features = replace(PixelFeatureParams(), **changes)
        classifier = ClassifierParams()
        if model is not None:
            classifier = replace(classifier, model=model)
        if n_estimators is not None:
            classifier = replace(classifier, n_estimators=int(n_estimators))
        if region_walk is not None:
            classifier = replace(classifier, region_walk=float(region_walk))
        return cls(features, classifier)


def parse_scales(text: str) -> tuple[float, ...]:
    """Scales typed as ``"1, 2, 4"`` (commas or spaces) → (1.0, 2.0, 4.0)."""
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    try:
        return tuple(float(p) for p in parts)
    except ValueError:
        raise PolarsegError(
            f"scales must be numbers (pixels), e.g. 1, 2, 4; got {text!r}"
        ) from None


def format_scales(scales: tuple[float, ...]) -> str:
    """``(1.0, 2.0, 4.0)`` → ``"1, 2, 4"``."""
    return ", ".join(f"{s:g}" for s in scales)
