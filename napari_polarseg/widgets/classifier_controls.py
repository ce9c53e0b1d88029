"""The Segment widget's classifier settings (advanced section): feature groups, scales,
model, trees and region walk of the scribble classifier.

Each control's tooltip is its parameter's one description
(:func:`~napari_polarseg.engine.classifier.classifier_settings.setting_help`, from the
parameter dataclasses' docstrings); :meth:`ClassifierControls.settings` gives the
:class:`~napari_polarseg.engine.classifier.classifier_settings.ClassifierSettings` a
training uses.
"""

from __future__ import annotations

from typing import Any

from magicgui.widgets import ComboBox, Container, FloatSpinBox, LineEdit, Select, SpinBox

from ..engine import PolarsegError
from ..engine.classifier.classifier_settings import (
    CHOICES,
    ClassifierSettings,
    format_scales,
    setting_help,
)

#: Most trees the control offers.
MAX_TREES = 1000


class ClassifierControls(Container):
    """Feature groups, scales, model, trees and region walk of the scribble classifier."""

    def __init__(self) -> None:
        default = ClassifierSettings()
        self.groups = Select(
            label="feature groups",
            choices=list(CHOICES["groups"]),
            value=list(default.features.groups),
            tooltip=setting_help("groups"),
        )
        self.groups.native.setMaximumHeight(110)
        self.scales = LineEdit(
            label="feature scales (px)",
            value=format_scales(default.features.scales),
            tooltip=setting_help("scales") + " Separated by commas, e.g. 1, 2, 4, 8, 16.",
        )
        self.model = ComboBox(
            label="classifier model",
            choices=list(CHOICES["model"]),
            value=default.classifier.model,
            tooltip=setting_help("model"),
        )
        self.trees = SpinBox(
            label="trees",
            value=default.classifier.n_estimators,
            min=1,
            max=MAX_TREES,
            tooltip=setting_help("n_estimators"),
        )
        self.walk = FloatSpinBox(
            label="region walk γ",
            value=default.classifier.region_walk,
            min=0.0,
            max=100.0,
            step=0.01,
            tooltip=setting_help("region_walk"),
        )
        super().__init__(widgets=self.controls, labels=True, label="")
        self.margins = (0, 0, 0, 0)

    @property
    def controls(self) -> list[Any]:
        """The controls whose changes a live update reruns after."""
        return [self.groups, self.scales, self.model, self.trees, self.walk]

    def settings(self) -> ClassifierSettings:
        """The settings the controls describe; raises :class:`PolarsegError` naming a
        bad value (no group chosen, scales that are not positive numbers)."""
        groups = tuple(self.groups.value)
        if not groups:
            raise PolarsegError("choose at least one feature group")
        return ClassifierSettings.of(
            groups=groups,
            scales=str(self.scales.value),
            model=str(self.model.value),
            n_estimators=int(self.trees.value),
            region_walk=float(self.walk.value),
        )

    def settings_or_none(self) -> ClassifierSettings | None:
        """:meth:`settings`, or None when a value is bad."""
        try:
            return self.settings()
        except PolarsegError:
            return None
