"""How an input is read: :class:`ReadOptions`, each option described once (:class:`ReadSpec`).

One type serves :func:`~napari_polarseg.io.read_stack` (its keywords build one), the
segment job and every scene of a batch (:mod:`napari_polarseg.jobs`,
:mod:`napari_polarseg.batch`) and the command line: the reading flags of every
subcommand are made from the specs (:func:`napari_polarseg.cli.options.add_read_options`),
and :meth:`ReadOptions.to_args` turns options back into those flags (the record a batch
keeps in each scene's completion marker).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..engine.limits import memory_limit
from ..engine.physics.colour_mosaic import BAYER_ORDERS
from ..engine.physics.mosaic import DEMOSAIC_METHODS


@dataclass(frozen=True)
class ReadSpec:
    """How one :class:`ReadOptions` field is asked for on the command line.

    Attributes
    ----------
    flag : str
        The option, e.g. ``"--dark-frame"``; its argparse ``dest`` is :attr:`dest`.
    help : str
        What the option does (``--help``); ``{input}`` stands for ``INPUT`` or, in a
        command with one stack per INPUT, ``every INPUT`` (:meth:`help_for`).
    kind : str
        How the word on the command line is parsed: ``angles`` (comma-separated degrees),
        ``number``, ``level`` (number, ``auto`` or ``none``), ``dark_level`` (number or
        ``none``), ``gib`` (positive GiB), ``bayer``, ``int``, ``file``, ``choice``
        (:attr:`choices`) or ``switch`` (present or not).
    metavar : str or None
        The argparse metavar.
    choices : tuple of str or None
        The words a ``choice`` option takes.
    stack : bool
        Whether :func:`~napari_polarseg.io.read_stack` uses the option (else the job reads
        it: mask, dark level, registration, label files, ground truth).
    """

    flag: str
    help: str
    kind: str = "file"
    metavar: str | None = None
    choices: tuple[str, ...] | None = None
    stack: bool = False

    def help_for(self, unit: str) -> str:
        """The help of a command whose INPUTs are each a ``unit`` (``stack``: the INPUTs
        are one stack)."""
        return self.help.replace("{input}", "INPUT" if unit == "stack" else "every INPUT")

    @property
    def dest(self) -> str:
        """The argparse attribute of the flag (``--max-memory`` -> ``max_memory``)."""
        return self.flag.lstrip("-").replace("-", "_")


def _option(default: Any, **spec: Any) -> Any:
    """A :class:`ReadOptions` field with its :class:`ReadSpec` in the field's metadata."""
    return field(default=default, metadata={"spec": ReadSpec(**spec)})


#: The words of :attr:`ReadOptions.lazy`.
LAZY_CHOICES = ("auto", "always", "never")

_SENSOR_NOTE = "A frame named after a Sony sensor (..._IMX250MZR.png, ..._IMX250MYR.png)"


