"""The Segment widget's scribble helpers: *Use as scribbles* and *Paint here next*.

*Use as scribbles* turns the chosen stack's segments (e.g. an unsupervised result) into
an editable scribbles layer: each segment's interior, a band of
:data:`~napari_polarseg.engine.classifier.scribbles_from_labels.DEFAULT_MARGIN` pixels
along every border left unlabelled for the classifier to decide
(:func:`~napari_polarseg.engine.classifier.scribbles_from_labels.scribbles_from_labels`).
*Paint here next* outlines the largest region the classifier is least sure of
(:func:`~napari_polarseg.engine.classifier.suggestion.paint_here_next`) as a Shapes layer
and centres the view on it. Both compute in well under a second on a camera frame, so
they run in the GUI thread.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import Container, PushButton

from ..engine import PolarsegError
from ..engine.classifier.scribbles_from_labels import DEFAULT_MARGIN, scribbles_from_labels
from ..engine.classifier.suggestion import Suggestion, paint_here_next
from ._layers import find_output
from .segment_layers import result_on_screen

if TYPE_CHECKING:
    import napari

    from .segment_inputs import SegmentInputs
    from .session.state import SegmentState

#: Name suffix of the suggestion's Shapes layer (``"<stack> paint here next"``).
SUGGESTION_SUFFIX = "paint here next"


def view_camera(viewer: Any) -> Any:
    """The viewer's camera (``viewer.scene.camera`` from napari 0.9, ``viewer.camera``
    before)."""
    scene = getattr(viewer, "scene", None)
    return scene.camera if scene is not None and hasattr(scene, "camera") else viewer.camera


def region_outline(region: np.ndarray) -> np.ndarray:
    """The longest outline (K, 2) of (row, column) vertices of a boolean region
    (:func:`skimage.measure.find_contours` at level ½, on the region padded by a pixel
    so an outline touching the image's edge closes)."""
    from skimage.measure import find_contours

    contours = find_contours(np.pad(region.astype(float), 1), 0.5)
    longest = max(contours, key=len)
    return longest - 1.0


class ScribbleAssist:
    """*Use as scribbles* and *Paint here next* of the Segment widget.

    Parameters
    ----------
    state : SegmentState
        The dock's state: the chosen stack and scribbles, the results shown.
    inputs : SegmentInputs
        The widget's inputs part: its strokes, material list and *New scribbles layer*.
    viewer : napari.viewer.Viewer
    status, fail : callable
        The widget's status line and error report.
    """

    def __init__(
        self,
        state: SegmentState,
        inputs: SegmentInputs,
        viewer: napari.viewer.Viewer,
        status: Callable[[str], None],
        fail: Callable[[PolarsegError], None],
    ) -> None:
        self._state, self._inputs, self._viewer = state, inputs, viewer
        self._status, self._fail = status, fail
        #: The last suggestion shown (None before, or when there was nothing to suggest).
        self.suggestion: Suggestion | None = None
        self.use_button = PushButton(
            text="Use as scribbles",
            tooltip="Turn the chosen stack's segments into a new scribbles layer to "
            f"correct: each segment's interior, a {DEFAULT_MARGIN}-pixel band along every "
            "border left unlabelled for the classifier to decide",
        )
        self.next_button = PushButton(
            text="Paint here next",
            tooltip="Outline the largest region the classifier is least sure of (its "
            "uncertainty, away from the strokes) and centre the view on it: a stroke "
            "there teaches it most",
        )
        self.buttons = Container(
            layout="horizontal",
            widgets=[self.use_button, self.next_button],
            labels=False,
            label="assist",
        )
        self.buttons.margins = (0, 0, 0, 0)
        self.use_button.changed.connect(self.use_as_scribbles)
        self.next_button.changed.connect(self.paint_here_next)

    def _shown(self) -> tuple[Any, Any, Any]:
        """The chosen stack, its segments layer and result; raises PolarsegError."""
        layer = self._state.inputs.stack
        if layer is None:
            raise PolarsegError("choose an angle-stack image layer first")
        segments = find_output(self._viewer, "segments", layer)
        entry = result_on_screen(self._state, self._viewer, layer)
        if segments is None or entry is None:
            raise PolarsegError("run a segmentation of this stack first")
        return layer, segments, entry.result

    def use_as_scribbles(self, *_: Any) -> Any:
        """A new scribbles layer from the chosen stack's segments (its values kept: a
        classifier's scribble values, else 1, 2, … as the segments layer shows them)."""
        try:
            _, segments, result = self._shown()
        except PolarsegError as exc:
            self._fail(exc)
            return None
        data = np.asarray(segments.data)
        strokes = scribbles_from_labels(
            data, DEFAULT_MARGIN, valid=result.valid, first_value=max(int(data.min()), 1)
        )
        materials = result.materials
        names = {} if materials is None else {int(v): n for v, n in materials.to_dict().items()}
        layer = self._inputs.new_scribbles_layer()
        if layer is None:
            return None
        layer.data = strokes
        if names:
            self._inputs.materials.set_names(names)
        self._inputs.materials.refresh()
        n = len(np.unique(strokes[strokes > 0]))
        self._status(
            f"{n} materials as scribbles in {layer.name!r}: each segment's interior, "
            f"a {DEFAULT_MARGIN}-pixel band along the borders left for the classifier; "
            "paint or erase to correct, then Run"
        )
        return layer

    def paint_here_next(self, *_: Any) -> Suggestion | None:
        """Outline the largest uncertain region of the chosen stack's classifier result
        (a Shapes layer) and centre the view on it."""
        try:
            layer, _, result = self._shown()
            uncertainty = find_output(self._viewer, "uncertainty", layer)
            if uncertainty is None:
                raise PolarsegError("paint scribbles and run the classifier first")
            _, painted = self._inputs.current_scribbles()
        except PolarsegError as exc:
            self._fail(exc)
            return None
        self.suggestion = paint_here_next(
            np.asarray(uncertainty.data), painted=painted, valid=result.valid
        )
        if self.suggestion is None:
            self._status("the classifier is sure everywhere: nothing to suggest")
            return None
        self._show(layer, self.suggestion)
        s = self.suggestion
        self._status(
            f"paint here next: {s.pixels} pixels around row {s.centre[0]}, column "
            f"{s.centre[1]} (mean uncertainty {s.mean_uncertainty:.2f})"
        )
        return s

    def _show(self, stack: Any, suggestion: Suggestion) -> None:
        """The outline as the ``<stack> paint here next`` Shapes layer; the view centred."""
        name = f"{stack.name} {SUGGESTION_SUFFIX}"
        outline = region_outline(suggestion.region)
        placement = {"scale": tuple(stack.scale[-2:]), "translate": tuple(stack.translate[-2:])}
        if name in self._viewer.layers:
            shapes = self._viewer.layers[name]
            shapes.data = [outline]
        else:
            shapes = self._viewer.add_shapes(
                [outline],
                shape_type="polygon",
                name=name,
                edge_color="white",  # not a palette colour: stands out on segments
                face_color=[0, 0, 0, 0],
                edge_width=2,
                **placement,
            )
        scale, translate = np.asarray(stack.scale[-2:]), np.asarray(stack.translate[-2:])
        world = translate + scale * np.asarray(suggestion.centre, dtype=float)
        camera = view_camera(self._viewer)
        camera.center = (*tuple(camera.center)[:-2], *world)
        self._viewer.layers.selection.active = self._state.inputs.scribbles or shapes
