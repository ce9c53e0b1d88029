"""How the plugin's docks use their width: bounded, with a full-width status line.

- :data:`MAX_DOCK_WIDTH`: the widest a dock's controls ask to be. A menu of long entries
  (the methods' descriptions) asked for 756 px once *advanced settings* showed it, and
  the dock stayed that wide after they were hidden: :func:`shrink_menus` lets every menu
  shrink to :data:`MENU_CHARS` characters (its list still shows whole entries, and its
  tooltip the chosen one), and ``WidthFollower`` asks for no more than this width
  (wider controls scroll sideways).
- :func:`release_dock_minimum`: a dock widened by a section shown (*advanced
  settings*) can be narrowed again once the section is hidden.
- :func:`full_width_status`: the status line of a dock's footer starts at its left edge
  and wraps at its right one (it sat in a narrow centred column beside an empty label).
- :func:`title_dock`: the short, distinct title of a dock's tab (napari names a plugin's
  dock "<widget> (<plugin>)": two tabs read "Polari…").
"""

from __future__ import annotations

from typing import Any

from qtpy.QtCore import Qt
from qtpy.QtWidgets import QComboBox, QDockWidget, QLabel, QSizePolicy, QWidget

#: The widest (px) a plugin dock's controls ask the dock to be.
MAX_DOCK_WIDTH = 540
#: The minimum width (px) napari gives its docks.
DOCK_MINIMUM = 50
#: Characters a shrunk menu still shows.
MENU_CHARS = 18
#: Qt property marking a menu :func:`shrink_menus` has handled (or must leave alone).
SHRUNK = "polarseg_shrunk"


def shrink_menus(root: QWidget) -> None:
    """Let every menu (QComboBox) under ``root`` shrink to :data:`MENU_CHARS` characters
    instead of asking for its longest entry's width; its list widens to its entries and
    its tooltip follows the chosen entry. A menu with the property :data:`SHRUNK` set is
    left alone (e.g. the material menu, which grows with the names)."""
    for combo in root.findChildren(QComboBox):
        if combo.property(SHRUNK) is not None:
            continue
        combo.setProperty(SHRUNK, True)
        combo.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        combo.setMinimumContentsLength(MENU_CHARS)
        combo.currentTextChanged.connect(lambda _text, c=combo: whole_entries(c))
        whole_entries(combo)


def whole_entries(combo: QComboBox) -> None:
    """The menu's list as wide as its longest entry; the tooltip ends with the chosen
    entry when the menu is narrower than it."""
    view = combo.view()
    view.setMinimumWidth(view.sizeHintForColumn(0) + 2 * view.frameWidth() + 8)
    text = combo.currentText()
    tip = str(combo.property("polarseg_tip") or "")
    if combo.property("polarseg_tip") is None:
        tip = combo.toolTip()
        combo.setProperty("polarseg_tip", tip)
    clipped = combo.fontMetrics().horizontalAdvance(text) > combo.width() - 30
    combo.setToolTip(f"{tip}\n\nChosen: {text}" if clipped and text else tip)


def grow_with_entries(combo: QComboBox) -> None:
    """A menu at least as wide as its longest entry, taking the width its row leaves
    (the material menu: "3: banana", not "3: banan"); call again when its entries
    change."""
    combo.setProperty(SHRUNK, False)
    combo.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
    policy = combo.sizePolicy()
    policy.setHorizontalPolicy(QSizePolicy.Policy.Expanding)
    combo.setSizePolicy(policy)
    combo.setMinimumWidth(combo.sizeHint().width())


def full_width_status(status: QLabel) -> None:
    """The status line uses its footer's whole width, left-aligned and wrapped: the
    empty label magicgui puts before it in a labelled footer is hidden."""
    status.setWordWrap(True)
    status.setAlignment(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop)
    status.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
    status.setMinimumWidth(0)
    row = status.parentWidget()
    layout = None if row is None else row.layout()
    if layout is None:
        return
    for i in range(layout.count()):
        other = layout.itemAt(i).widget()
        if isinstance(other, QLabel) and other is not status and not other.text():
            other.hide()  # the empty label column before the status
    layout.setStretchFactor(status, 1)


def title_dock(frame: QWidget, title: str | None) -> QDockWidget | None:
    """Set the tab title of the dock holding ``frame`` to ``title`` (the dock, or None
    when ``frame`` is not docked)."""
    parent: Any = frame.parent()
    while parent is not None and not isinstance(parent, QDockWidget):
        parent = parent.parent()
    if parent is not None and title and parent.windowTitle() != title:
        parent.setWindowTitle(title)
    return parent


def release_dock_minimum(frame: QWidget) -> None:
    """Let the dock of ``frame`` be narrowed again to what its contents need now.

    napari sets its docks' minimum width, so Qt takes every minimum the dock's layout
    computed since for one the user set: shown once, a wide section (*advanced
    settings*) kept the dock at least that wide after it was hidden."""
    try:
        dock = title_dock(frame, None)
        if dock is not None:
            dock.setMinimumWidth(DOCK_MINIMUM)
    except RuntimeError:  # deleted meanwhile
        return