@dataclass(frozen=True)
class ReadOptions:
    """How an input is read and what else is read with it (one description per option,
    in the field's :class:`ReadSpec`; :func:`read_specs`).

    The fields are in the order :meth:`to_args` writes them (a batch compares that record
    to resume). Angles are degrees; levels are in the input's units.

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
    max_memory_gib : float or None
        Memory limit of the read and the run, GiB (None: ``$POLARSEG_MAX_BYTES`` or the
        engine's default, :func:`~napari_polarseg.engine.limits.default_max_bytes`).
    lazy : str
        Leave a tiled TIFF or a Zarr stack on disk and read it block by block
        (:mod:`napari_polarseg.io.lazy_stack`): ``auto`` (when larger than
        :data:`~napari_polarseg.io.lazy_stack.LAZY_BYTES`), ``always`` or ``never``.
    classifier, scribbles : str or None
        A saved pixel classifier (``.polarseg-clf``), or a strokes file to train one on:
        it labels the pixels instead of the cut.
    dark_frame : str, path or ndarray (H, W), or None
        Dark frame subtracted from every frame (an array only from Python).
    offset : float or None
        Constant black level subtracted from every sample (input units).
    saturation, dark_level : float, "auto" or None
        Samples at or above ``saturation`` are saturated ("auto": the type's maximum),
        those at or below ``dark_level`` (after subtraction) black; input units; None: no
        check.
    mask : str or None
        Region file (labels image, non-zero = use).
    ground_truth : str or None
        True materials (labels image): ``evaluation.json`` is written.
    register : bool
        Align the frames to the first (sub-pixel phase correlation) first.
    """

    angles_deg: tuple[float, ...] | None = _option(
        None,
        flag="--angles",
        kind="angles",
        metavar="A,B,...",
        stack=True,
        help="polariser angle of each frame in degrees, in frame order (overrides the file)",
    )
    mosaic_deg: tuple[float, ...] | None = _option(
        None,
        flag="--mosaic",
        kind="angles",
        metavar="A,B,C,D",
        stack=True,
        help="{input} is one raw polarisation-camera frame; the 2x2 super-pixel angles in "
        "row-major order (Sony IMX250MZR: 90,45,135,0). Outputs are then half the raw "
        "frame's height and width (full size with --demosaic interpolated). "
        f"{_SENSOR_NOTE} needs no --mosaic",
    )
    demosaic: str = _option(
        "superpixel",
        flag="--demosaic",
        kind="choice",
        choices=DEMOSAIC_METHODS,
        stack=True,
        help="mosaic decoding: one output pixel per 2x2 super-pixel, or full resolution by "
        "bilinear interpolation of each angle [superpixel]",
    )
    bayer: str | None = _option(
        None,
        flag="--bayer",
        kind="bayer",
        metavar="ORDER",
        stack=True,
        help="with --mosaic: the raw frame is a colour-polarisation mosaic whose 2x2 "
        "polariser super-pixels lie under this Bayer colour order, row-major "
        f"({', '.join(BAYER_ORDERS)}; Sony IMX250MYR/IMX253MYR: RGGB). Outputs are then a "
        "quarter of the raw frame's height and width (full size with --demosaic "
        "interpolated); the luminance 0.299 R + 0.587 G + 0.114 B is segmented",
    )
    channel: int | None = _option(
        None,
        flag="--channel",
        kind="int",
        metavar="C",
        stack=True,
        help="colour channel to use (default: BT.601 luma)",
    )
    max_memory_gib: float | None = _option(
        None,
        flag="--max-memory",
        kind="gib",
        metavar="SIZE",
        stack=True,
        help="memory limit of the read and the run, GiB, or with a unit (20G, 512M): the "
        "tile size of a large image follows from it; inputs and runs that would need more "
        "even tiled are refused [$POLARSEG_MAX_BYTES, or 16G or 3/4 of the machine's "
        "memory when less]",
    )
    lazy: str = _option(
        "auto",
        flag="--lazy",
        kind="choice",
        choices=LAZY_CHOICES,
        stack=True,
        help="read a tiled TIFF or a Zarr stack block by block instead of whole: 'auto' when "
        "it decodes to more than 256 MiB, 'always', 'never' [auto]",
    )
    classifier: str | None = _option(
        None,
        flag="--classifier",
        metavar="FILE",
        help="apply a saved pixel classifier (.polarseg-clf, from --save-classifier or the "
        "plugin's Save classifier...) instead of the unsupervised method; nothing is retrained",
    )
    dark_frame: Any = _option(
        None,
        flag="--dark-frame",
        metavar="FILE",
        stack=True,
        help="dark frame (lens capped) subtracted from every frame, or from the raw mosaic",
    )
    offset: float | None = _option(
        None,
        flag="--offset",
        kind="number",
        metavar="V",
        stack=True,
        help="constant black level subtracted from every sample (after --dark-frame)",
    )
    saturation: float | str | None = _option(
        "auto",
        flag="--saturation",
        kind="level",
        metavar="LEVEL",
        stack=True,
        help="samples at or above LEVEL (in the file's units, before --dark-frame/--offset) "
        "are saturated and their pixels left out; 'auto' = the integer type's maximum (255, "
        "65535; 4095 for a 12-bit TIFF), 'none' = no check [auto]",
    )
    dark_level: float | None = _option(
        0.0,
        flag="--dark-level",
        kind="dark_level",
        metavar="LEVEL",
        help="samples at or below LEVEL (after subtraction) are black and their pixels left "
        "out; 'none' = no check [0]",
    )
    mask: str | None = _option(
        None,
        flag="--mask",
        metavar="FILE",
        help="a region (labels image: TIFF, PNG, .npy; non-zero = use): only its pixels "
        "enter the fit and the block features",
    )
    scribbles: str | None = _option(
        None,
        flag="--scribbles",
        metavar="FILE",
        help="strokes (labels image: TIFF, PNG, .npy/.npz; the outputs' height x width; 0 = "
        "unlabelled, 1, 2, ... = materials, at least two): the labels come from a pixel "
        "classifier (extremely randomised trees on multi-scale polarisation features) trained "
        "on the scribbled pixels instead of the unsupervised method; also writes "
        "probabilities.tif and uncertainty.tif",
    )
    ground_truth: str | None = _option(
        None,
        flag="--ground-truth",
        metavar="FILE",
        help="true materials (labels image, the outputs' size): writes evaluation.json "
        "(adjusted Rand index, IoU per segment, block accuracy) and adds it to summary.json",
    )
    register: bool = _option(
        False,
        flag="--register",
        kind="switch",
        help="align the frames to the first by sub-pixel phase correlation first (shifts "
        "are reported and written to params.json)",
    )

    def max_bytes(self) -> int:
        """The memory limit in bytes (:func:`napari_polarseg.engine.limits.memory_limit`)."""
        gib = self.max_memory_gib
        return memory_limit(None if gib is None else gib * 2**30)

    def to_args(self) -> list[str]:
        """The command-line options that ask for these options (defaults left out): the
        valued options in field order, then the switches."""
        values: list[str] = []
        switches: list[str] = []
        for f in fields(self):
            spec: ReadSpec = f.metadata["spec"]
            value = getattr(self, f.name)
            if _same(value, f.default):
                continue
            if spec.kind == "switch":
                switches.append(spec.flag)
            else:
                values += [spec.flag, option_text(value)]
        return values + switches


