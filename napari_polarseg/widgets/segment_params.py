"""The Segment widget's parameters: the preset, one control per labelled spec of the
parameter table, the thesis-maps option and the parameter files (*Load parameters…*,
*Save parameters…*), as one object the widget holds (:class:`ParameterControls`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from magicgui.widgets import CheckBox, ComboBox, Container, PushButton

from ..engine import PolarsegError, SegmentParams
from ..engine.params import (
    DEFAULT_PRESET,
    FINDS_K_METHODS,
    PARAM_SPECS,
    PRESET_HELP,
    PRESETS,
    ParamSpec,
    method_param_specs,
)
from ..engine.registered import computes_block_maps
from ..io import read_params_file
from ._base import ask_file
from .param_controls import control_label, controlled_names, method_controls, param_controls
from .session import wants_maps, write_params_json

if TYPE_CHECKING:
    from magicgui.widgets import Widget
    from magicgui.widgets.bases import ValueWidget
    from qtpy.QtWidgets import QWidget

    from .session.state import SegmentState

#: Tooltip of the preset menu: what a preset does to the controls, then each preset.
PRESET_TOOLTIP = (
    "Sets every parameter to a tested starting point; change any control afterwards.\n\n"
    + "\n".join(f"{name}: {text}" for name, text in PRESET_HELP.items())
)

#: Text of the option that adds the thesis maps and the error map to other methods' runs.
THESIS_MAPS_TEXT = "thesis maps and error map"

#: Controls of the normalized cut only: disabled while scribbles replace the cut.
CUT_ONLY = ("scale", "scale_mode", "clustering", "min_segment_blocks", "n_segments")


class ParameterControls:
    """The parameters of :class:`~napari_polarseg.widgets.segment.SegmentWidget`.

    The preset menu, the parameter-file buttons, one control per labelled spec of the
    shared table and of every registered method's own (:attr:`controls`, by parameter
    name; :attr:`owners`: the method of each method control) and the *thesis maps and
    error map* option (:attr:`thesis_maps`). Only the chosen method's own controls show
    (:meth:`show_method_controls`). :meth:`params` reads them, :meth:`set_params` sets
    them; :meth:`maps` says whether a run computes the thesis maps. Every change is
    written to the dock's state (``SegmentState.set_params``); the controls of the
    normalized cut follow the state's inputs (disabled while scribbles or a loaded
    classifier replace the cut: :data:`CUT_ONLY`).

    Parameters
    ----------
    specs : dict, optional
        The parameter table the controls are made from (default ``PARAM_SPECS``).
    state : SegmentState
        The dock's state: written on every change, its inputs followed.
    status, fail : callable
        The widget's status line (a text) and its error report (a PolarsegError).
    parent : callable() -> QWidget
        The widget file dialogs open over.
    """

    def __init__(
        self,
        specs: dict[str, ParamSpec] | None,
        state: SegmentState,
        status: Callable[[str], None],
        fail: Callable[[PolarsegError], None],
        parent: Callable[[], QWidget],
    ) -> None:
        self._status, self._fail, self._parent = status, fail, parent
        self._state = state
        d = PRESETS[DEFAULT_PRESET]
        self._base = d  # values of the fields without a control
        self._params_dir = Path.home()
        self.preset = ComboBox(
            label="preset",
            choices=list(PRESETS),
            value=DEFAULT_PRESET,
            tooltip=PRESET_TOOLTIP,
        )
        self.load_button = PushButton(
            text="Load parameters…",
            tooltip="Set every control from a parameters JSON file (as written by 'Save "
            "parameters…', or a params.json from polarseg segment)",
        )
        self.save_button = PushButton(
            text="Save parameters…",
            tooltip="Write the parameters as JSON, the format of polarseg segment --params",
        )
        self.params_file = Container(
            layout="horizontal",
            widgets=[self.load_button, self.save_button],
            labels=False,
            label="",
        )
        self.params_file.margins = (0, 0, 0, 0)
        #: The shared parameter table the controls are made from (one control per
        #: labelled spec), then each method's own (:attr:`owners`).
        self.param_specs = dict(specs or PARAM_SPECS)
        #: One control per labelled spec, by parameter name.
        self.controls: dict[str, ValueWidget] = param_controls(d.to_dict(), self.param_specs)
        #: The method whose own parameter each method control sets, by name.
        self.owners: dict[str, str] = {}
        for name, (method, control) in method_controls(d).items():
            if name not in self.controls:
                self.owners[name], self.controls[name] = method, control
                self.param_specs[name] = method_param_specs(method)[name]
        self.controlled = controlled_names(self.param_specs)
        self.controls["specular_branch"].visible = False
        self.thesis_maps = CheckBox(
            text=THESIS_MAPS_TEXT,
            value=False,
            tooltip="Also add the reconstruction-error layer and the maps the Polarisation "
            "plots draw when another method than thesis runs (slower).\n\nDetails: the "
            "thesis maps are the harmonic coefficients and PCA features (the plots' "
            "explained variance and component maps). Off: those runs compute none of them, "
            "and the error layer is removed. The thesis method always computes them",
        )
        self._maps_choice = False  # the option's value for the other methods
        self.parameter_widgets: list[Widget] = [self.controls[n] for n in self.controlled]
        self.preset.changed.connect(self._on_preset_changed)
        self.controls["model"].changed.connect(self._on_model_changed)
        if "method" in self.controls:
            self.controls["method"].changed.connect(self._on_method_changed)
            self._on_method_changed(self.controls["method"].value)
        else:
            self.show_method_controls(str(d.method))
        self.thesis_maps.changed.connect(self.on_maps_toggled)
        self.load_button.changed.connect(self._on_load_clicked)
        self.save_button.changed.connect(self._on_save_clicked)
        # after the handlers above: the state gets the values they leave
        for control in [*self.parameter_widgets, self.thesis_maps]:
            control.changed.connect(self.sync)
        state.inputs_changed.connect(self.follow_inputs)
        state.loaded_changed.connect(self.follow_inputs)
        self.sync()

    def sync(self, *_: Any) -> None:
        """Write the parameters (or the PolarsegError of a bad value) and whether a run
        computes the thesis maps to the dock's state."""
        try:
            params = self.params()
        except PolarsegError as exc:
            self._state.set_params(None, False, exc)
            return
        self._state.set_params(params, self.maps(params))

    def follow_inputs(self, *_: Any) -> None:
        """Enable the normalized cut's controls (:data:`CUT_ONLY`) only while neither
        scribbles nor a loaded classifier replace the unsupervised method."""
        state = self._state
        unsupervised = state.inputs.scribbles is None and state.loaded is None
        for name in CUT_ONLY:
            if name in self.controls:
                self.controls[name].enabled = unsupervised

    def maps(self, params: SegmentParams | None = None) -> bool:
        """Whether a run with ``params`` (default: the current ones) computes the thesis
        maps and the error map: always under the thesis method, else when the option is
        ticked."""
        params = params if params is not None else self.params()
        return wants_maps(params, self._maps_choice)

    def _on_method_changed(self, method: Any) -> None:
        """A method that declares ``block_maps`` (the thesis method) always computes the
        maps: the option shows them ticked and cannot be changed; another method gets
        the user's choice back. The segments box
        says "0 = auto" only under a method that finds the number itself."""
        if "n_segments" in self.controls:
            finds_k = str(method) in FINDS_K_METHODS
            spec = self.param_specs["n_segments"]
            self.controls["n_segments"].label = control_label("n_segments", spec, finds_k)
        box = self.thesis_maps
        if computes_block_maps(str(method)):
            if box.enabled:
                self._maps_choice = bool(box.value)
            box.enabled, box.value = False, True  # disabled first: not the user's choice
        elif not box.enabled:
            box.enabled, box.value = True, self._maps_choice
        self.show_method_controls(str(method))

    def on_maps_toggled(self, value: bool) -> None:
        """The option was ticked or unticked (under a method other than the thesis one)."""
        if self.thesis_maps.enabled:
            self._maps_choice = bool(value)
        method = self.controls["method"].value if "method" in self.controls else self._base.method
        self.show_method_controls(str(method))

    def show_method_controls(self, method: str) -> None:
        """Show the controls of ``method``'s own parameters and hide the other methods'
        (those of a method that computes the thesis maps stay while the maps are on:
        they set the maps)."""
        maps = bool(self.thesis_maps.value)
        for name, owner in self.owners.items():
            shown = owner == method or name in method_param_specs(method)
            self.controls[name].visible = shown or (maps and computes_block_maps(owner))

    def shown_method_controls(self) -> tuple[str, ...]:
        """Names of the method controls shown now (in the layout, whether or not the
        *advanced settings* are open)."""
        return tuple(n for n in self.owners if not self.controls[n].native.isHidden())

    # -- parameters -------------------------------------------------------------------
    def params(self) -> SegmentParams:
        """The engine parameters the widget's values describe (raises PolarsegError).

        Each method control sets its method's own parameter (whether shown or not:
        another method's values are kept for when it is chosen again). Parameters
        without a control (``ridge``, ``spatial_radius``, ``spatial_sigma``,
        ``ncut_threshold``, ``affinity_graph``) come from the chosen preset or the last
        :meth:`set_params`. A float set with more decimals than its control shows (e.g.
        ``refractive_index`` 1.4537 from a file, shown as 1.454) is kept exactly until
        the control is changed.
        """
        values: dict[str, Any] = {}
        own: dict[str, dict[str, Any]] = {}
        for name in self.controlled:
            spec, shown = self.param_specs[name], self.controls[name].value
            owner = self.owners.get(name)
            if spec.options() is not None:
                value: Any = str(shown)
            elif spec.decimals is None:
                value = int(shown)
            else:  # the control shows spec.decimals decimals of the exact value
                exact = float(self._value(self._base, name))
                tolerance = 0.5 * 10.0**-spec.decimals + 1e-12
                value = exact if abs(exact - float(shown)) <= tolerance else float(shown)
            if owner is None:
                values[name] = value
            else:
                own.setdefault(owner, {})[name] = value
        stored = {m: replace(self._base.params_of(m), **v) for m, v in own.items()}
        merged = {**self._base.method_params, **stored}
        return self._base.replace(method_params=merged, **values)

    def _value(self, params: SegmentParams, name: str) -> Any:
        """The value of the control ``name`` in ``params`` (a method control: its
        method's own parameter)."""
        owner = self.owners.get(name)
        return getattr(params if owner is None else params.params_of(owner), name)

    def set_params(self, params: SegmentParams | None = None, **changes: Any) -> None:
        """Set the controls from ``params`` and/or keyword changes (SegmentParams names).

        Validated first, also against the controls' ranges (raises PolarsegError and
        changes nothing); with live update on, the burst of changes triggers one run.
        """
        values = (params or self.params()).replace(**changes)
        self._check_controls(values)
        self._base = values
        for name in self.controlled:
            self.controls[name].value = self._value(values, name)
        self.sync()  # also when no control changed (a field without one did)

    def _check_controls(self, values: SegmentParams) -> None:
        """Raise PolarsegError if a value does not fit its control (range, menu)."""
        for name in self.controlled:
            control, value = self.controls[name], self._value(values, name)
            if isinstance(control, ComboBox):
                if value not in control.choices:
                    raise PolarsegError(f"{name} {value!r} is not offered by the widget")
            elif not control.min <= value <= control.max:
                raise PolarsegError(
                    f"{name} {value} is outside the widget's range {control.min:g}..{control.max:g}"
                )

    def _on_preset_changed(self, name: str) -> None:
        self.set_params(PRESETS[name])

    def _on_model_changed(self, model: str) -> None:
        self.controls["specular_branch"].visible = model == "specular"

    def save_params(self, path: str | Path) -> bool:
        """Write the current parameters to ``path`` as JSON (``SegmentParams.to_json``).

        The format of ``polarseg segment --params`` (and of *Load parameters…*, the
        batch widget's JSON file). Problems go to the status line and a notification;
        returns whether the file was written.
        """
        path = Path(path)
        try:
            write_params_json(path, self.params())
        except PolarsegError as exc:
            self._fail(exc)
            return False
        except OSError as exc:
            reason = exc.strerror or str(exc)
            self._fail(PolarsegError(f"{path}: cannot write the parameters file ({reason})"))
            return False
        self._params_dir = path.parent
        self._status(f"saved the parameters to {path}")
        return True

    def load_params(self, path: str | Path) -> bool:
        """Set every control from a parameters JSON file (see :func:`read_params_file`).

        Missing fields take their defaults (:meth:`SegmentParams.from_dict`).
        Invalid JSON, an unknown field or a value out of range leave every control as it
        was and are reported in the status line (and a notification); returns whether
        the parameters were loaded. With live update on, loading triggers one run.
        """
        path = Path(path)
        try:
            params = read_params_file(path)
            try:
                self.set_params(params)
            except PolarsegError as exc:
                raise PolarsegError(f"{path}: {exc}") from None
        except PolarsegError as exc:
            self._fail(exc)
            return False
        self._params_dir = path.parent
        self._status(f"loaded the parameters from {path}")
        return True

    def ask_path(self, save: bool) -> str | None:
        """A parameters file chosen in a Qt dialog (None when cancelled)."""
        filters = "JSON (*.json);;All files (*)"
        if save:
            start = str(self._params_dir / "params.json")
            return ask_file(self._parent(), "Save parameters", start, filters, save=True)
        return ask_file(self._parent(), "Load parameters", str(self._params_dir), filters)

    def _on_save_clicked(self, *_: Any) -> None:
        path = self.ask_path(save=True)
        if path:
            self.save_params(path if Path(path).suffix else f"{path}.json")

    def _on_load_clicked(self, *_: Any) -> None:
        path = self.ask_path(save=False)
        if path:
            self.load_params(path)
