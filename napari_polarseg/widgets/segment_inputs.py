"""The Segment widget's inputs beside the stack: the mask and scribbles layers (and the
edits painted into them), and the :class:`Snapshot` of everything a result depends on."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from magicgui.widgets import PushButton
from napari.layers import Labels

from ..engine import PolarsegError, SegmentParams
from ..engine.chunks import in_background
from ..io import parse_angles
from ._layers import MATERIAL_COLUMN, find_output, label_colormap, name_labels, source_key
from .classifier_controls import ClassifierControls
from .materials import MaterialList
from .session import (
    ClassifierOutput,
    LoadedClassifier,
    PipelineStore,
    content_digest,
    named_output,
    region_digest,
)
from .session.state import Inputs, SegmentState

#: Text of the "mask" menu entry that segments every pixel.
NO_MASK = "none"

#: Text of the "scribbles" menu entry that segments without supervision (normalized cut).
NO_SCRIBBLES = "none (unsupervised)"

#: Layer events that mean the user edited a Labels layer: a brush, fill or eraser stroke
#: (``paint``), new data (``data``), undo/redo and other refreshes (``set_data``).
EDIT_EVENTS = ("paint", "data", "set_data")


@dataclass(frozen=True)
class Snapshot:
    """Everything a Segment-widget result depends on (compared to tell whether a result
    still matches the controls, or whether a live update has anything to run).

    Attributes
    ----------
    stack_key : str or None
        The chosen stack layer (``source_key``).
    angles : str
        The angles field as typed.
    params : SegmentParams
        The parameters.
    mask_key, mask_digest : str or None
        The mask layer and a digest of its region.
    scribbles_key, scribbles_digest : str or None
        The scribbles layer and a digest of its strokes.
    classifier_serial : int or None
        Which *Load classifier…* is applied (None: none).
    maps : bool
        Whether the run computes the thesis maps and the error map.
    classifier_settings : ClassifierSettings or None
        The features and model a training uses (None: a value is bad).
    """

    stack_key: str | None
    angles: str
    params: SegmentParams
    mask_key: str | None
    mask_digest: str | None
    scribbles_key: str | None
    scribbles_digest: str | None
    classifier_serial: int | None
    maps: bool
    classifier_settings: Any = None

    def differs_only_in_params(self, other: Snapshot) -> tuple[str, ...] | None:
        """The parameters that differ (shared fields and methods' own, by name) when
        nothing else does (None otherwise)."""
        same = all(
            getattr(self, f.name) == getattr(other, f.name)
            for f in fields(self)
            if f.name != "params"
        )
        if not same:
            return None
        return self.params.changed_names(other.params)


class SegmentInputs:
    """The Segment widget's inputs beside the stack, a part the widget holds
    (``widget.inputs``): the mask and scribbles choosers, the named materials, the
    classifier settings, *New scribbles layer*, the edits painted into the chosen
    layers, and the :class:`Snapshot` of everything a result depends on.

    It writes the chosen mask and scribbles layers to the dock's state
    (``SegmentState.set_inputs``) and follows the state's inputs: it listens to the
    edits of the chosen layers (:meth:`sync_watches`; an edit is
    ``SegmentState.mark_edited``), lists the chosen scribbles' materials and computes a
    newly chosen stack's polarisation image in the background
    (:meth:`prefetch_polarisation`). The snapshot reads the parameters, the stack, the
    angles and the loaded classifier from the state.

    Parameters
    ----------
    state : SegmentState
        The dock's state.
    viewer : napari.viewer.Viewer
    store : PipelineStore
        The widget's pipelines (the background polarisation image goes there).
    labels_box : callable(label, none, tooltip) -> ComboBox
        Makes a chooser of the Labels layers that fit the stack.
    set_status, fail : callable
        The widget's status line.
    prefetch_features : callable(force=True)
        Starts computing the chosen stack's pixel features (*New scribbles layer*).
    """

    def __init__(
        self,
        state: SegmentState,
        viewer: Any,
        store: PipelineStore,
        labels_box: Callable[[str, str, str], Any],
        set_status: Callable[[str], None],
        fail: Callable[[PolarsegError], None],
        prefetch_features: Callable[..., None],
    ) -> None:
        self._state, self._viewer, self._store = state, viewer, store
        self._set_status, self._fail = set_status, fail
        self._prefetch_features = prefetch_features
        #: The layers whose edits are listened to, by role (``mask``, ``scribbles``).
        self.watched: dict[str, Any] = {"mask": None, "scribbles": None}
        self.mask_layer = labels_box(
            "mask",
            NO_MASK,
            "Segment only where this Labels layer is non-zero (same height x width as the "
            "stack); saturated and black samples are left out in any case",
        )
        self.scribbles_layer = labels_box(
            "scribbles",
            NO_SCRIBBLES,
            "Paint a few strokes on each material and every pixel gets the material it "
            "resembles most: the segments follow your strokes.\n\nDetails: a Labels "
            "layer of the stack's height x width (0 = unlabelled, 1, 2, … = materials, at "
            "least two); a pixel classifier (extremely randomised trees on multi-scale "
            "polarisation features) trained on the scribbled pixels replaces the "
            "unsupervised method; "
            "with live update every stroke retrains it",
        )
        #: The named materials of the chosen scribbles layer (brush class, swatch, name).
        self.materials = MaterialList(changed=self._on_materials_renamed)
        #: The classifier's features and model (advanced section).
        self.classifier_controls = ClassifierControls()
        self.new_scribbles_button = PushButton(
            text="New scribbles layer",
            tooltip="Add an empty Labels layer of the stack's size, choose it as the "
            "scribbles and start the paint brush: paint label 1 on one material, 2 on "
            "another, …",
        )
        self.mask_layer.changed.connect(self.write_choices)
        self.scribbles_layer.changed.connect(self.write_choices)
        self.new_scribbles_button.changed.connect(self.new_scribbles_layer)
        state.inputs_changed.connect(self._on_inputs_changed)
        self.write_choices()

    def write_choices(self, *_: Any) -> None:
        """Write the chosen mask and scribbles layers to the dock's state."""
        self._state.set_inputs(mask=self.mask_layer.value, scribbles=self.scribbles_layer.value)

    def _on_inputs_changed(self, new: Inputs, old: Inputs) -> None:
        """The state's inputs changed: listen to the chosen layers' edits, list the
        scribbles' materials, and compute a new stack's polarisation image."""
        self.sync_watches()
        if new.scribbles is not old.scribbles:
            self.on_scribbles_changed()
        if new.stack is not old.stack:
            self.prefetch_polarisation()

    def prefetch_polarisation(self, *_: Any) -> None:
        """Compute the chosen stack's polarisation image, which every method reads, on a
        background thread as soon as the stack is chosen: a run, or the scribbles'
        features, started meanwhile waits for it on the pipeline's lock."""
        state = self._state
        layer = state.inputs.stack
        try:
            if layer is None:
                return
            angles_deg = parse_angles(state.inputs.angles, option=None)
            mask_key, region = self.current_mask()
            params = state.params
        except PolarsegError:
            return  # nothing to compute yet; a run says why
        store, key, data, angles = self._store, source_key(layer), layer.data, angles_deg
        if store.needs_reading(key, data):
            return  # a stack shown from disk is read whole by a run, not on choosing it

        def polarisation() -> None:
            rad = np.deg2rad(angles)
            pipe = store.obtain(key, data, rad, params, region=region, mask_key=mask_key)
            pipe.get("polarisation", params)

        in_background(polarisation)  # its errors are the run's to report

    def unwatch(self, *_: Any) -> None:
        """Stop listening to the edits of the watched layers and the material list's
        layer (the widget is closed; :meth:`sync_watches` connects nothing once the
        state is closed)."""
        for layer in self.watched.values():
            disconnect_edits(layer, self._on_layer_edited)
        self.watched.clear()
        with contextlib.suppress(RuntimeError):  # its Qt widgets were deleted
            self.materials.set_layer(None)  # disconnected first, then redrawn

    # -- mask and scribbles -----------------------------------------------------------
    def current_mask(self) -> tuple[str | None, np.ndarray | None]:
        """Key and (H, W) bool region (a copy; True = use) of the chosen mask, or Nones."""
        layer = self._chosen(self.mask_layer, "mask")
        if layer is None:
            return None, None
        return source_key(layer), np.asarray(layer.data) != 0

    def current_scribbles(self) -> tuple[str | None, np.ndarray | None]:
        """Key and (H, W) labels (a copy) of the chosen scribbles layer, or Nones."""
        layer = self._chosen(self.scribbles_layer, "scribbles")
        if layer is None:
            return None, None
        return source_key(layer), np.array(layer.data, copy=True)

    def _chosen(self, chooser: Any, role: str) -> Any:
        """The layer ``chooser`` names (None for none); raises PolarsegError when it has
        been removed from the viewer."""
        layer = chooser.value
        if layer is not None and layer not in self._viewer.layers:
            raise PolarsegError(f"the {role} layer {layer.name!r} is no longer in the viewer")
        return layer

    def reset_choices(self) -> None:
        """The choosers list the Labels layers that fit the chosen stack now."""
        self.mask_layer.reset_choices()
        self.scribbles_layer.reset_choices()

    def new_scribbles_layer(self, *_: Any) -> Labels | None:
        """Add an empty Labels layer for strokes, choose it and start the paint brush.

        Named ``"<stack> scribbles"``, of the stack's height x width (and placement),
        selected in the layer list with the paint tool on label 1.
        """
        stack = self._state.inputs.stack
        if stack is None:
            self._fail(PolarsegError("choose an angle-stack image layer first"))
            return None
        if stack.ndim != 3:  # a raw mosaic frame: strokes go on the stack decoded from it
            self._fail(
                PolarsegError(
                    "press Run first: it decodes the raw mosaic frame into "
                    "the angle-stack layer the strokes are painted on"
                )
            )
            return None
        self._prefetch_features(force=True)  # started before napari adds the layer
        h, w = stack.data.shape[-2:]
        layer = self._viewer.add_labels(
            np.zeros((h, w), dtype=np.int32),
            name=f"{stack.name} scribbles",
            colormap=label_colormap(),  # the segments' colours: a stroke and its segment match
            scale=tuple(stack.scale[-2:]),
            translate=tuple(stack.translate[-2:]),
        )
        self.scribbles_layer.reset_choices()
        self.scribbles_layer.value = layer
        layer.selected_label = 1
        self.materials.set_layer(layer)
        self._viewer.layers.selection.active = layer
        layer.mode = "paint"
        self._set_status(
            f"paint strokes into {layer.name!r}: label 1 on one material, 2 on another, … "
            "(at least 2), then Run (or tick live update)"
        )
        return layer

    def material_names(self) -> dict[int, str]:
        """Scribble value → name of the chosen scribbles layer's named materials."""
        return self.materials.names()

    def named(self, result: Any) -> Any:
        """``result`` with its materials named, when it is a classifier's output: the
        loaded classifier's names name the strokes' materials that have none yet, and
        the list's names name the result (its plots, export, saved classifier)."""
        if not isinstance(result, ClassifierOutput) or result.segmentation is None:
            return result
        materials = result.classifier.materials()
        self.materials.adopt(dict(zip(materials.values, materials.names, strict=True)))
        return named_output(result, self.material_names())

    def _on_materials_renamed(self) -> None:
        """A material was renamed: the status line says so, the segments shown name it
        on hover (the names reach the next export, saved classifier and result)."""
        names = self.material_names()
        self._set_status("renamed: " + ", ".join(f"{v} {n}" for v, n in names.items()))
        stack = self._state.inputs.stack
        segments = None if stack is None else find_output(self._viewer, "segments", stack)
        if segments is not None and MATERIAL_COLUMN in segments.features:  # names on hover
            table = segments.features
            shown = dict(zip(table["index"].astype(int), table[MATERIAL_COLUMN], strict=True))
            name_labels(segments, {v: names.get(v, n) for v, n in shown.items()})

    def on_scribbles_changed(self, *_: Any) -> None:
        """Another scribbles layer is chosen (or its names may have changed): its
        materials are listed (none once the dock is closed)."""
        if not self._state.is_closed:
            self.materials.set_layer(self.scribbles_layer.value)

    def sync_watches(self, *_: Any) -> None:
        """Listen to edits of the chosen mask and scribbles layers (and no others;
        none once the dock is closed)."""
        if self._state.is_closed:
            return
        for role, chooser in (("mask", self.mask_layer), ("scribbles", self.scribbles_layer)):
            old, new = self.watched.get(role), chooser.value
            if old is new:
                continue
            if old is not None and old not in self._watched_except(role):
                disconnect_edits(old, self._on_layer_edited)
            if new is not None and new not in self._watched_except(role):
                for name in EDIT_EVENTS:
                    getattr(new.events, name).connect(self._on_layer_edited)
            self.watched[role] = new

    def _watched_except(self, role: str) -> list[Any]:
        return [layer for r, layer in self.watched.items() if r != role and layer is not None]

    def _on_layer_edited(self, *_: Any) -> None:
        """A stroke (or undo, new data) in the chosen mask or scribbles layer."""
        try:
            self._state.mark_edited()
        except RuntimeError:  # the widget was deleted
            pass

    # -- what a result depends on -----------------------------------------------------
    def snapshot(self) -> Snapshot | None:
        """Everything a result depends on, or None if the values are invalid."""
        try:
            params = self._state.params
            mask_key, region = self.current_mask()
            scribble_key, scribbles = self.current_scribbles()
        except PolarsegError:
            return None
        return self.snapshot_of(params, mask_key, region, scribble_key, scribbles)

    def snapshot_of(
        self,
        params: SegmentParams,
        mask_key: str | None,
        region: np.ndarray | None,
        scribble_key: str | None,
        scribbles: np.ndarray | None,
    ) -> Snapshot:
        """The :class:`Snapshot` of these values (read once by the caller) and the
        state's stack, angles, applied classifier and thesis maps, and the settings."""
        state = self._state
        layer = state.inputs.stack
        key = None if layer is None else source_key(layer)
        digest = content_digest(scribbles)
        loaded = self.applied(scribble_key, digest)
        return Snapshot(
            stack_key=key,
            angles=state.inputs.angles,
            params=params,
            mask_key=mask_key,
            mask_digest=region_digest(region),
            scribbles_key=scribble_key,
            scribbles_digest=digest,
            classifier_serial=None if loaded is None else loaded.serial,
            maps=state.maps,
            classifier_settings=self.classifier_controls.settings_or_none(),
        )

    def applied(self, scribble_key: str | None, digest: str | None) -> LoadedClassifier | None:
        """The loaded classifier if it still applies (the strokes are as when loaded)."""
        loaded = self._state.loaded
        if loaded is None or loaded.strokes != (scribble_key, digest):
            return None
        return loaded


def disconnect_edits(layer: Any, callback: Any) -> None:
    """Stop calling ``callback`` on the edit events (:data:`EDIT_EVENTS`) of ``layer``."""
    if layer is None:
        return
    for name in EDIT_EVENTS:
        with contextlib.suppress(Exception):
            getattr(layer.events, name).disconnect(callback)