def _same(value: Any, default: Any) -> bool:
    """Whether an option's value is its default (an array never is)."""
    if isinstance(value, np.ndarray):
        return False
    return bool(value == default) if value is not None else default is None


def option_text(value: Any) -> str:
    """An option's value as its flag spells it: ``none``, comma-separated angles, a file."""
    if value is None:
        return "none"
    if isinstance(value, (tuple, list)):
        return ",".join(f"{float(v):g}" for v in value)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return str(value)


def read_specs() -> dict[str, ReadSpec]:
    """:class:`ReadOptions` field -> its :class:`ReadSpec`, in field order."""
    return {f.name: f.metadata["spec"] for f in fields(ReadOptions)}


def options_from_values(values: dict[str, Any]) -> ReadOptions:
    """:class:`ReadOptions` from a mapping of argparse ``dest`` (or field name) -> value, as
    a command line parses them: angles become tuples of float, the word ``none`` None; a
    name the mapping lacks or holds as None keeps its default (``none`` is how a command
    line asks for no check)."""
    kwargs: dict[str, Any] = {}
    for name, spec in read_specs().items():
        value = values.get(spec.dest, values.get(name))
        if value is None:
            continue
        if spec.kind == "angles":
            value = tuple(float(v) for v in np.ravel(value))
        elif value == "none":
            value = None
        elif spec.kind == "switch":
            value = bool(value)
        kwargs[name] = value
    return ReadOptions(**kwargs)
