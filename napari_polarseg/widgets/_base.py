"""What the widgets share: docks that scroll, the angle-stack chooser, the angles field,
Run/Cancel, status."""

from __future__ import annotations

import contextlib
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from magicgui.widgets import ComboBox, Container, Label, LineEdit, ProgressBar, PushButton
from napari.layers import Image, Labels
from napari.utils.notifications import show_error
from qtpy.QtCore import QEvent, QObject, Qt, QTimer
from qtpy.QtWidgets import QDockWidget, QMainWindow, QScrollArea, QVBoxLayout, QWidget

from ..engine import PolarsegError
from ..io import parse_angles
from ._layers import ANGLES_KEY, find_output, layer_tag, source_key
from ._runner import PROGRESS_STEPS, WorkerSlot
from .angle_axis import AngleLabel
from .dims_guard import guard_viewer
from .dock_layout import MAX_DOCK_WIDTH, full_width_status, shrink_menus, title_dock
from .layer_queue import LayerQueue
from .raw_mosaic import RAW_MOSAIC_SUFFIX, is_raw_mosaic
from .session import format_angles
from .view_fit import FitKeeper
from .warm import warm_imports

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer


def is_angle_stack(layer: Layer) -> bool:
    """True for an image layer that can be an angle stack (3-D, grey, not our output)."""
    return (
        isinstance(layer, Image)
        and not layer.rgb
        and not layer.multiscale
        and layer.ndim == 3
        and layer_tag(layer) is None
    )


def ask_file(
    parent: QWidget, title: str, start: str, filters: str, save: bool = False
) -> str | None:
    """A file chosen in a Qt dialog, to save or to open (None when cancelled)."""
    from qtpy.QtWidgets import QFileDialog

    ask = QFileDialog.getSaveFileName if save else QFileDialog.getOpenFileName
    path, _ = ask(parent, title, start, filters)
    return path or None


@runtime_checkable
class ClassifierListener(Protocol):
    """A docked widget that wants each new pixel classifier of a stack (the
    *Polarisation plots* widget shows its feature importances). The Segment widget hands
    it over without importing the listener's module, so the two do not import each
    other."""

    def set_classifier(self, layer: Any, classifier: Any) -> None: ...


class WidthFollower(QObject):
    """Keeps a vertical scroll area at least as wide as the widget it scrolls.

    magicgui sets the area's minimum width when a control is added, before it widens the
    label column (and a section shown later widens the controls again): the area then
    cut off the right edge of the controls. This follows every layout change instead.
    """

    def __init__(self, area: QScrollArea) -> None:
        super().__init__(area)
        self._area = area
        area.widget().installEventFilter(self)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:  # noqa: N802 (Qt)
        if event.type() == QEvent.Type.LayoutRequest:
            self.fit()
        return False

    def fit(self) -> None:
        """Set the area's minimum width to its widget's plus the vertical scroll bar, at
        most :data:`~.dock_layout.MAX_DOCK_WIDTH` (its menus shrink first:
        :func:`~.dock_layout.shrink_menus`; wider controls scroll sideways)."""
        shrink_menus(self._area.widget())
        bar = self._area.verticalScrollBar().sizeHint().width()
        frame = 2 * self._area.frameWidth()
        wanted = self._area.widget().minimumSizeHint().width() + bar + frame
        self._area.setMinimumWidth(min(wanted, MAX_DOCK_WIDTH))


#: Object name of every plugin dock's frame (:class:`ScrollingContainer`), and of the
#: Segment dock's (the one the others open tabbed with, when it is open).
DOCK_NAME, SEGMENT_DOCK_NAME = "napari_polarseg_dock", "napari_polarseg_segment_dock"


def _dock_of(widget: QWidget) -> QDockWidget | None:
    """The QDockWidget holding ``widget``, if any."""
    parent = widget.parent()
    while parent is not None and not isinstance(parent, QDockWidget):
        parent = parent.parent()
    return parent


