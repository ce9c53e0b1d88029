"""The Segment widget's public members that scripts, tests and the other docks use: the
controls (as properties reading the parts that hold them), the state's values
(parameters, loaded classifier, prediction), and the few actions of the parts offered
as the widget's own (parameter files, classifier files, *Export results…*,
*New scribbles layer*).

:class:`SegmentMembers` is a base of :class:`~napari_polarseg.widgets.segment.SegmentWidget`;
it reads the attributes the widget sets: ``state``
(:class:`~napari_polarseg.widgets.session.state.SegmentState`), ``controls``
(:class:`~napari_polarseg.widgets.segment_params.ParameterControls`), ``inputs``,
``layers``, ``classifier_files`` and ``export``. A parameter's control is found by the
parameter's name (``widget.window``, ``widget.n_segments``, …).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._layers import source_key

if TYPE_CHECKING:
    import numpy as np
    from magicgui.widgets import CheckBox, ComboBox, Container, PushButton
    from napari.layers import Labels, Layer

    from ..engine import Pipeline, SegmentParams
    from ..engine.classifier.pixel_classifier import PixelClassifier
    from ..engine.params import ParamSpec
    from .classifier_controls import ClassifierControls
    from .materials import MaterialList
    from .segment_files import ClassifierFiles, ResultExport
    from .segment_inputs import SegmentInputs
    from .segment_layers import SegmentLayers
    from .segment_params import ParameterControls
    from .session import LoadedClassifier, PipelineStore
    from .session.state import SegmentState


class SegmentMembers:
    """The Segment widget's public members (see the module's docstring)."""

    state: SegmentState
    controls: ParameterControls
    inputs: SegmentInputs
    layers: SegmentLayers
    classifier_files: ClassifierFiles
    export: ResultExport
    store: PipelineStore
    stack_layer: ComboBox

    def __getattr__(self, name: str) -> Any:
        """A parameter's control by the parameter's name (``widget.window``); else the
        Container's lookup of a child widget by name."""
        controls = self.__dict__.get("controls")
        if controls is not None and name in controls.controls:
            return controls.controls[name]
        return super().__getattr__(name)  # type: ignore[misc]

    # -- the parameters -----------------------------------------------------------------
    @property
    def preset(self) -> ComboBox:
        """The preset menu."""
        return self.controls.preset

    @property
    def thesis_maps(self) -> CheckBox:
        """The *thesis maps and error map* option."""
        return self.controls.thesis_maps

    @property
    def params_file(self) -> Container:
        """*Load parameters…* and *Save parameters…*."""
        return self.controls.params_file

    @property
    def load_button(self) -> PushButton:
        """*Load parameters…*."""
        return self.controls.load_button

    @property
    def save_button(self) -> PushButton:
        """*Save parameters…*."""
        return self.controls.save_button

    @property
    def controlled(self) -> tuple[str, ...]:
        """Names of the parameters with a control."""
        return tuple(self.controls.controlled)

    @property
    def param_specs(self) -> dict[str, ParamSpec]:
        """The spec of each controlled parameter."""
        return self.controls.param_specs

    def params(self) -> SegmentParams:
        """The engine parameters the controls describe (the state's; raises the
        PolarsegError of a bad value)."""
        return self.state.params

    def set_params(self, params: SegmentParams | None = None, **changes: Any) -> None:
        """Set the controls (:meth:`ParameterControls.set_params
        <napari_polarseg.widgets.segment_params.ParameterControls.set_params>`)."""
        self.controls.set_params(params, **changes)

    def save_params(self, path: str | Path) -> bool:
        """Write the parameters as JSON (``ParameterControls.save_params``)."""
        return self.controls.save_params(path)

    def load_params(self, path: str | Path) -> bool:
        """Set every control from a parameters file (``ParameterControls.load_params``)."""
        return self.controls.load_params(path)

    # -- the inputs ---------------------------------------------------------------------
    @property
    def mask_layer(self) -> ComboBox:
        """The mask chooser."""
        return self.inputs.mask_layer

    @property
    def scribbles_layer(self) -> ComboBox:
        """The scribbles chooser."""
        return self.inputs.scribbles_layer

    @property
    def materials(self) -> MaterialList:
        """The named materials of the chosen scribbles layer."""
        return self.inputs.materials

    @property
    def classifier_controls(self) -> ClassifierControls:
        """The classifier's features and model."""
        return self.inputs.classifier_controls

    @property
    def new_scribbles_button(self) -> PushButton:
        """*New scribbles layer*."""
        return self.inputs.new_scribbles_button

    def new_scribbles_layer(self, *_: Any) -> Labels | None:
        """A new, chosen scribbles layer (``SegmentInputs.new_scribbles_layer``)."""
        return self.inputs.new_scribbles_layer()

    def material_names(self) -> dict[int, str]:
        """Scribble value → material name (``SegmentInputs.material_names``)."""
        return self.inputs.material_names()

    # -- the results shown --------------------------------------------------------------
    @property
    def pipeline(self) -> Pipeline | None:
        """The cached pipeline of the chosen stack layer (None before its first run)."""
        layer = self.stack_layer.value
        return None if layer is None else self.store.get(source_key(layer))

    def pipeline_for(self, layer: Layer) -> Pipeline | None:
        """The cached pipeline of ``layer`` (None before its first run)."""
        return self.store.get(source_key(layer))

    @property
    def views(self) -> CheckBox:
        """The *HSV and Stokes layers* option."""
        return self.layers.views

    @property
    def view_mode(self) -> ComboBox:
        """The *HSV view* menu."""
        return self.layers.view_mode

    @property
    def probabilities(self) -> np.ndarray | None:
        """Class probabilities (K, H, W) of the last scribble run shown, else None."""
        return self.state.prediction.probabilities

    @property
    def classes(self) -> np.ndarray | None:
        """The scribble value of each class of :attr:`probabilities` (None: none)."""
        return self.state.prediction.classes

    @property
    def uncertainty(self) -> np.ndarray | None:
        """Uncertainty (H, W) of the last scribble run shown, else None."""
        return self.state.prediction.uncertainty

    # -- the classifier files and the export --------------------------------------------
    @property
    def classifier_file(self) -> Container:
        """*Load classifier…*, *Save classifier…* and *Clear*."""
        return self.classifier_files.classifier_file

    @property
    def load_classifier_button(self) -> PushButton:
        """*Load classifier…*."""
        return self.classifier_files.load_classifier_button

    @property
    def save_classifier_button(self) -> PushButton:
        """*Save classifier…*."""
        return self.classifier_files.save_classifier_button

    @property
    def clear_classifier_button(self) -> PushButton:
        """*Clear* (the loaded classifier)."""
        return self.classifier_files.clear_classifier_button

    @property
    def export_button(self) -> PushButton:
        """*Export results…*."""
        return self.export.export_button

    @property
    def loaded(self) -> LoadedClassifier | None:
        """The classifier *Load classifier…* read, while it is applied (the state's)."""
        return self.state.loaded

    @property
    def classifier(self) -> PixelClassifier | None:
        """The pixel classifier behind the chosen stack's segments (what *Save
        classifier…* writes)."""
        return self.classifier_files.classifier

    def shown_classifier(self, layer: Layer) -> PixelClassifier | None:
        """The pixel classifier behind ``layer``'s ``segments`` layer, if any."""
        return self.classifier_files.shown_classifier(layer)

    def load_classifier(self, path: str | Path) -> bool:
        """Read a classifier file in a worker and apply it (see ``ClassifierFiles``)."""
        return self.classifier_files.load_classifier(path)

    def save_classifier(self, path: str | Path) -> bool:
        """Write the chosen stack's pixel classifier (see ``ClassifierFiles``)."""
        return self.classifier_files.save_classifier(path)

    def clear_classifier(self, *_: Any) -> None:
        """Stop applying the loaded classifier (see ``ClassifierFiles``)."""
        self.classifier_files.clear_classifier()

    def export_results(
        self, folder: str | Path, *, overview: bool = True, plots: bool = False
    ) -> bool:
        """Write the chosen stack's last result into ``folder`` in a worker (the folder
        of ``polarseg segment --out``; see ``ResultExport.export_results``)."""
        return self.export.export_results(folder, overview=overview, plots=plots)
