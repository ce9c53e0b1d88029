"""The Segment dock's state without Qt (``widgets/session/state.py``): what it emits,
what it keeps per stack, and that it needs no GUI module."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from napari_polarseg.engine import PolarsegError, SegmentParams
from napari_polarseg.widgets.session import shown_result
from napari_polarseg.widgets.session.state import Inputs, SegmentState, ShownEntry


class _Layer:
    """A stand-in for a napari layer (compared by identity)."""


def _entry(layer: object, snap: object = None) -> ShownEntry:
    from napari_polarseg.engine import Scene

    rng = np.random.default_rng(0)
    stack = rng.uniform(100, 200, (4, 24, 24))
    angles = np.deg2rad([0.0, 45.0, 90.0, 135.0])
    result = Scene(stack, angles).segment(SegmentParams(method="thesis", n_segments=2))
    return ShownEntry(layer, np.array([0.0, 45.0, 90.0, 135.0]), shown_result(result, angles), snap)


def test_the_state_imports_no_gui_module() -> None:
    code = (
        "import sys\n"
        "import napari_polarseg.widgets.session.state\n"
        "gui = {'napari', 'magicgui', 'qtpy', 'PyQt5', 'PyQt6', 'PySide2', 'PySide6'}\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & gui))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_parameters_and_their_error() -> None:
    state = SegmentState()
    seen: list[object] = []
    state.params_changed.connect(seen.append)
    with pytest.raises(PolarsegError):
        state.params  # noqa: B018 - not read yet
    params = SegmentParams(method="thesis")
    state.set_params(params, maps=True)
    state.set_params(params, maps=True)  # the same: no signal
    assert state.params is params and state.maps and seen == [params]
    state.set_params(None, False, PolarsegError("window 3 is too small"))
    with pytest.raises(PolarsegError, match="window 3"):
        state.params  # noqa: B018
    assert seen == [params, None]


def test_inputs_compare_layers_by_identity() -> None:
    state, stack, scribbles = SegmentState(), _Layer(), _Layer()
    changes: list[tuple[Inputs, Inputs]] = []
    state.inputs_changed.connect(lambda new, old: changes.append((new, old)))
    state.set_inputs(stack=stack, angles="0, 45, 90, 135")
    state.set_inputs(stack=stack)  # nothing changed
    state.set_inputs(scribbles=scribbles)
    assert len(changes) == 2
    new, old = changes[-1]
    assert new.scribbles is scribbles and old.scribbles is None and new.stack is stack


def test_results_shown_partial_runs_and_forget() -> None:
    state, layer = SegmentState(), _Layer()
    shown: list[tuple[str, object]] = []
    state.shown_changed.connect(lambda key, old: shown.append((key, old)))
    entry = _entry(layer)
    state.show("a", entry)
    assert state.shown["a"] is entry and shown == [("a", None)]
    assert state.classifier_of("a") is None  # an unsupervised result
    state.show_partial("a")  # a new run's segments before its error map
    state.show_partial("b")
    assert state.take_partial() == {"a", "b"} and state.take_partial() == set()
    state.show_partial("a")
    reshown = ShownEntry(layer, entry.angles_deg, entry.shown, snap="other parameters")
    state.show("a", reshown)  # the same result again: the run's segments stay marked
    assert state.take_partial() == {"a"}
    state.show_partial("a")
    state.show("a", _entry(layer))  # completed: no longer partial
    assert state.take_partial() == set()
    dropped: list[set[str]] = []
    state.forgotten.connect(dropped.append)
    state.forget({"a"})
    assert dropped == [] and "a" in state.shown
    state.forget(set())
    assert dropped == [{"a"}] and dict(state.shown) == {}
    with pytest.raises(TypeError):
        state.shown["b"] = entry  # type: ignore[index] - read-only


def test_loaded_classifier_exports_and_closing() -> None:
    state = SegmentState()
    loads: list[object] = []
    state.loaded_changed.connect(loads.append)
    state.set_loaded(None)  # already none
    assert loads == []
    exports: list[str] = []
    state.exports_changed.connect(exports.append)
    state.set_export("a", None)  # nothing to drop
    assert exports == []
    edits: list[int] = []
    state.edited.connect(lambda: edits.append(1))
    state.mark_edited()
    closed: list[int] = []
    state.closed.connect(lambda: closed.append(1))
    state.close()
    state.close()
    state.mark_edited()  # a closed dock: ignored
    assert state.is_closed and closed == [1] and edits == [1]


def test_the_degenerate_status_names_what_the_method_reads():
    """The status line's advice after a degenerate result: a larger window only for the
    thesis method, the object size for the default, more strokes for the classifier."""
    from napari_polarseg.widgets.session import degenerate_text

    reason = {"degenerate": True, "degenerate_reason": "one segment holds 99 % of the pixels"}
    thesis = degenerate_text({**reason, "method": "thesis"})
    default = degenerate_text({**reason, "method": "surface_superpixels"})
    classifier = degenerate_text({**reason, "method": "classifier"})
    assert "a larger window" in thesis
    assert "window" not in default and "another object size" in default
    assert "more strokes" in classifier and "window" not in classifier
    assert degenerate_text({"degenerate": False, "method": "thesis"}) == ""
