"""What a segmentation method is: the :class:`Segmenter` protocol, its output and its run.

A method reads the shared polarisation image of a :class:`~.scene.Scene` (and whatever
inputs it needs, e.g. scribbles), names the shared
:class:`~napari_polarseg.engine.SegmentParams` fields its labels depend on
(:attr:`Segmenter.reads`), declares its own parameters (``params_class``; the scene
reruns it only when one of these changes), lists its own stages (progress and status
come from that list) and returns pixel labels. Registering one is one line (:mod:`.registry`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..errors import Cancelled
from ..params import SegmentParams

if TYPE_CHECKING:  # annotations only: importing the methods stays light
    from ..features.object_size import ObjectSize
    from ..physics.pixel_mask import PixelMask
    from ..physics.polarimage import PolarisationImage
    from ..pipeline import Pipeline

#: Progress callback of a run: (stage, index, total); ``index`` counts the stages done
#: (a float inside a stage that reports its share), so the status can say what runs.
Progress = Callable[[str, float, int], None]
#: Receiver of a method's partial results (:meth:`MethodRun.partial`): the output so far
#: and whether its labels are final.
PartialOutput = Callable[["MethodOutput", bool], None]


@dataclass(frozen=True)
class MethodOutput:
    """What a method returns.

    Attributes
    ----------
    labels : ndarray (H, W) int
        A label for every pixel of the input (0 = first segment, or a classifier's
        class index).
    seconds : dict
        Seconds of each of its stages it computed (empty: the scene times the method
        as one stage under its name).
    ncut_values : list of float
        Ncut value of every cut made (graph-cut methods; else empty).
    cut_limits : dict
        Work counts of a graph cut (else empty).
    record : dict
        What the method reports about the run (``summary.json["method_record"]``), JSON
        ready.
    extra : dict
        Python objects a caller of this method may use (a classifier's prediction).
    """

    labels: np.ndarray
    seconds: dict[str, float] = field(default_factory=dict)
    ncut_values: list[float] = field(default_factory=list)
    cut_limits: dict[str, int] = field(default_factory=dict)
    record: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)


class SceneView(Protocol):
    """What a method reads of the :class:`~.scene.Scene` it segments (the scene module
    imports this one: the protocol names the scene here, so no import cycle)."""

    pipeline: Pipeline

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the stack."""
        ...

    @property
    def mask(self) -> PixelMask:
        """The pixel mask of the scene's pipeline."""
        ...

    @property
    def region(self) -> np.ndarray | None:
        """The user's region (H, W bool) or None (every pixel)."""
        ...

    @property
    def max_bytes(self) -> int | None:
        """The memory limit of the runs, bytes (None: the engine's default)."""
        ...

    def work_limit(self) -> int:
        """The memory limit of a method's work, bytes (the limit less the stack and its
        flags): a method that works tile by tile chooses its tiles from it."""
        ...

    def polarisation(self, params: SegmentParams) -> PolarisationImage:
        """The shared polarisation image for ``params.fit``."""
        ...

    def object_size(self, params: SegmentParams) -> ObjectSize:
        """The object size a run uses (given, or the scene's estimate)."""
        ...

    def cached(self, name: str, key: Any, compute: Callable[[], Any]) -> Any:
        """The scene's feature cache: the value kept under ``name`` for ``key``, else
        ``compute()`` (kept)."""
        ...


class Segmenter(Protocol):
    """A segmentation method (a peer of the others; see the module docstring).

    Attributes
    ----------
    name : str
        Registry key: the value of ``SegmentParams.method``, ``--method`` and
        ``params.json``.
    title : str
        Text of the plugin's method menu.
    reads : tuple of str
        The shared SegmentParams fields the labels depend on (its own parameters are
        part of its cache key in any case).
    inputs : tuple of str
        Inputs besides the image it needs, any one of which selects it (e.g.
        ``("scribbles", "classifier")``); empty for an unsupervised method.

    Optional attributes, False or None when a method has none (read at registration):
    ``params_class`` (its own parameters: a frozen dataclass whose fields carry a
    :class:`~napari_polarseg.engine.param_spec.ParamSpec`; ``params.params_of()`` in
    :meth:`segment` is its instance), ``finds_k`` (``n_segments`` = 0 lets it find the
    number of segments) and
    ``block_maps`` (it cuts the w × w block grid and computes the harmonic coefficients,
    the PCA features and the reconstruction-error map in any case, as the thesis method
    does: its runs show those maps, summaries name the block grid, the time series cuts
    its blocks and the memory estimate counts them). ``reads_normals`` (True when
    absent, read at each run): the scene computes the Fresnel normals before its stages;
    False: after them, for the result only, so they are not in memory while it works.
    """

    name: str
    title: str
    reads: tuple[str, ...]
    inputs: tuple[str, ...]

    def stages(self, params: SegmentParams) -> tuple[str, ...]:
        """Its stages in the order they run (after the shared ``polarisation``)."""
        ...

    def segment(
        self, scene: SceneView, params: SegmentParams, inputs: dict[str, Any], run: MethodRun
    ) -> MethodOutput:
        """Labels of the scene's image. Calls ``run.begin(stage)`` before each of its
        stages (which also raises :class:`~napari_polarseg.engine.errors.Cancelled` on a
        stop request) and honours ``scene.region`` (nothing outside it may move a
        label inside it). It may hand labels over before it returns with
        ``run.partial(output, final)`` (a coarse preview, then its final labels)."""
        ...


@dataclass
class MethodRun:
    """Progress, cancellation and partial results of one run over a list of stages.

    :meth:`begin` reports ``(stage, stages done, total)`` *before* the stage runs, so a
    status line names the stage that is running; :meth:`within` reports the share of it
    done (chunked loops); both raise :class:`Cancelled` when ``cancel()`` is True.
    :meth:`partial` hands labels over before the run ends (``on_partial``, see there).
    """

    names: list[str]
    cancel: Callable[[], bool] | None = None
    progress: Progress | None = None
    current: str = ""
    #: Receives ``(output, final)`` of every :meth:`partial` (in the running thread), or
    #: None: nobody looks before the end.
    on_partial: PartialOutput | None = None

    @property
    def total(self) -> int:
        return len(self.names)

    def check(self) -> None:
        """Raise :class:`Cancelled` if a stop was asked for."""
        if self.cancel is not None and self.cancel():
            raise Cancelled(f"cancelled in stage {self.current!r}")

    def begin(self, stage: str) -> None:
        """Stage ``stage`` starts."""
        self.current = stage
        self.check()
        if self.progress is not None:
            self.progress(stage, float(self.index(stage)), self.total)

    def within(self, share: float) -> None:
        """The running stage has done ``share`` (0..1] of its work."""
        self.check()
        if self.progress is not None and self.current:
            i = self.index(self.current)
            self.progress(self.current, i + min(max(share, 0.0), 1.0), self.total)

    @property
    def wants_partials(self) -> bool:
        """True when someone receives partial results: a method may skip the work it
        does only for them (a coarse preview)."""
        return self.on_partial is not None

    def partial(self, out: MethodOutput, final: bool = False) -> None:
        """Hand ``out`` over before the run ends: a coarse preview of the labels
        (``final`` False), or the method's final labels (``final`` True; the scene's
        stages after the method's may still run, e.g. the thesis maps). Raises
        :class:`Cancelled` first when a stop was asked for."""
        self.check()
        if self.on_partial is not None:
            self.on_partial(out, final)

    def finish(self) -> None:
        """Every stage is done."""
        if self.progress is not None:
            self.progress("done", float(self.total), self.total)

    def index(self, stage: str) -> int:
        return self.names.index(stage) if stage in self.names else 0
