"""The "Polarisation plots" widget: the analyst's plots of a stack's last segmentation.

Thin: the data come from :mod:`napari_polarseg.engine.analysis.plots`, the drawing from
:mod:`napari_polarseg.outputs.figures`; this module only finds the segmentation, runs the
engine in a worker when needed and shows a matplotlib canvas themed like napari.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import TYPE_CHECKING, Any

import numpy as np
from magicgui.widgets import ComboBox, PushButton

from ..engine import PolarsegError, Scene, SegmentParams
from ..engine.analysis import plots
from ..outputs import figures
from ._base import StackWidget
from ._layers import TAG, below_labels, find_output, fitted_limits, source_key
from .canvas import figure_canvas, napari_theme, show_message
from .docks import SegmentDock, docked
from .session import ClassifierOutput, classify_scene, content_digest, stack_pipeline

if TYPE_CHECKING:
    import napari
    from napari.layers import Layer

    from ..engine import SegmentationResult
    from ..engine.classifier.pixel_classifier import PixelClassifier

#: Plot menu: text shown → key.
PLOTS = (
    ("scatter Î–ρ", "scatter_dop"),
    ("scatter Î–φ", "scatter_phase"),
    ("explained variance", "variance"),
    ("histograms", "histograms"),
    ("feature importances", "importances"),
)
#: Features the importance chart shows at most.
TOP_FEATURES = 15
#: Degrees of the reconstruction histograms (thesis figure 5.17).
HISTOGRAM_DEGREES = (4, 12, 20)
#: Random blocks the histograms reconstruct at most (a fixed seed: the same blocks every
#: time): their time stops growing with the image, and the degree-20 fit of a block is
#: the cost (300 blocks of 12 x 12 are 43,200 pixels, some 700 a bin of the 64: smooth
#: curves; seconds in benchmarks/bench_gui.py --plots).
HISTOGRAM_BLOCKS = 300
#: Pixels drawn at most in a scatter plot.
MAX_POINTS = 20000
#: What the variance plot and the component maps say of a result without PCA features.
NO_MAPS = (
    "no PCA features: the segmentation was made without the thesis maps; tick 'thesis "
    "maps and error map' (advanced settings of 'Segment by material') or choose the "
    "thesis preset, run, and load the segmentation again"
)
#: Principal components "Add component maps" adds.
N_COMPONENTS = 3


def component_role(i: int) -> str:
    """Tag role of the layer of principal component ``i`` (0-based)."""
    return f"component_{i + 1}"


def segment_job(
    data: Any,
    angles_rad: np.ndarray,
    params: SegmentParams,
    region: np.ndarray | None = None,
    scribbles: np.ndarray | None = None,
    classifier_file: str | None = None,
    report: Callable[[str, float, int], None] | None = None,
) -> Generator[Any, None, SegmentationResult | ClassifierOutput]:
    """Worker job: the segmentation of a stack with ``params`` (as the Segment widget),
    on a :class:`~napari_polarseg.engine.Scene` of it.

    ``region`` (H, W bool, True = use) is the user's mask; with ``scribbles`` (H, W
    labels) the pixel classifier trained on them replaces the method, with
    ``classifier_file`` the classifier saved there (read again, checked, not retrained).
    Returns the result (of the method ``params.method``, with the thesis maps and the
    error map; ``report`` receives its stages as they start), or for the classifier the
    :class:`~napari_polarseg.widgets.session.ClassifierOutput` (result and classifier).
    """
    scene = Scene(pipeline=stack_pipeline(data, angles_rad, params, region))
    inputs: dict[str, Any] = {"scribbles": scribbles}
    if classifier_file is not None:
        from ..classifier_file import load_pixel_classifier

        inputs = {"classifier": load_pixel_classifier(classifier_file)}
    total = len(Scene.stages(params, inputs, maps=True, reconstruction=True))
    yield "polarisation", 0, total

    def progress(stage: str, index: float, total: int) -> None:
        if report is not None and stage != "done":
            report(stage, index, total)

    if scribbles is None and classifier_file is None:
        # the method the segments came from (params.method), with the maps the plots draw
        return scene.segment(params, maps=True, reconstruction=True, progress=progress)
    out = classify_scene(scene, params, inputs, True, progress=progress)
    if out.problem is not None:
        where = "scribbles" if out.trained else "classifier"
        raise PolarsegError(f"{where}: {out.problem}")
    return out


def histogram_job(
    result: SegmentationResult, degrees: tuple[int, ...]
) -> Generator[tuple[str, int, int], None, Any]:
    """Worker job: the reconstruction histograms of ``result`` (of at most
    :data:`HISTOGRAM_BLOCKS` random blocks)."""
    yield "reconstructions", 0, 1
    hist = plots.result_histograms(result, degrees, max_blocks=HISTOGRAM_BLOCKS)
    yield "histograms", 1, 1
    return hist


class PlotsWidget(StackWidget):
    """Plots of the last segmentation of an angle stack (thesis figures 4.1, 5.17).

    *Load segmentation* reads the result the docked *Segment by material* widget keeps
    for the stack's ``segments`` layer, or recomputes it in a worker from what that layer
    records: the parameters, and the mask and scribbles layers used (read again from the
    viewer; the status line says so when they were edited since). The plot menu shows Î
    against ρ or φ coloured by segment, the PCA's explained variance, or histograms of Î
    and of its reconstructions at L = 4, 12, 20. *Add component maps* adds the first
    principal components at pixel resolution as image layers (replaced in place).

    *feature importances* shows the largest importances (at most :data:`TOP_FEATURES`)
    of the pixel classifier behind the segments when they come from scribbles or a
    loaded classifier; a docked *Segment by material* widget hands over every
    retrained classifier of the chosen stack (:meth:`set_classifier`), so the chart
    follows the strokes as they are painted.
    """

    dock_title = "Plots"
    run_text = "Load segmentation"
    run_tooltip = "Load the chosen stack's last segmentation and draw its plots"
    progress_desc = "Polarisation plots"

    def __init__(self, viewer: napari.viewer.Viewer) -> None:
        super().__init__(viewer)
        self.result: SegmentationResult | None = None
        self.histograms: plots.ReconstructionHistograms | None = None
        #: The pixel classifier of the chosen stack's segments (None: not from one).
        self.classifier: PixelClassifier | None = None
        self._source: Layer | None = None
        #: The status line of the loaded segmentation (segments, components, notes).
        self._summary = ""
        self.plot = ComboBox(
            label="plot", choices=list(PLOTS), value="scatter_dop", tooltip="What to plot"
        )
        self.components_button = PushButton(
            text="Add component maps",
            tooltip="Add the first principal components of the block features (PCA) of "
            "the chosen stack's last segmentation as image layers (needs its thesis maps)",
        )
        self._add_parameters([self.plot, self.components_button])
        self.theme = napari_theme(viewer)
        self.figure, self.canvas = figure_canvas((4.0, 3.2), min_height=280)
        self.add_native(self.canvas, expand=True)
        self.plot.changed.connect(self.draw)
        self.components_button.changed.connect(self.add_component_maps)
        self.draw()

    # -- finding the segmentation ------------------------------------------------------
    def segmentation_params(self, layer: Layer) -> SegmentParams:
        """Parameters of the stack's last segmentation (raises PolarsegError)."""
        segments = find_output(self._viewer, "segments", layer)
        meta = None if segments is None else segments.metadata.get("polarseg_params")
        if not isinstance(meta, dict):
            raise PolarsegError(
                f"no segmentation of {layer.name!r} yet: run 'Segment by material' first"
            )
        return SegmentParams.from_dict({k: v for k, v in meta.items() if k != "angles_deg"})

    def segmentation_inputs(
        self, layer: Layer
    ) -> tuple[np.ndarray | None, np.ndarray | None, list[str]]:
        """The mask region and scribbles of the stack's last segmentation, and notes.

        Read from the layers the ``segments`` layer's metadata names (raises
        PolarsegError if one was removed); a note says when one was edited since. (A
        classifier file the segments came from is :meth:`segmentation_classifier_file`.)
        """
        segments = find_output(self._viewer, "segments", layer)
        inputs = None if segments is None else segments.metadata.get("polarseg_inputs")
        inputs = inputs if isinstance(inputs, dict) else {}
        notes: list[str] = []
        found: dict[str, np.ndarray | None] = {"mask": None, "scribbles": None}
        for role in found:
            info = inputs.get(role)
            if not isinstance(info, dict):
                continue
            source = self._layer_by_key(info.get("layer_id"))
            if source is None:
                raise PolarsegError(
                    f"the {role} layer {info.get('name')!r} of the segmentation of "
                    f"{layer.name!r} is no longer in the viewer"
                )
            data = np.array(source.data, copy=True)
            if role == "mask":
                data = data != 0
            if content_digest(data) != info.get("digest"):
                notes.append(f"{role} {source.name!r} edited since the segmentation")
            found[role] = data
        return found["mask"], found["scribbles"], notes

    def segmentation_classifier_file(self, layer: Layer) -> str | None:
        """The classifier file the stack's last segmentation applied, if any."""
        segments = find_output(self._viewer, "segments", layer)
        inputs = None if segments is None else segments.metadata.get("polarseg_inputs")
        path = inputs.get("classifier") if isinstance(inputs, dict) else None
        return path if isinstance(path, str) else None

    def _segment_widget_classifier(self) -> PixelClassifier | None:
        """The docked Segment widget's pixel classifier of the chosen stack, if any."""
        layer = self.stack_layer.value
        if layer is None:
            return None
        for widget in docked(self._viewer, SegmentDock):
            classifier = widget.shown_classifier(layer)
            if classifier is not None:
                return classifier
        return None

    def _layer_by_key(self, key: Any) -> Layer | None:
        for candidate in self._viewer.layers:
            if source_key(candidate) == key:
                return candidate
        return None

    def cached_result(self, layer: Layer, params: SegmentParams) -> SegmentationResult | None:
        """The docked Segment widget's result behind ``layer``'s ``segments`` layer."""
        found = self._cached(layer, params)
        return None if found is None else found[0]

    def _cached(
        self, layer: Layer, params: SegmentParams
    ) -> tuple[SegmentationResult, PixelClassifier | None] | None:
        """The docked Segment widget's result behind ``layer``'s segments and its
        pixel classifier (None when the labels came from the cut)."""
        for widget in docked(self._viewer, SegmentDock):
            result = widget.shown_result(layer)
            if result is not None and result.params == params:
                return result, widget.shown_classifier(layer)
        return None

    def run(self, *_: Any) -> None:
        """Load the chosen stack's last segmentation (cached, or in a worker)."""
        try:
            layer, angles_deg = self.current_stack()
            params = self.segmentation_params(layer)
        except PolarsegError as exc:
            self._fail(exc)
            return
        cached = self._cached(layer, params)
        if cached is not None:
            self.set_result(layer, cached[0], classifier=cached[1])
            return
        try:
            region, scribbles, notes = self.segmentation_inputs(layer)
        except PolarsegError as exc:
            self._fail(exc)
            return
        classifier_file = self.segmentation_classifier_file(layer)

        def on_result(run_id: int, value: Any) -> None:
            if layer in self._viewer.layers and self.stack_layer.value is layer:
                if isinstance(value, ClassifierOutput):
                    self.set_result(layer, value.result, notes, value.classifier)
                else:
                    self.set_result(layer, value, notes)

        args = (layer.data, np.deg2rad(angles_deg), params, region, scribbles, classifier_file)
        inputs = {"scribbles": scribbles, "classifier": classifier_file}
        total = len(Scene.stages(params, inputs, maps=True, reconstruction=True))
        self._submit(segment_job, args, total, on_result, reports=True)

    def set_result(
        self,
        layer: Layer,
        result: SegmentationResult,
        notes: list[str] | None = None,
        classifier: PixelClassifier | None = None,
    ) -> None:
        """Plot ``result`` (a segmentation of ``layer``; ``classifier``: the pixel
        classifier its labels came from, for the feature importances)."""
        self.result, self._source, self.histograms = result, layer, None
        self.classifier = classifier
        parts = [f"{result.n_segments} segments"]
        if result.features is not None:
            parts.append(f"{result.features.shape[1]} components")
        else:
            parts.append(f"no PCA features ({result.method} without the thesis maps)")
        self._summary = " · ".join([*parts, *(notes or [])])
        self._set_progress(1, 1)  # loaded (a cached result ran no worker to say so)
        self.draw()

    def set_classifier(self, layer: Layer, classifier: PixelClassifier | None) -> None:
        """A new pixel classifier behind ``layer``'s segments (None: they no longer come
        from one). Kept when ``layer`` is the chosen stack; the chart is redrawn only
        while it is shown."""
        try:
            if self.stack_layer.value is not layer:
                return
            self.classifier = classifier
            if self.plot.value == "importances":
                self.draw()
        except RuntimeError:  # the widget was deleted
            pass

    def _on_stack_changed(self, layer: Layer | None) -> None:
        super()._on_stack_changed(layer)
        if getattr(self, "plot", None) is None:  # the base class initialises
            return
        self.classifier = None  # the new stack's comes from the Segment widget
        if self.result is not None and layer is not self._source:
            self.result, self._source, self.histograms = None, None, None
            self.draw()
        elif self.plot.value == "importances":
            self.draw()

    # -- drawing -----------------------------------------------------------------------
    def draw(self, *_: Any) -> None:
        """Draw the chosen plot into the canvas (a hint when there is nothing to plot);
        the status line says what the canvas shows."""
        kind = self.plot.value
        result = self.result
        fig, theme = self.figure, self.theme
        status = self._summary
        if kind == "importances":
            status = self._draw_importances()
        elif result is None:
            self._message("press 'Load segmentation' to plot the stack's last segmentation")
        elif kind in ("scatter_dop", "scatter_phase"):
            data = plots.scatter_data(result, MAX_POINTS)
            # numbered as the segments layer shows them (label + 1)
            against, materials = kind.split("_")[1], result.materials
            figures.scatter_figure(data, against, fig, theme, first_label=1, materials=materials)
        elif kind == "variance" and result.explained_variance_ratio is None:
            self._message(NO_MAPS)
        elif kind == "variance":
            figures.explained_variance_figure(plots.explained_variance(result), fig, theme)
        elif self.histograms is not None:
            figures.histograms_figure(self.histograms, fig, theme)
            degrees = ", ".join(map(str, self.histograms.reconstructed))
            status = f"{self._summary} · histograms of Î and L = {degrees}"
        else:
            self._message("computing the reconstructions…")
            res = result

            def on_result(run_id: int, value: Any) -> None:
                if self.result is res:
                    self.histograms = value
                    self.draw()  # the histograms, or the plot chosen meanwhile and its status

            self._submit(histogram_job, (result, HISTOGRAM_DEGREES), 1, on_result)
            status = None  # the worker's stages
        if status is not None:
            self._set_status(status)
        self.canvas.draw_idle()

    def _draw_importances(self) -> str:
        """Draw the feature importances (or say why there are none); the status line."""
        clf = self.classifier
        if clf is None:
            clf = self.classifier = self._segment_widget_classifier()
        if clf is None:
            self._message(
                "no pixel classifier: paint scribbles (or load a classifier) in 'Segment "
                "by material', or press 'Load segmentation'"
            )
            return "no pixel classifier behind the segments"
        data = plots.feature_importances(clf.importances(), TOP_FEATURES)
        if not data.names:
            self._message(f"the {clf.params.model} classifier has no feature importances")
            return f"the {clf.params.model} classifier has no feature importances"
        figures.importances_figure(data, self.figure, self.theme)
        return (
            f"feature importances of the {clf.params.model} classifier: the top "
            f"{len(data.names)} of {data.n_features} features"
        )

    def _message(self, text: str) -> None:
        show_message(self.figure, self.theme, text)

    # -- component layers --------------------------------------------------------------
    def add_component_maps(self, *_: Any) -> list[Layer]:
        """Add (or replace in place) the first principal components as image layers; new
        ones go below the segments and scribbles (:func:`~._layers.below_labels`)."""
        if self.result is None or self._source is None or self._source not in self._viewer.layers:
            self._fail(PolarsegError("load a segmentation first"))
            return []
        if self.result.features is None:
            self._fail(PolarsegError(NO_MAPS))
            return []
        source, comp = self._source, plots.component_maps(self.result, N_COMPONENTS)
        out = []
        for i, data in enumerate(comp.pixels):
            role = component_role(i)
            meta = {TAG: {"role": role, "source": source_key(source)}}
            hi = max(abs(v) for v in fitted_limits(data, (1.0, 99.0)))
            limits = (-hi, hi)
            layer = find_output(self._viewer, role, source)
            if layer is not None:
                layer.data = data
                layer.contrast_limits_range = (
                    min(-hi, float(data.min())),
                    max(hi, float(data.max())),
                )
                layer.contrast_limits = limits
                layer.metadata = {**layer.metadata, **meta}
            else:
                layer = self._viewer.add_image(
                    data,
                    name=f"principal component {i + 1}",
                    metadata=meta,
                    colormap="PiYG",
                    contrast_limits=limits,
                    scale=tuple(source.scale[-2:]),
                    translate=tuple(source.translate[-2:]),
                    visible=i == 0,
                )
                below_labels(self._viewer, layer, source)  # not over segments, scribbles
            out.append(layer)
        self._done(f"added {len(out)} component maps")
        return out
