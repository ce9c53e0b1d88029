"""Reading angle stacks (no napari, no Qt): :func:`read_stack` and the checks of its result.

Angles are **degrees** in files and on the command line (the engine takes radians:
:attr:`StackData.angles_rad`). Every problem with an input file is raised as
:class:`~napari_polarseg.engine.PolarsegError` with one line that names the file.

Inputs :func:`read_stack` understands
--------------------------------------
- **Multi-page TIFF** ``.tif``/``.tiff``, one page per polariser angle. The angles come
  from the ``angles_deg`` argument or else from the file's metadata
  (:mod:`napari_polarseg.tiff_angles`): any JSON ImageDescription of any page with an
  ``"angles"`` key — tifffile's shaped metadata (as
  :func:`~napari_polarseg.io.writers.write_stack_tiff` writes it,
  ``tifffile.imwrite(path, stack, metadata={"angles": [...]})``) or a plain JSON
  description (``description=json.dumps({"angles": [...]})``) — else the ImageJ slice
  labels, else the OME channel names, each frame's angle being the last number of its
  label (``pol_045`` → 45, ``0°`` → 0).
- **NumPy** ``.npz`` with arrays ``stack`` (N, H, W) and ``angles`` (degrees), optionally
  ``labels`` (H, W ground truth) and ``params`` (a JSON string of segmentation
  parameters); loaded with ``allow_pickle=False``. A plain ``.npy`` stack needs the angles.
- **A folder of frames, or a list of frame files** (``.png``, ``.tif``, ``.tiff``,
  ``.jpg``, ``.jpeg``; hidden files in a folder are skipped). Unless the angles are given,
  each frame's angle in degrees is **the last number in its file name without the
  extension**: ``leaf_030.png`` → 30, ``nir_45_aligned.tif`` → 45,
  ``scene-b_22.5deg.png`` → 22.5 (digits with an optional decimal part; no sign). Frames
  are then sorted by angle. With explicit angles (one per file) the frames of a folder
  are taken in natural file-name order (``f2`` before ``f10``), those of a list in the
  order given.
- **A raw polarisation-camera frame** (any of the image types above) with ``mosaic`` set:
  the four polariser angles of the 2 × 2 super-pixel in row-major order (Sony IMX250MZR:
  90, 45, 135, 0). It is split into four frames at **half resolution**
  (``demosaic="superpixel"``) or interpolated to **full resolution**
  (``demosaic="interpolated"``, bilinear), see :mod:`napari_polarseg.engine.physics.mosaic`.
- **A raw colour-polarisation frame** with ``mosaic`` and ``bayer`` set (the Bayer order
  of the 2 × 2 polariser super-pixels, ``"RGGB"`` for the Sony IMX250MYR/IMX253MYR): a
  4 × 4 period decoded to a (colour, angle) stack at a quarter of the resolution or, with
  ``demosaic="interpolated"``, at full resolution
  (:mod:`napari_polarseg.engine.physics.colour_mosaic`). :attr:`StackData.stack` is then the
  luminance stack (Rec. 601: 0.299 R + 0.587 G + 0.114 B), which is segmented, and
  :attr:`StackData.colour_stack` the R, G, B stacks, which feed the pixel classifier.
- **A file named after a Sony polarisation sensor**
  (:func:`~napari_polarseg.io.angles.sensor_from_name`): a single frame whose name
  carries ``IMX250MZR``, ``IMX253MZR`` or ``IMX264MZR`` (mono) or ``IMX250MYR`` or
  ``IMX253MYR`` (colour) is read as that sensor's raw frame without ``mosaic``: layout
  90, 45, 135, 0, and Bayer order RGGB for the colour sensors. A ``mosaic`` or ``bayer``
  given explicitly wins over the name.

Colour frames (H, W, 3 or 4) become grey by the ITU-R BT.601 luma weights
0.299 R + 0.587 G + 0.114 B (alpha ignored) unless ``channel`` picks one channel.

Bit depth, saturation and black level
-------------------------------------
8-bit and 16-bit integer data (a 12-bit camera's frames are usually stored as 16-bit)
and float data are read as they are. Saturated samples are found on the data as
recorded, before any conversion: at or above ``saturation`` — by default (``"auto"``)
the integer dtype's maximum, or 2**bits − 1 when a TIFF declares fewer bits per sample
(12-bit TIFFs), and none for float data — and returned as :attr:`StackData.saturated`
for :func:`~napari_polarseg.engine.physics.pixel_mask.validity_mask`. A dark frame (``dark``: an
image of the same size as the raw frames, or an array) and/or a constant ``offset`` are
then subtracted and negative results set to 0 (the stack becomes float64).

Repeated angles (the same angle modulo 180°) are kept as separate frames here; the
engine averages them before the fit.

Checks
------
After reading: angles present, one per frame, finite, at least 3 distinct modulo 180°;
frames of one size; no negative intensity (light through a polariser is never negative:
subtract less, or shift the data with ``offset``); no frame without a finite value or
constant over the whole frame (a blank, black or fully saturated capture). Before
reading, the size announced by the file's header is checked against the memory limit of
:mod:`napari_polarseg.engine.limits`, so an absurd size is refused with the memory it
would need instead of exhausting the machine.


The readers of each kind of input are in :mod:`napari_polarseg.io.stack_formats`, single
frames in :mod:`napari_polarseg.io.frames`, NumPy files in :mod:`napari_polarseg.io.arrays`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..engine.errors import PolarsegError
from ..engine.physics.colour_mosaic import check_bayer
from ..engine.physics.mosaic import DEMOSAIC_METHODS
from ..engine.physics.polarimage import distinct_angle_count
from .angles import sensor_from_name
from .arrays import read_arrays
from .common import PathLike, finite_number, format_numbers, input_error
from .frames import FRAME_SUFFIXES, folder_frames, read_frame, single_frame_file
from .lazy_stack import frame_extremes, is_lazy, lazy_read_error, wants_lazy
from .read_options import LAZY_CHOICES, ReadOptions
from .stack_data import BlackLevel, StackData
from .stack_formats import STACK_FORMATS, read_frame_files, read_mosaic

#: File types read as whole stacks (the suffixes of :data:`STACK_FORMATS`).
STACK_SUFFIXES = tuple(STACK_FORMATS)


def _frame_label(k: int, angles: np.ndarray) -> str:
    return f"frame {k} ({angles[k]:g} degrees)"


def _check_angles(path: Path, angles: np.ndarray | None, n: int) -> np.ndarray:
    """The angles as float64 (N,): present, one per frame, finite, 3 distinct mod 180°."""
    if angles is None:
        raise input_error(
            path,
            "no polariser angles in the file; give them in degrees, one per frame "
            "(e.g. --angles 0,45,90,135)",
        )
    angles = np.asarray(angles, dtype=np.float64).ravel()
    if angles.size != n:
        raise input_error(path, f"{n} frames but {angles.size} angles ({format_numbers(angles)})")
    if not np.all(np.isfinite(angles)):
        raise input_error(
            path, f"polariser angles must be finite numbers, got {format_numbers(angles)}"
        )
    distinct = distinct_angle_count(np.deg2rad(angles))
    if distinct < 3:
        raise input_error(
            path,
            f"need at least 3 distinct polariser angles (modulo 180 degrees), got {distinct} "
            f"({format_numbers(angles)})",
        )
    return angles


def _frame_ranges(path: Path, stack: Any, angles: np.ndarray) -> tuple[Any, Any]:
    """Lowest and highest finite value of each frame (a lazy stack: read block by block)."""
    try:
        lo, hi, finite = frame_extremes(stack)
    except Exception as exc:
        if not is_lazy(stack) or isinstance(exc, PolarsegError):
            raise
        raise lazy_read_error(path, exc) from exc
    if finite is None:
        return lo, hi
    if not finite.any():
        raise input_error(path, "the data has no finite values (all NaN or infinite)")
    empty = np.flatnonzero(~finite)
    if empty.size:
        raise input_error(
            path,
            f"{_frame_label(int(empty[0]), angles)} has no finite values (all NaN or infinite)",
        )
    return lo, hi


def _check_stack_data(path: Path, data: StackData) -> StackData:
    """The checks after reading (module docstring, *Checks*); the angles become float64."""
    stack = data.stack
    n = stack.shape[0]
    angles = _check_angles(path, data.angles_deg, n)
    if min(stack.shape[1:]) < 1:
        raise input_error(path, f"the frames are empty (shape {stack.shape})")
    lo, hi = _frame_ranges(path, stack, angles)
    negative = np.flatnonzero(lo < 0)
    if negative.size:
        k = int(negative[0])
        raise input_error(
            path,
            f"negative intensities (down to {float(lo[k]):g} in {_frame_label(k, angles)}): "
            "light through a polariser is never negative; subtract a smaller offset or dark "
            "frame, or shift the data with a negative --offset",
        )
    if stack.shape[1] * stack.shape[2] > 1:
        constant = np.flatnonzero(lo == hi)
        if constant.size:
            k = int(constant[0])
            raise input_error(
                path,
                f"{_frame_label(k, angles)} is constant (every pixel is {float(lo[k]):g}): "
                "a blank, black or fully saturated capture?",
            )
    data.angles_deg = angles
    return data


def _resolve_dark(dark: Any, channel: int | None) -> tuple[np.ndarray | None, str | None]:
    """The dark frame as an array and, when read from a file, its name."""
    if dark is None:
        return None, None
    if isinstance(dark, (str, os.PathLike)):
        p = Path(dark)
        if p.suffix.lower() == ".npy":
            if not p.is_file():
                raise input_error(p, "no such file")
            array = read_arrays(p, ("dark",))[0]
        else:
            array = read_frame(p, channel)
        array = np.asarray(array)
        if array.ndim != 2 or array.dtype.kind not in "biuf":
            raise input_error(
                p, f"a dark frame must be one 2-D image, got an array of {array.shape}"
            )
        return array, os.fspath(p)
    array = np.asarray(dark)
    if array.ndim != 2 or array.dtype.kind not in "biuf":
        raise PolarsegError(f"a dark frame must be one 2-D image, got an array of {array.shape}")
    return array, None


def _input_paths(path: PathLike | Sequence[PathLike]) -> tuple[Path, list[Path] | None]:
    """The path named in messages and, for a list of several files, the files."""
    if not isinstance(path, (list, tuple)):
        return Path(os.fspath(path)), None
    if not path:
        raise PolarsegError("no input files given")
    files = [Path(os.fspath(f)) for f in path]
    return files[0], (files if len(files) > 1 else None)


def _checked(read: ReadOptions) -> ReadOptions:
    """The reading options checked: demosaicing method, Bayer order (upper case),
    saturation level and offset (finite numbers)."""
    if read.lazy not in LAZY_CHOICES:
        raise PolarsegError(f"lazy must be one of {', '.join(LAZY_CHOICES)}; got {read.lazy!r}")
    if read.demosaic not in DEMOSAIC_METHODS:
        raise PolarsegError(
            f"demosaic method must be one of {', '.join(DEMOSAIC_METHODS)}; got {read.demosaic!r}"
        )
    bayer = None if read.bayer is None else check_bayer(read.bayer)
    saturation, offset = read.saturation, read.offset
    if isinstance(saturation, str) and saturation != "auto":
        raise PolarsegError(f"saturation must be a number, 'auto' or None; got {saturation!r}")
    if saturation is not None and not isinstance(saturation, str):
        saturation = finite_number(saturation, "the saturation level")
    if offset is not None:
        offset = finite_number(offset, "the offset")
    read.max_bytes()  # a bad limit stops here
    return replace(read, bayer=bayer, saturation=saturation, offset=offset)


def _black_level(read: ReadOptions) -> BlackLevel:
    """What is subtracted from the samples (the dark frame read)."""
    dark, dark_name = _resolve_dark(read.dark_frame, read.channel)
    return BlackLevel(dark, dark_name, read.offset)


def _read_file_list(
    first: Path, files: list[Path], read: ReadOptions, black: BlackLevel
) -> StackData:
    """Several frame files, one per angle."""
    for f in files:
        if not f.exists():
            raise input_error(f, "no such file")
        if f.is_dir():
            raise input_error(f, "a list of frames must name image files, not folders")
    if read.mosaic_deg is not None or read.bayer is not None:
        raise input_error(first, "a mosaic layout needs a single raw frame, not a list of files")
    angles = read.angles_deg
    if angles is not None and len(angles) != len(files):
        raise input_error(first, f"{len(files)} files but {len(angles)} angles")
    return read_frame_files(first, files, angles is not None, read, black, "files")


def _read_stack_file(p: Path, read: ReadOptions, black: BlackLevel) -> StackData:
    """A file that holds a whole stack (TIFF, NumPy, Zarr), by its type
    (:data:`STACK_FORMATS`): lazily if the format can and :func:`wants_lazy` says so."""
    suffix = p.suffix.lower()
    if suffix in STACK_FORMATS:
        kind = STACK_FORMATS[suffix]
        if kind.lazy is not None and wants_lazy(read, kind.lazy.nbytes(p)):
            return kind.lazy.read(p, read, black)
        return kind.read(p, read, black)
    if suffix in FRAME_SUFFIXES:
        raise input_error(
            p,
            "a single image is not an angle stack: give a multi-page TIFF, an .npz, "
            "a folder of frames, or a mosaic layout for a raw polarisation-camera frame",
        )
    kinds = ", ".join(sorted(set(STACK_SUFFIXES + FRAME_SUFFIXES)))
    raise input_error(p, f"unsupported file type {suffix or '(none)'!r} (expected {kinds})")


def _read_path(p: Path, read: ReadOptions, black: BlackLevel) -> StackData:
    """One file or folder: a raw mosaic (given, or named after a sensor), a folder of
    frames, or a stack file."""
    if not p.exists():
        raise input_error(p, "no such file or folder")
    mosaic, bayer, given = read.mosaic_deg, read.bayer, read.angles_deg is not None
    if given and (mosaic is not None or bayer is not None):
        raise input_error(p, "give either the polariser angles or a mosaic layout, not both")
    sensor = sensor_from_name(p) if single_frame_file(p) else None
    if sensor is not None and not given:
        mosaic = sensor.layout_deg if mosaic is None else mosaic
        bayer = sensor.bayer if bayer is None else bayer
    if bayer is not None and mosaic is None:
        raise input_error(p, "a Bayer order needs a mosaic layout (--mosaic)")
    if mosaic is not None:
        layout = tuple(float(a) for a in np.ravel(mosaic))
        data = read_mosaic(p, replace(read, mosaic_deg=layout, bayer=bayer), black)
        if sensor is not None:
            data.metadata["sensor"] = sensor.sensor
        return data
    if p.is_dir() and p.suffix.lower() not in STACK_FORMATS:
        return read_frame_files(p, folder_frames(p), given, read, black, "folder")
    return _read_stack_file(p, read, black)


def _note_reading(data: StackData, black: BlackLevel, angles_deg: Any) -> None:
    """Record the dark frame, the offset and where the angles came from; given angles
    replace those of the file."""
    if black.dark is not None:
        data.metadata["dark_frame"] = black.dark_name or "array"
    if black.offset is not None:
        data.metadata["offset"] = float(black.offset)
    if angles_deg is not None:
        data.angles_deg = np.asarray(angles_deg, dtype=np.float64).ravel()
        data.metadata["angles_from"] = "given"
    else:
        kind = data.metadata["format"]
        data.metadata.setdefault("angles_from", "names" if kind == "files" else kind)


def _options(options: ReadOptions | None, keywords: dict[str, Any]) -> ReadOptions:
    """``options``, or the options the keywords of :func:`read_stack` ask for (not both)."""
    defaults = {"demosaic": "superpixel", "saturation": "auto", "lazy": "auto"}
    changed = [k for k, v in keywords.items() if not _is(v, defaults.get(k))]
    if options is not None:
        if changed:
            raise TypeError(
                f"read_stack takes options or the keywords {', '.join(changed)}, not both"
            )
        return options
    angles, mosaic, max_bytes = (keywords.pop(k) for k in ("angles_deg", "mosaic", "max_bytes"))
    return ReadOptions(
        angles_deg=None if angles is None else tuple(np.ravel(angles).tolist()),
        mosaic_deg=None if mosaic is None else tuple(np.ravel(mosaic).tolist()),
        max_memory_gib=None if max_bytes is None else max_bytes / 2**30,
        dark_frame=keywords.pop("dark"),
        **keywords,
    )


def _is(value: Any, default: Any) -> bool:
    """Whether a keyword still has its default (an array never has)."""
    return not isinstance(value, np.ndarray) and (value is default or value == default)


def read_stack(
    path: PathLike | Sequence[PathLike],
    angles_deg: Sequence[float] | np.ndarray | None = None,
    mosaic: Sequence[float] | None = None,
    channel: int | None = None,
    *,
    demosaic: str = "superpixel",
    bayer: str | None = None,
    dark: PathLike | np.ndarray | None = None,
    offset: float | None = None,
    saturation: float | str | None = "auto",
    max_bytes: int | None = None,
    lazy: str = "auto",
    options: ReadOptions | None = None,
) -> StackData:
    """Read an angle stack from a TIFF, an ``.npz``/``.npy``, a folder, files or a mosaic.

    See the module docstring for the formats, the file-name rule and the checks.

    Parameters
    ----------
    path : str or path, or a sequence of them
        File or folder; or a list of frame files (one per angle).
    angles_deg : sequence of float, optional
        Polariser angle of each frame in degrees, in frame order (folder: natural
        file-name order; list of files: the order given). Overrides stored angles.
    mosaic : sequence of 4 floats, optional
        Read ``path`` as one raw polarisation-camera frame with this 2 × 2 super-pixel
        layout (degrees, row-major; :data:`~napari_polarseg.io.angles.DEFAULT_MOSAIC` for
        the Sony IMX250MZR). Without it, a single frame named after a Sony sensor
        (:func:`~napari_polarseg.io.angles.sensor_from_name`) takes the sensor's layout.
    channel : int, optional
        Colour channel to use for colour images (default: ITU-R BT.601 luma).
    demosaic : {"superpixel", "interpolated"}
        For a mosaic: half resolution, or full resolution by bilinear interpolation.
    bayer : {"RGGB", "BGGR", "GRBG", "GBRG"}, optional
        With ``mosaic``: the Bayer order (row-major) of a colour-polarisation mosaic's
        2 × 2 polariser super-pixels; default: the sensor's, for a file named after a
        colour sensor (``…IMX250MYR…``), else a mono mosaic.
    dark : path or array (H, W), optional
        Dark frame subtracted from every frame (from the raw frame, for a mosaic) after
        saturation was detected; negative results become 0.
    offset : float, optional
        Constant black level subtracted the same way.
    saturation : float, "auto" or None
        Level at or above which a recorded sample is saturated (:attr:`StackData.saturated`):
        ``"auto"`` = the integer dtype's maximum (2**bits − 1 for TIFFs with fewer bits
        per sample), nothing for float data; None = do not check.
    max_bytes : int, optional
        Memory limit for reading (default: :func:`~napari_polarseg.engine.limits.memory_limit`).
    lazy : {"auto", "always", "never"}
        Leave a TIFF or Zarr stack on disk (a Dask stack: :mod:`~napari_polarseg.io.lazy_stack`).
    options : ReadOptions, optional
        All of the above in one :class:`~napari_polarseg.io.read_options.ReadOptions`
        (its other fields are the job's), instead of the keywords: give one or the other.

    Returns
    -------
    StackData
        The stack (N, H, W), angles in degrees (N,), source, metadata, the saturated
        samples and, for an ``.npz`` with ``labels``, the ground truth.

    Raises
    ------
    PolarsegError
        With one line naming the file and the problem (module docstring, *Checks*): a
        missing, unreadable, truncated, non-image or too large file; missing or too few
        angles; frames of different sizes; bad data; an odd-sized mosaic; a bad option.

    """
    keywords = {k: v for k, v in locals().items() if k not in ("path", "options")}
    first, files = _input_paths(path)
    read = _checked(_options(options, keywords))
    black = _black_level(read)
    if files is not None:
        data = _read_file_list(first, files, read, black)
    else:
        data = _read_path(first, read, black)
    _note_reading(data, black, read.angles_deg)
    return _check_stack_data(first, data)
