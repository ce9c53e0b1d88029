"""What a pipeline run produces: the stage values and the assembled result.

:class:`Normals` and :class:`Reconstruction` are the values of the ``normals`` and
``reconstruction`` stages (:mod:`.stages`); :class:`SegmentationResult` is everything one
run produced (:meth:`.pipeline.Pipeline.result`); :class:`ScribbleSegmentation` what
:func:`.classifier.scribbles.scribble_segmentation` returns.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from .degenerate import DegenerateCheck, degenerate_result, segment_sizes
from .materials import Materials
from .params import SegmentParams
from .registered import computes_block_maps


@dataclass
class Normals:
    """Value of the ``normals`` stage: zenith and azimuth (radians, H × W) and the pixels
    whose degree of polarisation was clamped to the model's range."""

    zenith: np.ndarray
    azimuth: np.ndarray
    clamped: np.ndarray


@dataclass
class Reconstruction:
    """Value of the ``reconstruction`` stage: Î rebuilt from the harmonics and its
    absolute error |Î_rec − Î| (H × W, intensity units)."""

    intensity: np.ndarray
    error: np.ndarray

    @property
    def mean_error(self) -> float:
        return float(np.mean(self.error))


@dataclass
class SegmentationResult:
    """Everything one pipeline run produced (arrays are H × W unless noted).

    ``labels`` covers every input pixel (remainder strips take their nearest block's
    label); ``block_labels`` is (H // w, W // w). Angles are radians. ``residual`` is the
    RMS residual of the sinusoid fit. ``valid`` marks the pixels the block features and
    the reconstruction fit used (inside the pixel mask and with Î > 0); ``mask_counts``
    holds the pixel counts per exclusion reason
    (:meth:`~napari_polarseg.engine.physics.pixel_mask.PixelMask.counts`);
    ``duplicate_angle_frames`` lists the frames taken at a repeated polariser angle
    (modulo π), which were averaged before the fit. ``cut_limits`` holds the cut's
    work counts (:meth:`~napari_polarseg.engine.graph.ncut.CutTree.cut_limits`: eigensolves
    capped, segments with an isolated block not solved, products); empty when labels
    came from elsewhere (scribbles). ``superpixels`` is the record of the superpixel
    methods (``"superpixels"``, ``"valid_superpixels"``, ``"surface_superpixels"``):
    ``surface_share`` and ``close_up``
    (:class:`~napari_polarseg.engine.unsupervised.params.UnsupervisedResult`); empty
    otherwise. ``method`` names the segmentation method that made ``labels`` and
    ``method_record`` is what it reported. ``coefficients``, ``features`` and
    ``explained_variance_ratio`` (the thesis maps) and the reconstruction are None when
    the run did not compute them (other methods, unless asked for). ``materials``: the
    scribble value and name of every label when a scribble classifier made them
    (:class:`~napari_polarseg.engine.materials.Materials`; None for the other methods).
    ``on_blocks``: the run worked on the w × w block grid (the method cuts blocks or the
    thesis maps were computed); only then does :meth:`summary` name the grid
    (``n_blocks``, ``block_grid``). The number of segments and the degenerate check
    read the block grid only for a method that cuts it (:attr:`cuts_blocks`); for the
    others ``block_labels`` is the pixel labels sampled on the grid, and they read
    ``labels``.
    """

    params: SegmentParams
    intensity: np.ndarray
    dop: np.ndarray
    phase: np.ndarray
    residual: np.ndarray
    zenith: np.ndarray
    azimuth: np.ndarray
    clamped: np.ndarray
    coefficients: np.ndarray | None
    features: np.ndarray | None
    explained_variance_ratio: np.ndarray | None
    block_labels: np.ndarray
    labels: np.ndarray
    ncut_values: list[float]
    timings: dict[str, float]
    recomputed: list[str] = field(default_factory=list)
    reconstruction: np.ndarray | None = None
    reconstruction_error: np.ndarray | None = None
    valid: np.ndarray | None = None
    mask_counts: dict[str, Any] = field(default_factory=dict)
    duplicate_angle_frames: list[list[int]] = field(default_factory=list)
    cut_limits: dict[str, int] = field(default_factory=dict)
    superpixels: dict[str, Any] = field(default_factory=dict)
    method: str = "thesis"
    method_record: dict[str, Any] = field(default_factory=dict)
    materials: Materials | None = None
    on_blocks: bool = True

    @property
    def cuts_blocks(self) -> bool:
        """The method that made ``labels`` cuts the w × w block grid (it declares
        ``block_maps``: the thesis method); False for the others, the classifier too."""
        return computes_block_maps(self.method)

    @property
    def n_segments(self) -> int:
        """The number of segments: the cut's (``block_labels``) for a method that cuts
        blocks, else the distinct values of the pixel labels."""
        if self.cuts_blocks:
            return int(self.block_labels.max()) + 1
        return int(segment_sizes(self.labels).size)

    @property
    def n_clamped(self) -> int:
        return int(np.count_nonzero(self.clamped))

    @property
    def mean_reconstruction_error(self) -> float | None:
        """Mean absolute reconstruction error over the used pixels (``valid``)."""
        if self.reconstruction_error is None:
            return None
        if self.valid is not None and not self.valid.all():
            return float(np.mean(self.reconstruction_error[self.valid]))
        return float(np.mean(self.reconstruction_error))

    def degenerate(self) -> DegenerateCheck:
        """Whether (nearly) every pixel is in one segment
        (:func:`~napari_polarseg.engine.degenerate.degenerate_result`).

        A method that cuts blocks (:attr:`cuts_blocks`): over every pixel, with its
        minimum segment size ``min_segment_blocks`` · w² pixels. The others: their pixel
        labels over the used pixels (``valid``), no minimum size; one segment is
        degenerate when more were asked for (``n_segments``, 0 = found: more; a
        classifier: its number of materials).
        """
        p = self.params
        if self.cuts_blocks:
            return degenerate_result(
                self.labels, p.min_segment_blocks * p.window**2, requested=p.n_segments
            )
        asked = len(self.materials.values) if self.materials is not None else p.n_segments
        return degenerate_result(self.labels, requested=asked or None, valid=self.valid)

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures of the run (stage seconds, segments, variance, error).

        ``degenerate`` (with ``largest_segment_share`` and ``degenerate_reason``): see
        :meth:`degenerate`; ``cut_limits``, ``superpixels``: see the class docstring;
        ``n_blocks`` and ``block_grid`` only for a run on blocks (:attr:`on_blocks`).
        """
        check = self.degenerate()
        evr = self.explained_variance_ratio
        blocks = {
            "n_blocks": int(self.block_labels.size),
            "block_grid": list(self.block_labels.shape),
        }
        return {
            "method": self.method,
            # which maps of the thesis method this run computed (others: when asked)
            "thesis_maps": self.features is not None,
            "reconstruction_error_map": self.reconstruction_error is not None,
            "stage_seconds": {k: round(v, 6) for k, v in self.timings.items()},
            # stages this run computed (the others came from the cache) and their time
            "recomputed_stages": list(self.recomputed),
            "total_seconds": round(sum(self.timings[s] for s in self.recomputed), 6),
            "n_segments": self.n_segments,
            "segment_pixels": np.bincount(self.labels.ravel()).tolist(),
            "degenerate": check.degenerate,
            "largest_segment_share": round(check.largest_share, 6),
            "degenerate_reason": check.reason,
            **(blocks if self.on_blocks else {}),  # a method that never saw blocks: none
            "n_components": None if self.features is None else int(self.features.shape[1]),
            "explained_variance": None if evr is None else float(np.sum(evr)),
            "explained_variance_ratio": None if evr is None else [float(v) for v in evr],
            "ncut_values": [float(v) for v in self.ncut_values],
            "clamped_pixels": self.n_clamped,
            "mean_reconstruction_error": self.mean_reconstruction_error,
            "fit": self.params.fit,
            "mask": dict(self.mask_counts),
            "averaged_duplicate_angles": [list(g) for g in self.duplicate_angle_frames],
            "cut_limits": dict(self.cut_limits),
            "superpixels": dict(self.superpixels),
        }


class ScribbleSegmentation(NamedTuple):
    """What :func:`~napari_polarseg.engine.classifier.scribbles.scribble_segmentation` returns."""

    result: SegmentationResult
    probabilities: np.ndarray
    classes: np.ndarray
    training_blocks: int
