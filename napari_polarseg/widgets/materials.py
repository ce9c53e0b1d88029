"""The Segment widget's material list: named scribble classes, as ilastik's label list.

:class:`MaterialList` shows the materials of the chosen scribbles layer (its painted
values and the brush's), each with a name and the colour swatch of the value (the
segments' palette, :func:`napari_polarseg.palette.label_rgba`): choosing one sets the
brush's label, *Add material* starts a new value, the name field renames the chosen one.
The names are kept in the layer's metadata (``"polarseg_materials"``: ``{"<value>":
name}``), so they stay with the strokes, and are handed to the classifier's result, its
file and the exported folder (:class:`~napari_polarseg.engine.materials.Materials`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from magicgui.widgets import ComboBox, Container, Label, LineEdit, PushButton

from ..engine.materials import clean_name, default_name
from ..palette import label_rgba
from .dock_layout import grow_with_entries

#: Metadata key of a scribbles layer holding its material names.
NAMES_KEY = "polarseg_materials"
#: Events of a Labels layer after which its painted values may differ.
PAINT_EVENTS = ("data", "paint", "labels_update")


def layer_names(layer: Any) -> dict[int, str]:
    """Value → name of the named materials kept in a scribbles layer's metadata (empty
    for None)."""
    if layer is None:
        return {}
    stored = layer.metadata.get(NAMES_KEY) or {}
    return {int(k): str(v) for k, v in stored.items()}


def swatch_style(value: int) -> str:
    """Qt style sheet of the swatch of scribble value ``value`` (its viewer colour)."""
    r, g, b, _ = (np.asarray(label_rgba([value])[0]) * 255).round().astype(int)
    return f"background-color: rgb({r}, {g}, {b}); border: 1px solid #888; min-width: 24px;"


class MaterialList(Container):
    """Named materials of a scribbles layer: pick the brush's, add, rename, see the colour.

    Parameters
    ----------
    changed : callable(), optional
        Called after a rename (e.g. to redraw what shows the names).
    """

    def __init__(self, changed: Callable[[], None] | None = None) -> None:
        self.layer: Any = None
        self._painted: set[int] | None = None  # the layer's painted values (kept)
        self._changed = changed
        self._syncing = False
        self.material = ComboBox(
            label="material",
            # a callable: the containers' reset_choices() asks it again
            choices=self._choices,
            tooltip="The material the brush paints (its scribble label): choosing one "
            "selects it in the scribbles layer",
        )
        self.swatch = Label(value="")
        self.swatch.tooltip = "The material's colour: its strokes, segments, plots and overview"
        self.name_edit = LineEdit(
            label="name",
            tooltip="The chosen material's name: shown in the status, kept with the "
            "classifier file, written to segments.csv and the overview's legend",
        )
        self.add_button = PushButton(
            text="Add material", tooltip="A new material (the next label) for the brush"
        )
        row = Container(
            layout="horizontal",
            widgets=[self.material, self.swatch, self.add_button],
            labels=False,
            label="material",
        )
        row.margins = (0, 0, 0, 0)
        super().__init__(widgets=[row, self.name_edit], labels=True, label="materials")
        self.margins = (0, 0, 0, 0)
        grow_with_entries(self.material.native)  # whole names: "3: banana"
        self.material.changed.connect(self._on_material)
        # renamed when the editing ends (Enter, focus out): not at every key
        self.name_edit.native.editingFinished.connect(self._on_name)
        self.add_button.changed.connect(self.add_material)

    # -- the layer ----------------------------------------------------------------------
    def set_layer(self, layer: Any) -> None:
        """Show the materials of the scribbles layer ``layer`` (None: none)."""
        old = self.layer
        if old is layer:
            self.refresh()
            return
        if old is not None:
            try:
                old.events.selected_label.disconnect(self._on_selected_label)
                for event in PAINT_EVENTS:
                    getattr(old.events, event).disconnect(self._on_painted)
            except (TypeError, ValueError, RuntimeError):
                pass
        self.layer, self._painted = layer, None
        if layer is not None:
            layer.events.selected_label.connect(self._on_selected_label)
            for event in PAINT_EVENTS:
                getattr(layer.events, event).connect(self._on_painted)
        self.refresh()

    def _on_painted(self, *_: Any) -> None:
        self._painted = None  # counted again when next asked

    def names(self) -> dict[int, str]:
        """Value → name of the named materials of the layer (empty without a layer)."""
        return layer_names(self.layer)

    def set_names(self, names: dict[int, str]) -> None:
        """Name the materials of ``names`` (value → name) in the layer, keeping others."""
        if self.layer is None:
            return
        merged = {**self.names(), **{int(k): clean_name(v, int(k)) for k, v in names.items()}}
        meta = {str(k): v for k, v in sorted(merged.items())}
        self.layer.metadata = {**self.layer.metadata, NAMES_KEY: meta}
        self.refresh()

    def adopt(self, names: dict[int, str]) -> None:
        """Take the names of ``names`` (e.g. a loaded classifier's) for the materials
        that have none yet."""
        own = self.names()
        new = {v: n for v, n in names.items() if v not in own and n != default_name(v)}
        if new:
            self.set_names(new)

    def name_of(self, value: int) -> str:
        return self.names().get(int(value), default_name(value))

    def values(self) -> list[int]:
        """The layer's materials: painted values, named ones and the brush's label."""
        if self.layer is None:
            return []
        if self._painted is None:  # the menu asks at every layer added: once per edit
            data = np.asarray(self.layer.data)
            self._painted = {int(v) for v in np.unique(data[data > 0])}  # the strokes only
        found = self._painted | set(self.names())
        selected = int(self.layer.selected_label)
        if selected > 0:
            found.add(selected)
        return sorted(found)

    # -- the controls -------------------------------------------------------------------
    def _choices(self, *_: Any) -> list[tuple[str, int]]:
        """The menu's entries: ``"<value>: <name>"`` of every material of the layer."""
        return [(f"{v}: {self.name_of(v)}", v) for v in self.values()]

    def refresh(self) -> None:
        """The menu, swatch and name of the layer's materials (the brush's chosen)."""
        self._syncing = True
        try:
            values = self.values()
            self.material.reset_choices()
            grow_with_entries(self.material.native)  # the longest name whole
            selected = None if self.layer is None else int(self.layer.selected_label)
            if selected in values:
                self.material.value = selected
            self._show_chosen()
            self.enabled = self.layer is not None
        finally:
            self._syncing = False

    def _show_chosen(self) -> None:
        value = self.material.value
        if value is None:
            self.swatch.native.setStyleSheet("")
            self.name_edit.value = ""
            return
        self.swatch.native.setStyleSheet(swatch_style(value))
        self.name_edit.value = self.names().get(int(value), "")

    def _on_material(self, value: Any) -> None:
        if self._syncing or value is None:
            return
        if self.layer is not None and int(self.layer.selected_label) != int(value):
            self.layer.selected_label = int(value)  # the brush paints this material
        self._show_chosen()

    def _on_selected_label(self, *_: Any) -> None:
        """The brush's label changed in napari's own controls: follow it."""
        try:
            self.refresh()
        except RuntimeError:  # the widget is gone
            pass

    def _on_name(self, *_: Any) -> None:
        if self._syncing or self.layer is None or self.material.value is None:
            return
        value = int(self.material.value)
        if self.name_edit.value.strip() != self.names().get(value, ""):
            self.rename(value, self.name_edit.value)

    def rename(self, value: int, name: str) -> None:
        """Call the material of scribble value ``value`` ``name``."""
        self.set_names({value: name})
        if self._changed is not None:
            self._changed()

    def add_material(self, *_: Any) -> int | None:
        """Start a new material: the next unused value, chosen for the brush."""
        if self.layer is None:
            return None
        value = max(self.values(), default=0) + 1
        self.layer.selected_label = value
        self.refresh()
        return value