class DockTabber(QObject):
    """Opens a plugin dock as a tab of the plugin's docks already open (the Segment dock
    first), in place of a slice of their height.

    napari stacks each dock the Plugins menu opens below the others: with every dock of
    the plugin open, each got a sixth of the window's height. Once the frame is put in a
    dock, the next event-loop turn (the dock is then in its window) tabifies it.
    """

    def __init__(self, frame: QWidget, title: str = "") -> None:
        super().__init__(frame)
        self._frame, self._title = frame, title
        frame.installEventFilter(self)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:  # noqa: N802 (Qt)
        if event.type() == QEvent.Type.ParentChange:
            QTimer.singleShot(0, self.tabify)
        return False

    def tabify(self) -> None:
        """Give the frame's dock its short tab title (:func:`~.dock_layout.title_dock`),
        and tabify it with the first plugin dock in the same window area."""
        try:
            dock = title_dock(self._frame, self._title)
            window = None if dock is None else dock.parentWidget()
        except RuntimeError:  # deleted meanwhile
            return
        if not isinstance(window, QMainWindow) or dock.isFloating():
            return
        area = window.dockWidgetArea(dock)
        others = [
            d
            for d in window.findChildren(QDockWidget)
            if d is not dock
            and not d.isHidden()  # closed (a hidden window's docks count)
            and not d.isFloating()
            and window.dockWidgetArea(d) == area
            and (d.findChild(QWidget, DOCK_NAME) or d.findChild(QWidget, SEGMENT_DOCK_NAME))
        ]
        if not others or dock in window.tabifiedDockWidgets(others[0]):
            return
        others.sort(key=lambda d: d.findChild(QWidget, SEGMENT_DOCK_NAME) is None)
        window.tabifyDockWidget(others[0], dock)
        dock.show()
        dock.raise_()


class CloseWatcher(QObject):
    """Calls ``closed`` when a dock's frame is closed: ``close()`` (a Close event), or
    taken out of its dock (napari's ✕ removes the dock and leaves the frame, still
    alive, without a parent). The frame's ``destroyed`` signal is the widget's to
    connect (a plain function: this watcher is deleted with the frame)."""

    def __init__(self, frame: QWidget, closed: Callable[[], None]) -> None:
        super().__init__(frame)
        self._frame, self._closed = frame, closed
        self._docked = frame.parent() is not None
        frame.installEventFilter(self)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:  # noqa: N802 (Qt)
        kind = event.type()
        if kind == QEvent.Type.Close:
            self._closed()
        elif kind == QEvent.Type.ParentChange:
            docked = self._frame.parent() is not None
            if self._docked and not docked:
                self._closed()
            self._docked = docked
        return False


class ScrollingContainer(Container):
    """A labelled vertical Container whose controls scroll when its dock is too short,
    with a footer that never scrolls.

    napari docks a magicgui widget's ``native`` (``add_dock_widget`` of napari 0.9 has no
    scroll option), and magicgui's ``scrollable=True`` puts the widget holding the
    controls' layout inside a ``QScrollArea``, its ``root_native_widget``. Here ``native``
    is a frame holding that scroll area (:attr:`scroll_area`) and, below it, the footer
    (:meth:`add_footer`: Run, Cancel, progress, status), so napari docks the frame: the
    window's minimum height no longer grows with the controls, and however short the dock
    the footer stays in view. :attr:`content` is the widget with the controls' layout
    (where a subclass adds plain Qt widgets such as a plot canvas).
    """

    #: The dock's tab title: short, and distinct from the other docks' first letters.
    dock_title = ""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(scrollable=True, **kwargs)
        # controls wider than MAX_DOCK_WIDTH scroll sideways (magicgui: never)
        self.scroll_area.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAsNeeded)
        # the scroll area stretches the controls' widget to its height: a stretch below
        # them keeps them packed at the top (napari adds one to a dock that does not scroll)
        self.content.layout().addStretch(1)
        self._frame = QWidget()
        frame_layout = QVBoxLayout(self._frame)
        frame_layout.setContentsMargins(0, 0, 0, 0)
        frame_layout.setSpacing(0)
        frame_layout.addWidget(self.root_native_widget, 1)
        self._frame.setObjectName(DOCK_NAME)
        self._frame._magic_widget = self  # type: ignore[attr-defined] (as magicgui's native)
        self._tabber = DockTabber(self._frame, self.dock_title)
        self._width = WidthFollower(self.scroll_area)

    @property
    def native(self) -> QWidget:
        """The frame of the scroll area and the footer: the widget napari docks (the
        scroll area while magicgui's ``__init__`` runs)."""
        frame = vars(self).get("_frame")
        return self.root_native_widget if frame is None else frame

    def close(self) -> None:
        """Close the frame napari docks (magicgui's ``close`` closes the scroll area
        only), then the controls."""
        self._frame.close()
        super().close()

    @property
    def scroll_area(self) -> QScrollArea:
        """The scroll area around the controls."""
        return self.root_native_widget

    @property
    def content(self) -> QWidget:
        """The widget inside the scroll area that holds the controls' layout."""
        return self.root_native_widget.widget()

    def add_footer(self, widgets: list[Any]) -> Container:
        """A labelled Container of ``widgets`` below the scroll area (always in view)."""
        footer = Container(widgets=widgets, labels=True)
        self._frame.layout().addWidget(footer.native)
        for widget in widgets:  # the status line: the footer's whole width
            if isinstance(widget, Label) and not widget.label:
                full_width_status(widget.native)
        return footer

    def add_native(self, widget: QWidget, expand: bool = False) -> None:
        """Add a plain Qt ``widget`` below the controls (add every magicgui widget first).

        With ``expand`` it takes the height the controls leave (a plot canvas) in place of
        the stretch that packs them at the top; widgets added after it follow it.
        """
        layout = self.content.layout()
        last = layout.count() - 1
        packed = last >= 0 and layout.itemAt(last).spacerItem() is not None
        if packed and expand:
            layout.takeAt(last)
            layout.addWidget(widget, 1)  # the only stretch: the controls keep their height
        elif packed:
            layout.insertWidget(last, widget)
        else:
            layout.addWidget(widget)


