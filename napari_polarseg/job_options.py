"""What ``polarseg segment`` (and each scene of a batch) is asked for: how to read the
input (:class:`ReadOptions`), which optional files to write (:class:`OutputOptions`), and
the command-line options that ask for both (:func:`segment_args`, a batch's record).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .engine.limits import memory_limit


@dataclass(frozen=True)
class ReadOptions:
    """How ``segment`` reads an input and what else it reads with it.

    Attributes
    ----------
    angles_deg, mosaic_deg : tuple of float or None
        Polariser angle of every frame in frame order (overrides the file), or: the input
        is one raw mosaic frame with these 2 x 2 super-pixel angles; degrees.
    demosaic : str
        Mosaic decoding (``superpixel`` or ``interpolated``).
    bayer : str or None
        Bayer colour order of a colour-polarisation mosaic.
    channel : int or None
        Colour channel to use (None: BT.601 luma).
    dark_frame : str or None
        Dark frame file subtracted from every frame.
    offset : float or None
        Constant black level subtracted from every sample (input units).
    saturation, dark_level : float, "auto" or None
        Samples at or above ``saturation`` are saturated ("auto": the type's maximum),
        those at or below ``dark_level`` (after subtraction) black; input units; None: no
        check.
    mask : str or None
        Region file (labels image, non-zero = use).
    register : bool
        Align the frames to the first (sub-pixel phase correlation) first.
    max_memory_gib : float or None
        Memory limit of the read and the run, GiB (None: ``$POLARSEG_MAX_BYTES`` or 8).
    scribbles, classifier : str or None
        Strokes file to train a pixel classifier on, or a saved one (``.polarseg-clf``):
        it labels the pixels instead of the cut.
    ground_truth : str or None
        True materials (labels image): ``evaluation.json`` is written.
    """

    angles_deg: tuple[float, ...] | None = None
    mosaic_deg: tuple[float, ...] | None = None
    demosaic: str = "superpixel"
    bayer: str | None = None
    channel: int | None = None
    dark_frame: str | None = None
    offset: float | None = None
    saturation: float | str | None = "auto"
    dark_level: float | None = 0.0
    mask: str | None = None
    register: bool = False
    max_memory_gib: float | None = None
    scribbles: str | None = None
    classifier: str | None = None
    ground_truth: str | None = None

    def max_bytes(self) -> int:
        """The memory limit in bytes (:func:`napari_polarseg.engine.limits.memory_limit`)."""
        gib = self.max_memory_gib
        return memory_limit(None if gib is None else gib * 2**30)


@dataclass(frozen=True)
class OutputOptions:
    """Which optional files a result folder gets.

    Attributes
    ----------
    overview, plots : bool
        ``overview.png`` (matplotlib figure); the analyst's plots as PNGs in ``plots/``.
    save_classifier : str or None
        With scribbles: also write the trained classifier to this file.
    thesis_maps : bool
        Also compute the thesis maps for a method that does not need them (harmonic
        coefficients and PCA features: the feature columns of ``segments.csv`` and the
        plots; the reconstruction-error map ``reconstruction_error.tif``). The thesis
        method always computes them; ``plots`` asks for them too.
    """

    overview: bool = False
    plots: bool = False
    save_classifier: str | None = None
    thesis_maps: bool = False


def _angles_text(values: Sequence[float]) -> str:
    return ",".join(f"{v:g}" for v in values)


def _level_text(value: float | str | None, default: float | str) -> str | None:
    """A level option's text: None when it is the default, ``none`` for no check."""
    if value is None:
        return "none"
    return None if value == default else str(value)


def segment_args(read: ReadOptions, outputs: OutputOptions) -> list[str]:
    """The ``polarseg segment`` options that ask for ``read`` and ``outputs`` (the record
    a batch keeps in each scene's completion marker; defaults are left out)."""
    out: list[str] = []
    values: list[tuple[str, Any]] = [
        ("--angles", None if read.angles_deg is None else _angles_text(read.angles_deg)),
        ("--mosaic", None if read.mosaic_deg is None else _angles_text(read.mosaic_deg)),
        ("--demosaic", None if read.demosaic == "superpixel" else read.demosaic),
        ("--bayer", read.bayer),
        ("--channel", read.channel),
        ("--max-memory", read.max_memory_gib),
        ("--classifier", read.classifier),
        ("--dark-frame", read.dark_frame),
        ("--offset", read.offset),
        ("--saturation", _level_text(read.saturation, "auto")),
        ("--dark-level", _level_text(read.dark_level, 0.0)),
        ("--mask", read.mask),
        ("--scribbles", read.scribbles),
        ("--ground-truth", read.ground_truth),
    ]
    for flag, value in values:
        if value is not None:
            out += [flag, str(value)]
    flags = [
        ("--register", read.register),
        ("--overview", outputs.overview),
        ("--plots", outputs.plots),
        ("--thesis-maps", outputs.thesis_maps),
    ]
    out += [flag for flag, on in flags if on]
    if outputs.save_classifier:
        out += ["--save-classifier", outputs.save_classifier]
    return out
