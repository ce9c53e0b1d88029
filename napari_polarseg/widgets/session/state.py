"""The Segment dock's one state, without Qt: what its parts read, write and listen to.

:class:`SegmentState` holds the parameters the controls describe, the inputs (the stack,
mask and scribbles layers chosen, the angles typed, the snapshot of the last request),
the results on screen per stack (:class:`ShownEntry`, and which stacks show a run that
has not completed), the classifier's last prediction, the loaded classifier and what
*Export results…* writes. Every change goes through a method that
emits a :mod:`psygnal` signal; the parts (parameter controls, inputs, output layers,
classifier files, export) listen to those instead of calling one another through the
widget. Imports neither Qt, napari nor magicgui (psygnal is napari's signal library);
not imported by :mod:`napari_polarseg.widgets.session` itself, so the session layer
stays importable without psygnal.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from psygnal import Signal

from .results import ExportRecord, ShownResult

if TYPE_CHECKING:
    import numpy as np

    from ...engine import PolarsegError, SegmentationResult, SegmentParams
    from ...engine.classifier.pixel_classifier import PixelClassifier
    from .classify import LoadedClassifier


@dataclass(frozen=True, eq=False)
class ShownEntry:
    """What a stack's ``segments`` layer shows once a run has completed.

    ``layer`` and ``angles_deg``: the stack layer and its angles; ``shown``: the result
    as shown (labels, metadata, classifier output); ``snap``: the snapshot of the
    controls the run was requested with; ``meta``: the segments layer's metadata (the
    result's, or that of a re-show for parameters its method does not read).
    """

    layer: Any
    angles_deg: np.ndarray
    shown: ShownResult
    snap: Any = None
    meta: Mapping[str, Any] | None = None

    @property
    def result(self) -> SegmentationResult:
        """The result behind the segments."""
        return self.shown.result

    @property
    def inputs(self) -> dict[str, Any]:
        """The mask, scribbles and classifier file the run used (``polarseg_inputs``)."""
        return self.shown.inputs

    @property
    def classifier(self) -> PixelClassifier | None:
        """The pixel classifier behind the segments (None after an unsupervised run)."""
        out = self.shown.out
        return None if out is None else out.classifier

    @property
    def metadata(self) -> dict[str, Any]:
        """The segments layer's metadata (:attr:`meta`, else the result's)."""
        return dict(self.meta if self.meta is not None else self.shown.meta)


@dataclass(frozen=True, eq=False)
class Inputs:
    """The inputs chosen in the dock: the stack layer, the angles as typed, the mask
    and scribbles layers (None: none). Layers compare by identity."""

    stack: Any = None
    angles: str = ""
    mask: Any = None
    scribbles: Any = None

    def same(self, other: Inputs) -> bool:
        """True when the layers are the same objects and the angles the same text."""
        layers = ("stack", "mask", "scribbles")
        return self.angles == other.angles and all(
            getattr(self, name) is getattr(other, name) for name in layers
        )


@dataclass(frozen=True)
class Prediction:
    """The classifier's last prediction shown: class probabilities (K, H, W), the
    scribble value of each class, the uncertainty (H, W); all None after a run of an
    unsupervised method."""

    probabilities: np.ndarray | None = None
    classes: np.ndarray | None = None
    uncertainty: np.ndarray | None = None


class SegmentState:
    """The Segment dock's state: parameters, inputs, results on screen, the loaded
    classifier and the exports (see the module's docstring).

    Signals (:mod:`psygnal`): :attr:`params_changed` (the parameters),
    :attr:`inputs_changed` (the new and the old :class:`Inputs`), :attr:`edited` (a
    stroke or new data in the chosen mask or scribbles layer),
    :attr:`shown_changed` (a stack key and the entry it showed before),
    :attr:`loaded_changed`, :attr:`exports_changed` (a
    stack key), :attr:`forgotten` (the stack keys dropped) and :attr:`closed` (the dock
    was closed: nothing more is to run).
    """

    params_changed = Signal(object)
    inputs_changed = Signal(object, object)
    edited = Signal()
    shown_changed = Signal(str, object)
    loaded_changed = Signal(object)
    exports_changed = Signal(str)
    forgotten = Signal(object)
    closed = Signal()

    def __init__(self) -> None:
        self._params: SegmentParams | None = None
        self._params_error: PolarsegError | None = None
        #: Whether a run with the current parameters computes the thesis maps.
        self.maps = False
        self._inputs = Inputs()
        #: The snapshot of the last request (None before one, or for bad values).
        self.requested: Any = None
        self._shown: dict[str, ShownEntry] = {}
        self._partial: set[str] = set()
        self._prediction = Prediction()
        self._loaded: LoadedClassifier | None = None
        self._exports: dict[str, ExportRecord] = {}
        self._closed = False

    # -- parameters -----------------------------------------------------------------
    @property
    def params(self) -> SegmentParams:
        """The parameters the controls describe; raises the PolarsegError of a bad value
        (or before the controls were read)."""
        if self._params_error is not None:
            raise self._params_error
        if self._params is None:
            from ...engine import PolarsegError

            raise PolarsegError("the parameters have not been read yet")
        return self._params

    def set_params(
        self, params: SegmentParams | None, maps: bool, error: PolarsegError | None = None
    ) -> None:
        """The controls describe ``params`` (None and ``error``: a bad value), with the
        thesis maps when ``maps``; emits :attr:`params_changed` when they changed."""
        same = (
            params == self._params and maps == self.maps and repr(error) == repr(self._params_error)
        )
        self._params, self._params_error, self.maps = params, error, bool(maps)
        if not same:
            self.params_changed.emit(params)

    # -- inputs ---------------------------------------------------------------------
    @property
    def inputs(self) -> Inputs:
        """The stack, angles, mask and scribbles chosen."""
        return self._inputs

    def set_inputs(self, **changes: Any) -> None:
        """Change fields of :attr:`inputs` (``stack``, ``angles``, ``mask``,
        ``scribbles``); emits :attr:`inputs_changed` (new, old) when one changed."""
        old = self._inputs
        new = replace(old, **changes)
        if new.same(old):
            return
        self._inputs = new
        self.inputs_changed.emit(new, old)

    def mark_edited(self) -> None:
        """The chosen mask or scribbles layer was painted or its data replaced."""
        if not self._closed:
            self.edited.emit()

    # -- results on screen ----------------------------------------------------------
    @property
    def shown(self) -> Mapping[str, ShownEntry]:
        """Per stack key: the completed result its ``segments`` layer shows (read-only)."""
        return MappingProxyType(self._shown)

    def show(self, key: str, entry: ShownEntry) -> None:
        """Stack ``key`` shows ``entry`` (a completed run, or a re-show of the same
        result, which leaves the segments of a run still going as they are); emits
        :attr:`shown_changed` (key, the entry before)."""
        old = self._shown.get(key)
        self._shown[key] = entry
        if old is None or entry.shown is not old.shown:
            self._partial.discard(key)
        self.shown_changed.emit(key, old)

    def show_partial(self, key: str) -> None:
        """Stack ``key``'s segments show a run's labels before it completed."""
        self._partial.add(key)

    def take_partial(self) -> set[str]:
        """The stacks whose segments show a run that never completed (its layers stop
        at the segments), and none from now on: the runs have ended."""
        keys, self._partial = self._partial, set()
        return keys

    @property
    def prediction(self) -> Prediction:
        """The classifier's last prediction shown (Nones after an unsupervised run)."""
        return self._prediction

    def set_prediction(self, prediction: Prediction) -> None:
        """The classifier's prediction now shown."""
        self._prediction = prediction

    def classifier_of(self, key: str) -> PixelClassifier | None:
        """The pixel classifier behind stack ``key``'s shown result, if any."""
        entry = self._shown.get(key)
        return None if entry is None else entry.classifier

    # -- the loaded classifier ---------------------------------------
    @property
    def loaded(self) -> LoadedClassifier | None:
        """The classifier *Load classifier…* read, while it is applied."""
        return self._loaded

    def set_loaded(self, loaded: LoadedClassifier | None) -> None:
        """Apply ``loaded`` (None: stop applying one); emits :attr:`loaded_changed`."""
        if loaded is self._loaded:
            return
        self._loaded = loaded
        self.loaded_changed.emit(loaded)

    # -- exports --------------------------------------------------------------------
    @property
    def exports(self) -> Mapping[str, ExportRecord]:
        """Per stack key: what *Export results…* writes (read-only)."""
        return MappingProxyType(self._exports)

    def set_export(self, key: str, record: ExportRecord | None) -> None:
        """What *Export results…* writes for stack ``key`` (None: nothing)."""
        if record is None and key not in self._exports:
            return
        if record is None:
            del self._exports[key]
        else:
            self._exports[key] = record
        self.exports_changed.emit(key)

    # -- lifetime -------------------------------------------------------------------
    def forget(self, keep: set[str]) -> None:
        """Drop every stack's results and exports whose key is not in ``keep``; emits
        :attr:`forgotten` with the keys dropped (if any)."""
        dropped = (set(self._shown) | set(self._exports) | self._partial) - keep
        for key in dropped:
            self._shown.pop(key, None)
            self._exports.pop(key, None)
            self._partial.discard(key)
        if dropped:
            self.forgotten.emit(dropped)

    @property
    def is_closed(self) -> bool:
        """True once the dock was closed."""
        return self._closed

    def close(self) -> None:
        """The dock was closed: emits :attr:`closed` once; :meth:`mark_edited` is
        ignored from then on."""
        if not self._closed:
            self._closed = True
            self.closed.emit()