class StackWidget(ScrollingContainer):
    """Base of the plugin's widgets: stack layer, polariser angles, Run, Cancel, status.

    Subclasses add their parameter widgets with :meth:`_add_parameters`, implement
    :meth:`run`, and call :meth:`_submit` with an engine job.
    """

    #: Text of the Run button.
    run_text = "Run"
    #: Tooltip of the Run button: what a run computes and where it shows.
    run_tooltip = "Run the computation on the chosen angle stack in the background"
    #: Description of the progress bar.
    progress_desc = "napari-polarseg"
    #: Whether the stack chooser lists raw mosaic frames too (the Segment dock decodes
    #: them: :class:`~.raw_mosaic.MosaicInput`).
    lists_raw_mosaics = False

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(labels=True)
        self._viewer = viewer
        self.stack_layer = ComboBox(
            label="angle stack",
            choices=self._stack_choices,
            nullable=True,
            tooltip="Image layer holding the angle stack (angles, rows, columns)",
        )
        self.angles = LineEdit(
            label="angles (deg)",
            tooltip="Polariser angle of each frame in degrees, comma-separated; "
            f"filled from the layer's metadata[{ANGLES_KEY!r}] when present",
        )
        self.run_button = PushButton(text=self.run_text, tooltip=self.run_tooltip)
        self.cancel_button = PushButton(
            text="Cancel",
            enabled=False,
            tooltip="Stop the running computation (within about a second); what was "
            "shown before stays",
        )
        #: stages of the current (or last) run done, PROGRESS_STEPS ticks each (a long
        #: stage moves it as it goes); long runs also show in napari's activity dock
        #: (see ``_runner.ACTIVITY_DELAY``)
        self.progress = ProgressBar(label="progress", value=0, min=0, max=1)
        self.status = Label(value="")
        self.extend([self.stack_layer, self.angles])
        #: Run, Cancel, progress and status, below the scrolling controls
        self.footer = self.add_footer(
            [self.run_button, self.cancel_button, self.progress, self.status]
        )
        self._slot = WorkerSlot(
            self.progress_desc,
            on_status=self._set_status,
            on_idle=self._on_idle,
            on_progress=self._set_progress,
        )

        guard_viewer(viewer)  # deleting the stack after a Run must not crash napari
        self.stack_layer.changed.connect(self._on_stack_changed)
        self.run_button.changed.connect(self.run)
        self.cancel_button.changed.connect(self.cancel)
        events = viewer.layers.events
        events.inserted.connect(self._on_layers_changed)
        events.removed.connect(self._on_layers_changed)
        #: A result's secondary layers, added one per event-loop turn (the window
        #: freezes for one layer at most).
        self._later = LayerQueue(self.native)
        #: Fits the view again when the dock narrows the canvas under a fitted view.
        self._fit = FitKeeper(viewer)
        #: Shows the polariser angle of the frame shown beside the angle slider.
        self._angle_label = AngleLabel(viewer)
        self._closed = False
        this = weakref.ref(self)

        def _closed(*_: Any) -> None:
            widget = this()
            if widget is not None:
                widget.on_closed()

        self._close_watcher = CloseWatcher(self.native, _closed)
        self.native.destroyed.connect(_closed)
        self._on_layers_changed()
        warm_imports()  # the plot docks and the first segments find them imported

    @property
    def closed(self) -> bool:
        """True once the dock was closed (:meth:`on_closed`)."""
        return self._closed

    def on_closed(self) -> None:
        """The dock was closed (its ✕, ``close()``, or its frame destroyed): stop the
        computation and every connection to the viewer (its layer list's events, the
        choices napari refreshes, the view fit and the angle label), once. Subclasses
        add theirs."""
        if self._closed:
            return
        self._closed = True
        self._slot.cancel()
        self._fit.close()
        self._angle_label.close()
        events = self._viewer.layers.events
        for name in ("inserted", "removed", "reordered", "renamed"):
            emitter = getattr(events, name)
            for callback in (self._on_layers_changed, self.reset_choices):
                with contextlib.suppress(Exception):
                    emitter.disconnect(callback)

    # -- building ---------------------------------------------------------------------
    def _add_parameters(self, widgets: list[Any]) -> None:
        """Append the parameter widgets (the buttons and the status line are in
        :attr:`footer`)."""
        self.extend(widgets)

    # -- stack and angles -------------------------------------------------------------
    def _stack_choices(self, _widget: Any = None) -> list[tuple[str, Layer]]:
        """The angle-stack layers; with :attr:`lists_raw_mosaics`, also the raw mosaic
        frames (:func:`~.raw_mosaic.is_raw_mosaic`), named ``"<name> (raw mosaic)"``."""
        choices = []
        for layer in self._viewer.layers:
            if is_angle_stack(layer):
                choices.append((layer.name, layer))
            elif self.lists_raw_mosaics and is_raw_mosaic(layer):
                choices.append((layer.name + RAW_MOSAIC_SUFFIX, layer))
        return choices

    def _labels_choices(self, _widget: Any = None) -> list[tuple[str, Layer]]:
        """The user's 2-D Labels layers with the chosen stack's height x width.

        Choices of the widgets' mask, scribbles and ground-truth pickers.
        """
        stack = getattr(self, "stack_layer", None)
        stack = None if stack is None else stack.value
        if stack is None or stack.ndim != 3:  # none, or a raw mosaic frame (decoded by Run)
            return []
        size = tuple(stack.data.shape[-2:])
        return [
            (layer.name, layer)
            for layer in self._viewer.layers
            if isinstance(layer, Labels)
            and layer_tag(layer) is None
            and not layer.multiscale
            and layer.ndim == 2
            and tuple(layer.data.shape) == size
        ]

    def _labels_box(self, label: str, none: str, tooltip: str) -> ComboBox:
        """A chooser of the user's Labels layers that fit the stack (:meth:`_labels_choices`),
        offering ``none`` for no layer, and at first on it."""
        box = ComboBox(label=label, choices=self._labels_choices, nullable=True, tooltip=tooltip)
        box.null_string = none
        box.reset_choices()
        box.value = None
        return box

    def _on_layers_changed(self, *_: Any) -> None:
        try:
            self._refresh_stacks()
        except RuntimeError:  # the Qt widgets are gone (viewer closing)
            return
        self._forget({source_key(layer) for layer in self._viewer.layers})

    def _refresh_stacks(self) -> None:
        self.stack_layer.reset_choices()
        if self.stack_layer.value is None:
            choices = [c for c in self.stack_layer.choices if c is not None]
            stacks = [c for c in choices if is_angle_stack(c)]  # before a raw mosaic frame
            if stacks or choices:
                self.stack_layer.value = (stacks or choices)[-1]

    def _forget(self, keep: set[str]) -> None:
        """Subclasses: drop state kept for stack layers whose key is not in ``keep``."""

    def _on_stack_changed(self, layer: Layer | None) -> None:
        if layer is None:
            return
        if layer.ndim != 3:  # a raw mosaic frame: its decoded stack brings the angles
            self.angles.value = ""
            return
        angles = layer.metadata.get(ANGLES_KEY) if isinstance(layer.metadata, dict) else None
        if angles is not None and np.size(angles) == layer.data.shape[0]:
            self.angles.value = format_angles(angles)
        elif self.angles.value:
            try:
                if parse_angles(self.angles.value, option=None).size != layer.data.shape[0]:
                    self.angles.value = ""
            except PolarsegError:
                self.angles.value = ""

    def current_stack(self) -> tuple[Layer, np.ndarray]:
        """The chosen stack layer and its angles in degrees (raises PolarsegError)."""
        layer = self.stack_layer.value
        if layer is None:
            raise PolarsegError("choose an angle-stack image layer (angles, rows, columns)")
        return layer, parse_angles(self.angles.value, option=None)

    def output(self, role: str, source: Layer | None = None) -> Layer | None:
        """The plugin's ``role`` layer (e.g. ``"segments"``) for ``source`` or the chosen stack."""
        source = source if source is not None else self.stack_layer.value
        return None if source is None else find_output(self._viewer, role, source)

    # -- running ----------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        """True while a computation runs or waits to run."""
        return self._slot.busy

    @property
    def worker(self) -> Any:
        """The running napari worker, if any."""
        return self._slot.worker

    @property
    def last_error(self) -> str | None:
        """Message of the last error of a run (also shown as a notification)."""
        return self._slot.last_error

    def run(self, *_: Any) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def cancel(self, *_: Any) -> None:
        """Stop the running computation at its next stage boundary; drop queued runs."""
        self._slot.cancel()

    def wait(self, timeout: float | None = 60.0) -> bool:
        """Process events until no computation runs or waits (scripts and tests)."""
        return self._slot.wait(timeout, extra=self._waiting)

    def _waiting(self) -> bool:
        """True while layers of a result wait to be added (subclasses: or a run is
        scheduled but not yet submitted)."""
        return self._later.pending

    def _submit(
        self,
        job: Any,
        args: tuple[Any, ...],
        total: int,
        on_result: Any,
        on_partial: Any = None,
        live: bool = False,
        cancellable: bool = False,
        reports: bool = False,
    ) -> None:
        """Run ``job`` in the widget's worker slot. A ``live`` rerun (after a parameter
        change) enables Cancel and reports progress only if it still runs
        ``_runner.REPORT_INTERVAL`` later: one that ends sooner repaints nothing before
        its result. A ``cancellable`` job gets a ``cancel`` callable
        (:meth:`~napari_polarseg.widgets._runner.WorkerSlot.submit`), a job that
        ``reports`` a ``report`` callable for progress within its stages (and, given
        ``on_partial``, a ``partial`` one for results handed over from inside them)."""
        if not live:
            self.cancel_button.enabled = True
        self._slot.submit(job, args, total, on_result, on_partial, live, cancellable, reports)

    def _set_status(self, text: str) -> None:
        try:
            self.status.value = text
        except RuntimeError:  # the widget was deleted while a worker ended
            pass

    def _set_progress(self, index: float, total: int) -> None:
        """Move the progress bar to ``index`` of ``total`` stages, painted with the
        window's next repaint: a QProgressBar whose value moves repaints at once, which
        with a software-rendered canvas composes the whole window (20-90 ms of the GUI
        thread, just before a result is shown), so its updates are off meanwhile."""
        try:
            bar = self.progress.native
            bar.setUpdatesEnabled(False)
            try:
                # PROGRESS_STEPS ticks per stage: a share of a stage (index 2.4) moves it
                self.progress.max = max(total, 1) * PROGRESS_STEPS
                self.progress.value = round(min(index, total) * PROGRESS_STEPS)
            finally:
                bar.setUpdatesEnabled(True)  # schedules its paint (no repaint now)
            if self._slot.worker is not None:
                self.cancel_button.enabled = True
        except RuntimeError:  # the widget was deleted while a worker ended
            pass

    def _on_idle(self) -> None:
        try:
            self.cancel_button.enabled = False
        except RuntimeError:
            pass

    def _fail(self, exc: PolarsegError) -> None:
        """Report a problem found before starting a worker."""
        self._set_status(f"error: {exc}")
        show_error(str(exc))

    def _done(self, text: str) -> None:
        self._set_status(text)
