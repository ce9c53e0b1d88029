"""The scribble classifier's settings (issue 23, item 4): described once, in the
parameter dataclasses' docstrings, and turned into the engine's parameters."""

from __future__ import annotations

import pytest

from napari_polarseg.engine.classifier.classifier_settings import (
    SETTINGS,
    ClassifierSettings,
    format_scales,
    parse_scales,
    setting_help,
)
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.features.pixel_features import PixelFeatureParams


def test_each_setting_is_described_by_its_dataclass():
    assert setting_help("scales").startswith("Gaussian σ of every scale, pixels (> 0): the")
    assert setting_help("n_estimators").startswith("Trees of a forest")
    assert "GROUPS" in setting_help("groups") and ":data:" not in setting_help("groups")
    for name, (cls, attr) in SETTINGS.items():
        assert attr in cls.__dataclass_fields__ and setting_help(name)


def test_settings_become_the_engine_parameters():
    s = ClassifierSettings.of(
        groups=("intensity",), scales="0.5, 2 4", model="random_forest", n_estimators=7
    )
    assert s.features == PixelFeatureParams(scales=(0.5, 2.0, 4.0), groups=("intensity",))
    assert s.classifier == ClassifierParams(model="random_forest", n_estimators=7)
    assert ClassifierSettings.of() == ClassifierSettings()
    assert parse_scales(format_scales((1.0, 2.5))) == (1.0, 2.5)
    for bad in ({"scales": "a, 2"}, {"scales": "-1"}, {"groups": ("colour",)}, {"model": "svm"}):
        with pytest.raises(PolarsegError):
            ClassifierSettings.of(**bad)
