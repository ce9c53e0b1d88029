"""What a segmentation method is: the :class:`Segmenter` protocol, its output and its run.

A method reads the shared polarisation image of a :class:`~.scene.Scene` (and whatever
inputs it needs, e.g. scribbles), names the :class:`~napari_polarseg.engine.SegmentParams`
fields its labels depend on (:attr:`Segmenter.reads`: the scene reruns it only when one
of them changes), lists its own stages (progress and status come from that list) and
returns pixel labels. Registering one is one line (:mod:`.registry`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..errors import Cancelled
from ..params import SegmentParams

if TYPE_CHECKING:
    from .scene import Scene

#: Progress callback of a run: (stage, index, total); ``index`` counts the stages done
#: (a float inside a stage that reports its share), so the status can say what runs.
Progress = Callable[[str, float, int], None]


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
        The SegmentParams fields the labels depend on.
    inputs : tuple of str
        Inputs besides the image it needs, any one of which selects it (e.g.
        ``("scribbles", "classifier")``); empty for an unsupervised method.

    Optional attributes, False when a method has none (read at registration):
    ``finds_k`` (``n_segments`` = 0 lets it find the number of segments) and
    ``block_maps`` (it cuts the w × w block grid and computes the harmonic coefficients,
    the PCA features and the reconstruction-error map in any case, as the thesis method
    does: its runs show those maps, summaries name the block grid, the time series cuts
    its blocks and the memory estimate counts them).
    """

    name: str
    title: str
    reads: tuple[str, ...]
    inputs: tuple[str, ...]

    def stages(self, params: SegmentParams) -> tuple[str, ...]:
        """Its stages in the order they run (after the shared ``polarisation``)."""
        ...

    def segment(
        self, scene: Scene, params: SegmentParams, inputs: dict[str, Any], run: MethodRun
    ) -> MethodOutput:
        """Labels of the scene's image. Calls ``run.begin(stage)`` before each of its
        stages (which also raises :class:`~napari_polarseg.engine.errors.Cancelled` on a
        stop request) and honours ``scene.region`` (nothing outside it may move a
        label inside it)."""
        ...


@dataclass
class MethodRun:
    """Progress and cancellation of one run over a list of stages.

    :meth:`begin` reports ``(stage, stages done, total)`` *before* the stage runs, so a
    status line names the stage that is running; :meth:`within` reports the share of it
    done (chunked loops); both raise :class:`Cancelled` when ``cancel()`` is True.
    """

    names: list[str]
    cancel: Callable[[], bool] | None = None
    progress: Progress | None = None
    current: str = ""

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

    def finish(self) -> None:
        """Every stage is done."""
        if self.progress is not None:
            self.progress("done", float(self.total), self.total)

    def index(self, stage: str) -> int:
        return self.names.index(stage) if stage in self.names else 0
