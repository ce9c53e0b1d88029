"""Reading angle stacks and writing results (no napari, no Qt).

Angles are **degrees** in files and on the command line (the engine takes radians:
:attr:`StackData.angles_rad`). Every problem with an input file is raised as
:class:`~napari_polarseg.engine.PolarsegError` with one line that names the file.

Inputs :func:`read_stack` understands
--------------------------------------
- **Multi-page TIFF** ``.tif``/``.tiff``, one page per polariser angle. The angles come
  from the ``angles_deg`` argument or else from the file's metadata
  (:mod:`napari_polarseg.tiff_angles`): any JSON ImageDescription of any page with an
  ``"angles"`` key — tifffile's shaped metadata (as :func:`write_stack_tiff` writes it,
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
- **A file named after a Sony polarisation sensor** (:func:`sensor_from_name`): a single
  frame whose name carries ``IMX250MZR``, ``IMX253MZR`` or ``IMX264MZR`` (mono) or
  ``IMX250MYR`` or ``IMX253MYR`` (colour) is read as that sensor's raw frame without
  ``mosaic``: layout 90, 45, 135, 0, and Bayer order RGGB for the colour sensors. A
  ``mosaic`` or ``bayer`` given explicitly wins over the name.

Colour frames (H, W, 3 or 4) become grey by the ITU-R BT.601 luma weights
0.299 R + 0.587 G + 0.114 B (alpha ignored) unless ``channel`` picks one channel.

Bit depth, saturation and black level
-------------------------------------
8-bit and 16-bit integer data (a 12-bit camera's frames are usually stored as 16-bit)
and float data are read as they are. Saturated samples are found on the data as
recorded, before any conversion: at or above ``saturation`` — by default (``"auto"``)
the integer dtype's maximum, or 2**bits − 1 when a TIFF declares fewer bits per sample
(12-bit TIFFs), and none for float data — and returned as :attr:`StackData.saturated`
for :func:`~napari_polarseg.engine.physics.polarimage.validity_mask`. A dark frame (``dark``: an
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

Writers
-------
:func:`write_tiff`, :func:`write_stack_tiff`, :func:`write_json` and :func:`write_png`
write to a temporary file in the destination's directory and :func:`os.replace` it into
place (:func:`atomic_output`), so a failure never leaves a truncated file where a good one
was.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import re
import uuid
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from .engine.errors import PolarsegError
from .engine.limits import check_bytes, memory_limit
from .engine.params import SegmentParams
from .engine.physics.colour_mosaic import (
    COLOURS,
    IMX250MYR_BAYER,
    IMX250MYR_LAYOUT,
    check_bayer,
    demosaic_colour,
    demosaic_colour_flags,
    luminance,
)
from .engine.physics.mosaic import (
    DEMOSAIC_METHODS,
    IMX250MZR_LAYOUT,
    demosaic,
    demosaic_flags,
    subtract_dark,
)
from .engine.physics.pixel_mask import auto_saturation_level
from .engine.physics.polarimage import distinct_angle_count
from .tiff_angles import FROM_JSON, tiff_angles

PathLike = str | os.PathLike

#: File types read as single frames (in a folder, or as a raw mosaic).
FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
#: File types read as whole stacks.
STACK_SUFFIXES = (".tif", ".tiff", ".npz", ".npy")
#: File types read as masks (:func:`read_mask`).
MASK_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".npz")
#: ITU-R BT.601 luma weights of R, G, B.
LUMA_BT601 = np.array([0.299, 0.587, 0.114])
#: Default 2 x 2 super-pixel layout (degrees, row-major) of a polarisation camera.
DEFAULT_MOSAIC = IMX250MZR_LAYOUT

#: Sony polarisation sensors named in raw files: mono (``…MZR``) and colour (``…MYR``).
SENSOR_NAMES = re.compile(r"IMX2(?:50|53|64)M[ZY]R", re.IGNORECASE)

_NUMBER = re.compile(r"\d+(?:\.\d+)?")
#: tifffile log messages that mean the file is cut short or damaged.
_CORRUPT_HINTS = ("invalid page offset", "truncat", "corrupt", "failed to read", "invalid ifd")


@dataclass
class StackData:
    """An angle stack as read from disk.

    Attributes
    ----------
    stack : ndarray (N, H, W)
        Grey frames, real numbers (the file's dtype where no conversion was needed;
        float64 after dark subtraction, interpolated demosaicing or luma conversion).
    angles_deg : ndarray (N,) float64
        Polariser angle of each frame, degrees.
    source : str
        The file or folder read (the first file, for a list of files).
    metadata : dict
        What else was learned: ``format``, ``saturation_level`` (None: not checked),
        ``bits_per_sample`` (TIFF), and per format ``files`` (folder, list), ``demosaic``,
        ``mosaic_layout_deg`` and ``raw_shape`` (mosaic), ``params`` (npz), ``dark_frame``
        and ``offset`` (when subtracted), ``warnings``.
    ground_truth : ndarray (H, W) or None
        Reference labels shipped with the stack (``labels`` in an ``.npz``), if any.
    saturated : ndarray (N, H, W) of bool or None
        Samples at or above the saturation level in the data as recorded (for a mosaic:
        the demosaiced samples that draw on a saturated raw pixel); None when no level
        applies (float data with ``saturation="auto"``, or ``saturation=None``).
    colour_stack : ndarray (3, N, H, W) float64 or None
        For a colour-polarisation mosaic: the R, G, B stacks (``stack`` is their
        luminance); ``metadata["colours"]`` names them. None otherwise.
    """

    stack: np.ndarray
    angles_deg: np.ndarray
    source: str
    metadata: dict[str, Any] = field(default_factory=dict)
    ground_truth: np.ndarray | None = None
    saturated: np.ndarray | None = None
    colour_stack: np.ndarray | None = None

    @property
    def angles_rad(self) -> np.ndarray:
        """Polariser angles in radians, for the engine."""
        return np.deg2rad(self.angles_deg)


@dataclass
class _Options:
    """Reading options shared by the format readers."""

    channel: int | None = None
    saturation: float | str | None = "auto"
    limit: int = 0
    dark: np.ndarray | None = None
    dark_name: str | None = None
    offset: float | None = None

    @property
    def subtracts(self) -> bool:
        return self.dark is not None or self.offset is not None


# -- small helpers ------------------------------------------------------------------------


def _error(path: PathLike, problem: str) -> PolarsegError:
    return PolarsegError(f"{os.fspath(path)}: {problem}")


def _first_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def _fmt(values: Sequence[float]) -> str:
    return ", ".join(f"{float(v):g}" for v in values)


def _finite_number(value: Any, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise PolarsegError(f"{name} must be a finite number, got {value!r}")
    return number


def _dims(shape: Sequence[int]) -> str:
    return " x ".join(str(int(v)) for v in shape)


def read_params_dict(path: PathLike) -> dict[str, Any]:
    """The fields of a parameters JSON file, as ``polarseg segment --params`` reads it.

    Either a SegmentParams object (``SegmentParams.to_json``, what the plugin's *Save
    parameters…* writes) or a ``params.json`` written by ``polarseg`` (its ``"params"``
    entry). Invalid JSON, anything but a JSON object or an unreadable file raise
    :class:`PolarsegError` naming the file; the fields are not checked here.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise PolarsegError(f"{path}: cannot read the parameters file ({reason})") from None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise PolarsegError(f"{path}: parameters file is not valid JSON ({exc})") from None
    if isinstance(data, dict) and isinstance(data.get("params"), dict):
        data = data["params"]  # a params.json written by polarseg
    if not isinstance(data, dict):
        raise PolarsegError(f"{path}: parameters file must hold a JSON object")
    return data


def read_params_file(path: PathLike) -> SegmentParams:
    """SegmentParams from a parameters JSON file (:func:`read_params_dict`).

    Missing fields take the thesis defaults; an unknown field or a value out of range
    raise :class:`PolarsegError` naming the file.
    """
    data = read_params_dict(path)
    try:
        return SegmentParams.from_dict(data)
    except PolarsegError as exc:
        raise PolarsegError(f"{path}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise PolarsegError(f"{path}: a parameter has the wrong type ({exc})") from None


def parse_angles(text: str, option: str = "--angles") -> np.ndarray:
    """Parse comma-separated angles in degrees, e.g. ``"0,30,60,90"``.

    Parameters
    ----------
    text : str
        Numbers separated by commas (spaces allowed).
    option : str
        Name used in the error message.

    Returns
    -------
    ndarray (N,) float64
        The angles in degrees, in the given order.

    Raises
    ------
    PolarsegError
        If a value is empty, not a number, or not finite.

    Examples
    --------
    >>> parse_angles("0, 45,90,135").tolist()
    [0.0, 45.0, 90.0, 135.0]
    """
    parts = [p.strip() for p in str(text).split(",")]
    values = []
    for part in parts:
        try:
            value = float(part)
        except ValueError:
            value = math.nan
        if not part or not math.isfinite(value):
            raise PolarsegError(
                f"bad {option} value {text!r}: expected comma-separated numbers in degrees, "
                f"e.g. 0,45,90,135 (problem at {part!r})"
            )
        values.append(value)
    return np.array(values, dtype=np.float64)


def angle_from_name(name: PathLike) -> float | None:
    """Polariser angle in degrees carried by a file name: the last number of its stem.

    Parameters
    ----------
    name : str or path
        File name or path; only the name without its extension is looked at.

    Returns
    -------
    float or None
        The last run of digits (with an optional decimal part) in the stem, or None if
        the stem has no digits.

    Examples
    --------
    >>> angle_from_name("leaf_030.png"), angle_from_name("nir_45_aligned.tif")
    (30.0, 45.0)
    >>> angle_from_name("scene-b_22.5deg.png"), angle_from_name("dark.png")
    (22.5, None)
    """
    numbers = _NUMBER.findall(Path(name).stem)
    return float(numbers[-1]) if numbers else None


@dataclass(frozen=True)
class SensorDefaults:
    """Decoding of a raw frame named after a polarisation sensor.

    Attributes
    ----------
    sensor : str
        The sensor's name as found in the file name, upper case (e.g. ``"IMX250MYR"``).
    layout_deg : tuple of 4 floats
        Its 2 × 2 polariser layout, degrees, row-major.
    bayer : str or None
        Its Bayer order (colour sensors), None for a mono sensor.
    """

    sensor: str
    layout_deg: tuple[float, ...]
    bayer: str | None


def sensor_from_name(name: PathLike) -> SensorDefaults | None:
    """The sensor defaults of a raw frame whose file name names a Sony polarisation sensor.

    ``…IMX250MZR…``, ``…IMX253MZR…``, ``…IMX264MZR…`` (mono: layout 90, 45, 135, 0) and
    ``…IMX250MYR…``, ``…IMX253MYR…`` (colour: the same layout under an RGGB Bayer filter);
    case does not matter. None for any other name.

    Examples
    --------
    >>> sensor_from_name("fruits_IMX250MYR.png").bayer
    'RGGB'
    >>> sensor_from_name("fruits_IMX250MZR.png").bayer is None
    True
    """
    match = SENSOR_NAMES.search(Path(os.fspath(name)).name)
    if match is None:
        return None
    sensor = match.group(0).upper()
    if sensor.endswith("MYR"):
        return SensorDefaults(sensor, tuple(IMX250MYR_LAYOUT), IMX250MYR_BAYER)
    return SensorDefaults(sensor, tuple(IMX250MZR_LAYOUT), None)


def single_frame_file(path: Path) -> bool:
    """Whether ``path`` is one image file holding a single 2-D frame (never raises)."""
    suffix = path.suffix.lower()
    if not path.is_file() or suffix not in FRAME_SUFFIXES:
        return False
    if suffix not in (".tif", ".tiff"):
        return True
    try:
        with tifffile.TiffFile(path) as tif:
            return len(tif.pages) == 1
    except Exception:
        return False


def natural_key(name: str) -> list[Any]:
    """Sort key of a file name with its digit runs as numbers (``f2`` before ``f10``)."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def to_grey(image: np.ndarray, channel: int | None = None) -> np.ndarray:
    """Grey image from an image with a trailing colour axis.

    Parameters
    ----------
    image : array (..., C)
        C = 2 (grey + alpha), 3 (RGB) or 4 (RGBA).
    channel : int, optional
        Take this channel as it is instead of the luma.

    Returns
    -------
    ndarray (...)
        ``0.299 R + 0.587 G + 0.114 B`` (ITU-R BT.601, float64) for RGB/RGBA, the grey
        channel for grey + alpha, or the chosen channel in its own dtype.

    Raises
    ------
    PolarsegError
        If ``channel`` is out of range or C is not 2, 3 or 4.
    """
    image = np.asarray(image)
    n_channels = image.shape[-1]
    if channel is not None:
        if not 0 <= channel < n_channels:
            raise PolarsegError(
                f"channel {channel} does not exist in an image with {n_channels} channels"
            )
        return image[..., channel]
    if n_channels == 2:
        return image[..., 0]
    if n_channels in (3, 4):
        return image[..., :3].astype(np.float64) @ LUMA_BT601
    raise PolarsegError(f"cannot make a grey image from {n_channels} colour channels")


def _saturation_level(
    saturation: float | str | None, dtype: np.dtype, bits: int | None = None
) -> float | None:
    if saturation is None:
        return None
    if isinstance(saturation, str):
        return auto_saturation_level(dtype, bits)
    return float(saturation)


def _check_read_size(path: Path, shape: Sequence[int], dtype: Any, limit: int) -> None:
    """Refuse (before reading) data whose decoded size and float64 copy exceed the limit."""
    count = float(np.prod([float(v) for v in shape])) if len(shape) else 1.0
    itemsize = np.dtype(dtype).itemsize if dtype is not None else 8
    check_bytes(
        count * (itemsize + 8),
        f"{os.fspath(path)}: reading {_dims(shape)} values of {np.dtype(dtype).name}",
        limit,
    )


# -- low-level readers ----------------------------------------------------------------------


class _Collect(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextlib.contextmanager
def _tifffile_messages() -> Iterator[list[str]]:
    """Collect tifffile's log warnings instead of letting them reach stderr."""
    logger = logging.getLogger("tifffile")
    handler = _Collect()
    propagate = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield handler.messages
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


def _angle_metadata(tif: tifffile.TiffFile, series: Any) -> dict[str, Any]:
    """``{"angles": ..., "angles_from": ...}`` from the file's metadata, or ``{}``."""
    frames = [n for n, ax in zip(series.shape, series.axes, strict=False) if ax not in "YXS"]
    found = tiff_angles(tif, int(np.prod(frames)) if frames else 1)
    if found is None:
        return {}
    return {"angles": found[0], "angles_from": found[1]}


def _read_tiff(path: Path, limit: int = 0) -> tuple[np.ndarray, str, dict[str, Any]]:
    """Array, axes string and JSON metadata of the first series of a TIFF."""
    with _tifffile_messages() as messages:
        try:
            with tifffile.TiffFile(path) as tif:
                if not tif.series:
                    raise _error(path, "the TIFF file holds no image")
                series = tif.series[0]
                _check_read_size(path, series.shape, series.dtype, limit or memory_limit())
                bits = None
                with contextlib.suppress(Exception):
                    bits = int(series.keyframe.bitspersample)
                data = series.asarray()
                axes = series.axes
                meta = _angle_metadata(tif, series)
        except PolarsegError:
            raise
        except Exception as exc:
            reason = _first_line(exc)
            if any(hint in text.lower() for text in [reason, *messages] for hint in _CORRUPT_HINTS):
                raise _error(path, f"the TIFF file is truncated or corrupt ({reason})") from exc
            raise _error(path, f"cannot read the TIFF file ({reason})") from exc
    for message in messages:
        if any(hint in message.lower() for hint in _CORRUPT_HINTS):
            raise _error(path, f"the TIFF file is truncated or corrupt ({message})")
    meta = {"description": meta}
    if bits is not None and data.dtype.kind in "ui" and bits < data.dtype.itemsize * 8:
        meta["bits_per_sample"] = bits
    if messages:
        meta["warnings"] = list(messages)
    return data, axes, meta


def _picture_header(path: Path) -> tuple[tuple[int, ...], np.dtype] | None:
    """Shape and dtype a PNG/JPEG decodes to, from its header (None if unknown)."""
    try:
        from PIL import Image

        cap = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = None  # only the header is read; the size is checked below
        try:
            with Image.open(path) as image:
                width, height = image.size
                bands = len(image.getbands())
                mode = image.mode
        finally:
            Image.MAX_IMAGE_PIXELS = cap
    except Exception:
        return None
    itemsize = {"I;16": 2, "I;16B": 2, "I;16L": 2, "I": 4, "F": 4}.get(mode, 1)
    shape = (height, width) if bands == 1 else (height, width, bands)
    return shape, np.dtype(f"u{itemsize}") if itemsize < 4 else np.dtype(np.float32)


def _read_picture(path: Path, limit: int = 0) -> np.ndarray:
    from skimage import io as skio

    header = _picture_header(path)
    if header is not None:
        _check_read_size(path, header[0], header[1], limit or memory_limit())
    try:
        return np.asarray(skio.imread(path))
    except Exception as exc:
        reason = _first_line(exc)
        if "could not find a backend" in reason.lower():  # imageio's text repeats the path
            kind = path.suffix.lstrip(".").upper() or "image"
            reason = f"its content is not a {kind} image that any reader recognises"
        raise _error(path, f"cannot read the image ({reason})") from exc


def _colour_last(data: np.ndarray, axes: str) -> tuple[np.ndarray, bool]:
    """Move a TIFF samples axis ``S`` last; report whether there is one."""
    if "S" not in axes:
        return data, False
    return np.moveaxis(data, axes.index("S"), -1), True


def _load_frame(path: Path, limit: int) -> tuple[np.ndarray, bool, int | None]:
    """One image file as (data, has a colour axis, TIFF bits per sample)."""
    if not path.is_file():
        raise _error(path, "no such file")
    suffix = path.suffix.lower()
    if suffix not in FRAME_SUFFIXES:
        raise _error(path, f"not an image file type ({', '.join(FRAME_SUFFIXES)})")
    bits = None
    if suffix in (".tif", ".tiff"):
        data, axes, meta = _read_tiff(path, limit)
        bits = meta.get("bits_per_sample")
        data, colour = _colour_last(data, axes)
        extra = data.ndim - (3 if colour else 2)
        if extra > 0 and int(np.prod(data.shape[:extra])) == 1:
            data = data.reshape(data.shape[extra:])
        elif extra > 0:
            raise _error(
                path,
                f"the TIFF holds {int(np.prod(data.shape[:extra]))} frames; a single image "
                "was expected",
            )
    else:
        data = _read_picture(path, limit)
        colour = data.ndim == 3 and data.shape[-1] in (2, 3, 4)
    return data, colour, bits


def read_frame(path: PathLike, channel: int | None = None) -> np.ndarray:
    """Read one image file as a single grey frame (H, W).

    Parameters
    ----------
    path : str or path
        A ``.png``, ``.jpg``/``.jpeg`` or single-page ``.tif``/``.tiff`` file.
    channel : int, optional
        Colour channel to take from a colour image (default: BT.601 luma).

    Returns
    -------
    ndarray (H, W)
        The frame, in the file's dtype for grey images, float64 for luma.

    Raises
    ------
    PolarsegError
        If the file is missing, unreadable, not an image, holds several frames, or
        ``channel`` is given for a grey image or is out of range.
    """
    path = Path(path)
    data, colour, _ = _load_frame(path, memory_limit())
    return _grey_frames(path, data, colour, channel, frames=False)[0]


def _grey_frames(
    path: Path,
    data: np.ndarray,
    colour: bool,
    channel: int | None,
    frames: bool,
    level: float | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Colour conversion and dimension check: (H, W) or (N, H, W) if frames.

    Returns the grey data and, if ``level`` is given, the samples at or above it in the
    data as recorded (for colour: in the chosen channel, or in any of R, G, B).
    """
    want = 3 if frames else 2
    shape = data.shape[:-1] if colour else data.shape
    if len(shape) != want:
        what = "a stack of frames (frames, rows, columns)" if frames else "a single 2-D image"
        raise _error(path, f"expected {what}, got an array of shape {data.shape}")
    if data.dtype == np.bool_:
        data = data.astype(np.uint8)
    if not np.issubdtype(data.dtype, np.number) or np.iscomplexobj(data):
        raise _error(path, f"image data must be real numbers, got dtype {data.dtype}")
    saturated = None
    if level is not None:
        with np.errstate(invalid="ignore"):
            hits = data >= level
        if colour:
            n_channels = data.shape[-1]
            if channel is not None and 0 <= channel < n_channels:
                hits = hits[..., channel]
            else:
                hits = hits[..., : 3 if n_channels >= 3 else 1].any(axis=-1)
        saturated = hits
    if colour:
        try:
            data = to_grey(data, channel)
        except PolarsegError as exc:
            raise _error(path, str(exc)) from None
    elif channel is not None:
        raise _error(path, f"channel {channel} was chosen but the image is grey")
    return data, saturated


# -- stack readers --------------------------------------------------------------------------


def _metadata_angles(path: Path, meta: dict[str, Any]) -> np.ndarray | None:
    angles = meta.get("angles")
    if angles is None:
        return None
    try:
        values = np.asarray(angles, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise _error(path, f"the 'angles' metadata is not a list of numbers: {angles!r}") from None
    return values


def _finish(
    path: Path, stack: np.ndarray, saturated: np.ndarray | None, opts: _Options
) -> tuple[np.ndarray, np.ndarray | None]:
    """Subtract the dark frame / offset (after saturation was found on the raw data)."""
    if not opts.subtracts:
        return stack, saturated
    try:
        return subtract_dark(stack, opts.dark, opts.offset), saturated
    except PolarsegError as exc:
        raise _error(opts.dark_name or path, str(exc)) from None


def _read_tiff_stack(path: Path, opts: _Options) -> StackData:
    data, axes, meta = _read_tiff(path, opts.limit)
    data, colour = _colour_last(data, axes)
    if data.ndim == (3 if colour else 2):
        raise _error(
            path,
            "the TIFF holds a single image, not an angle stack "
            "(for a raw polarisation-camera frame give the mosaic layout, --mosaic)",
        )
    bits = meta.get("bits_per_sample")
    level = _saturation_level(opts.saturation, data.dtype, bits)
    stack, saturated = _grey_frames(path, data, colour, opts.channel, True, level)
    stack, saturated = _finish(path, stack, saturated, opts)
    info = {"format": "tiff", **{k: v for k, v in meta.items() if k != "description"}}
    info["saturation_level"] = level
    angles = _metadata_angles(path, meta["description"])
    if meta["description"].get("angles_from") not in (None, FROM_JSON):
        info["angles_from"] = meta["description"]["angles_from"]
    return StackData(stack, angles, os.fspath(path), info, saturated=saturated)


def _npy_header(handle: Any) -> tuple[tuple[int, ...], np.dtype]:
    version = np.lib.format.read_magic(handle)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
    else:
        shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
    return tuple(shape), dtype


def _array_header(path: Path) -> tuple[tuple[int, ...], np.dtype] | None:
    """Shape and dtype of the stack in an ``.npy``/``.npz`` from its header, or None."""
    try:
        if path.suffix.lower() == ".npy":
            with open(path, "rb") as handle:
                return _npy_header(handle)
        with zipfile.ZipFile(path) as archive, archive.open("stack.npy") as handle:
            return _npy_header(handle)
    except Exception:
        return None  # np.load reports the problem


def _read_array_stack(path: Path, opts: _Options) -> StackData:
    info: dict[str, Any] = {"format": path.suffix.lower().lstrip(".")}
    angles = ground_truth = None
    header = _array_header(path)
    if header is not None:
        _check_read_size(path, header[0], header[1], opts.limit)
    try:
        # our own handle: np.load leaks the one it opens when a damaged .npz is refused
        with open(path, "rb") as handle:
            loaded = np.load(handle, allow_pickle=False)
            if isinstance(loaded, np.ndarray):
                data = loaded
            else:
                with loaded:
                    names = loaded.files
                    if "stack" not in names:
                        found = ", ".join(names) or "none"
                        raise _error(
                            path, f"no array named 'stack' in the .npz file (found: {found})"
                        )
                    data = loaded["stack"]
                    angles = loaded["angles"] if "angles" in names else None
                    ground_truth = loaded["labels"] if "labels" in names else None
                    if "params" in names:
                        info["params"] = json.loads(str(loaded["params"]))
    except PolarsegError:
        raise
    except Exception as exc:
        raise _error(path, f"cannot read the NumPy file ({_first_line(exc)})") from exc
    colour = data.ndim == 4 and data.shape[-1] in (2, 3, 4)
    level = _saturation_level(opts.saturation, data.dtype)
    stack, saturated = _grey_frames(path, data, colour, opts.channel, True, level)
    stack, saturated = _finish(path, stack, saturated, opts)
    info["saturation_level"] = level
    if angles is not None:
        if angles.dtype.kind not in "uif":
            raise _error(path, f"the 'angles' array must hold numbers, got dtype {angles.dtype}")
        angles = _metadata_angles(path, {"angles": angles.tolist()})
    if ground_truth is not None and ground_truth.shape != stack.shape[1:]:
        raise _error(
            path,
            f"ground-truth labels are {ground_truth.shape} but the frames are {stack.shape[1:]}",
        )
    return StackData(stack, angles, os.fspath(path), info, ground_truth, saturated)


def _folder_frames(folder: Path) -> list[Path]:
    files = [
        f
        for f in folder.iterdir()
        if f.is_file() and not f.name.startswith(".") and f.suffix.lower() in FRAME_SUFFIXES
    ]
    if not files:
        raise _error(folder, f"no image frames ({', '.join(FRAME_SUFFIXES)}) in the folder")
    return sorted(files, key=lambda f: natural_key(f.name))


def _read_frame_files(
    source: Path, files: list[Path], angles_given: bool, opts: _Options, kind: str
) -> StackData:
    angles = None
    if not angles_given:
        named = [angle_from_name(f) for f in files]
        for f, a in zip(files, named, strict=True):
            if a is None:
                raise _error(
                    f,
                    "no angle in the file name (the last number in the name is the angle in "
                    "degrees, e.g. leaf_030.png); or give the angles",
                )
        order = np.argsort(named, kind="stable")
        files = [files[i] for i in order]
        angles = np.asarray(named, dtype=np.float64)[order]
    frames, flags, levels = [], [], []
    budget = opts.limit
    for f in files:
        data, colour, bits = _load_frame(f, budget)
        level = _saturation_level(opts.saturation, data.dtype, bits)
        frame, saturated = _grey_frames(f, data, colour, opts.channel, False, level)
        if frames and frame.shape != frames[0].shape:
            raise _error(
                f,
                f"frame is {frame.shape[0]} x {frame.shape[1]} pixels but {files[0].name} is "
                f"{frames[0].shape[0]} x {frames[0].shape[1]}; all frames must have one size",
            )
        if not frames:  # the whole stack and its float64 copy, before reading the rest
            check_bytes(
                len(files) * frame.size * 16.0,
                f"{os.fspath(source)}: reading {len(files)} frames of {_dims(frame.shape)} pixels",
                opts.limit,
            )
        frames.append(frame)
        flags.append(saturated)
        levels.append(level)
    stack = np.stack(frames)
    saturated = None
    if all(s is not None for s in flags):
        saturated = np.stack(flags)
    stack, saturated = _finish(source, stack, saturated, opts)
    info = {"format": kind, "files": [f.name if kind == "folder" else os.fspath(f) for f in files]}
    known = [lv for lv in levels if lv is not None]
    info["saturation_level"] = min(known) if known else None
    return StackData(stack, angles, os.fspath(source), info, saturated=saturated)


def _read_mosaic(
    path: Path, layout: Sequence[float], method: str, opts: _Options, bayer: str | None = None
) -> StackData:
    """A raw mono (``bayer`` None) or colour-polarisation frame, decoded."""
    if path.is_dir():
        raise _error(path, "a mosaic layout needs a single raw frame, not a folder")
    data, colour, bits = _load_frame(path, opts.limit)
    level = _saturation_level(opts.saturation, data.dtype, bits)
    raw, saturated_raw = _grey_frames(path, data, colour, opts.channel, False, level)
    if method == "interpolated":
        planes = 10 if bayer is None else 20  # 12 colour planes, luminance, work space
        check_bytes(
            raw.size * 8.0 * planes,
            f"{os.fspath(path)}: interpolating a {_dims(raw.shape)} mosaic",
            opts.limit,
        )
    if opts.subtracts:
        try:
            raw = subtract_dark(raw, opts.dark, opts.offset)
        except PolarsegError as exc:
            raise _error(opts.dark_name or path, str(exc)) from None
    colour_stack = None
    try:
        if bayer is None:
            stack, angles = demosaic(raw, layout, method)
            saturated = (
                None if saturated_raw is None else demosaic_flags(saturated_raw, layout, method)
            )
        else:
            colour_stack, angles = demosaic_colour(raw, layout, bayer, method)
            stack = luminance(colour_stack)
            saturated = None
            if saturated_raw is not None:
                flags = demosaic_colour_flags(saturated_raw, layout, bayer, method)
                saturated = flags.any(axis=0)
    except PolarsegError as exc:
        raise _error(path, str(exc)) from None
    info: dict[str, Any] = {
        "format": "mosaic",
        "demosaic": method,
        "mosaic_layout_deg": [float(a) for a in np.asarray(layout, dtype=float).ravel()],
        "raw_shape": list(raw.shape),
        "saturation_level": level,
    }
    if bayer is not None:
        info["bayer"] = bayer
        info["colours"] = list(COLOURS)
    if bits is not None:
        info["bits_per_sample"] = bits
    return StackData(
        stack, angles, os.fspath(path), info, saturated=saturated, colour_stack=colour_stack
    )


def _frame_label(k: int, angles: np.ndarray) -> str:
    return f"frame {k} ({angles[k]:g} degrees)"


def _check_stack_data(path: Path, data: StackData) -> StackData:
    stack, angles = data.stack, data.angles_deg
    n = stack.shape[0]
    if angles is None:
        raise _error(
            path,
            "no polariser angles in the file; give them in degrees, one per frame "
            "(e.g. --angles 0,45,90,135)",
        )
    angles = np.asarray(angles, dtype=np.float64).ravel()
    if angles.size != n:
        raise _error(path, f"{n} frames but {angles.size} angles ({_fmt(angles)})")
    if not np.all(np.isfinite(angles)):
        raise _error(path, f"polariser angles must be finite numbers, got {_fmt(angles)}")
    distinct = distinct_angle_count(np.deg2rad(angles))
    if distinct < 3:
        raise _error(
            path,
            f"need at least 3 distinct polariser angles (modulo 180 degrees), got {distinct} "
            f"({_fmt(angles)})",
        )
    if min(stack.shape[1:]) < 1:
        raise _error(path, f"the frames are empty (shape {stack.shape})")
    flat = stack.reshape(n, -1)
    if stack.dtype.kind == "f":
        finite = np.isfinite(flat)
        if not finite.any():
            raise _error(path, "the data has no finite values (all NaN or infinite)")
        empty = np.flatnonzero(~finite.any(axis=1))
        if empty.size:
            raise _error(
                path,
                f"{_frame_label(int(empty[0]), angles)} has no finite values (all NaN or infinite)",
            )
        with np.errstate(invalid="ignore"):
            lo = np.nanmin(np.where(finite, flat, np.nan), axis=1)
            hi = np.nanmax(np.where(finite, flat, np.nan), axis=1)
    else:
        lo, hi = flat.min(axis=1), flat.max(axis=1)
    negative = np.flatnonzero(lo < 0)
    if negative.size:
        k = int(negative[0])
        raise _error(
            path,
            f"negative intensities (down to {float(lo[k]):g} in {_frame_label(k, angles)}): "
            "light through a polariser is never negative; subtract a smaller offset or dark "
            "frame, or shift the data with a negative --offset",
        )
    if flat.shape[1] > 1:
        constant = np.flatnonzero(lo == hi)
        if constant.size:
            k = int(constant[0])
            raise _error(
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
                raise _error(p, "no such file")
            try:
                array = np.load(p, allow_pickle=False)
            except Exception as exc:
                raise _error(p, f"cannot read the NumPy file ({_first_line(exc)})") from exc
        else:
            array = read_frame(p, channel)
        array = np.asarray(array)
        if array.ndim != 2 or array.dtype.kind not in "biuf":
            raise _error(p, f"a dark frame must be one 2-D image, got an array of {array.shape}")
        return array, os.fspath(p)
    array = np.asarray(dark)
    if array.ndim != 2 or array.dtype.kind not in "biuf":
        raise PolarsegError(f"a dark frame must be one 2-D image, got an array of {array.shape}")
    return array, None


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
        layout (degrees, row-major; :data:`DEFAULT_MOSAIC` for the Sony IMX250MZR).
        Without it, a single frame named after a Sony sensor (:func:`sensor_from_name`)
        takes the sensor's layout.
    channel : int, optional
        Colour channel to use for colour images (default: ITU-R BT.601 luma).
    demosaic : {"superpixel", "interpolated"}
        For a mosaic: half resolution, or full resolution by bilinear interpolation.
    bayer : {"RGGB", "BGGR", "GRBG", "GBRG"}, optional
        With ``mosaic``: the frame is a colour-polarisation mosaic whose 2 × 2 polariser
        super-pixels lie under this Bayer order (row-major); default: the sensor's, for a
        file named after a colour sensor (``…IMX250MYR…``), else a mono mosaic.
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

    Returns
    -------
    StackData
        The stack (N, H, W), angles in degrees (N,), source, metadata, the saturated
        samples and, for an ``.npz`` with ``labels``, the ground truth.

    Raises
    ------
    PolarsegError
        With one line naming the file and the problem: missing, unreadable, truncated or
        non-image file; too large for the memory limit; angles missing, not matching the
        frame count, or fewer than 3 distinct modulo 180 degrees; frames of different
        sizes; data with no finite value, negative values or a constant frame; an
        odd-sized mosaic; angles and a mosaic both given; a bad option.

    Examples
    --------
    >>> data = read_stack("scene.tif", angles_deg=[0, 45, 90, 135])  # doctest: +SKIP
    >>> data.stack.shape, data.angles_deg                             # doctest: +SKIP
    ((4, 480, 640), array([  0.,  45.,  90., 135.]))
    """
    files: list[Path] | None = None
    if isinstance(path, (list, tuple)):
        if not path:
            raise PolarsegError("no input files given")
        files = [Path(os.fspath(f)) for f in path]
        if len(files) == 1:
            p, files = files[0], None
        else:
            p = files[0]
    else:
        p = Path(os.fspath(path))
    if demosaic not in DEMOSAIC_METHODS:
        raise PolarsegError(
            f"demosaic method must be one of {', '.join(DEMOSAIC_METHODS)}; got {demosaic!r}"
        )
    if bayer is not None:
        bayer = check_bayer(bayer)
    if isinstance(saturation, str) and saturation != "auto":
        raise PolarsegError(f"saturation must be a number, 'auto' or None; got {saturation!r}")
    if saturation is not None and not isinstance(saturation, str):
        saturation = _finite_number(saturation, "the saturation level")
    if offset is not None:
        offset = _finite_number(offset, "the offset")
    dark_array, dark_name = _resolve_dark(dark, channel)
    opts = _Options(
        channel=channel,
        saturation=saturation,
        limit=memory_limit(max_bytes),
        dark=dark_array,
        dark_name=dark_name,
        offset=None if offset is None else float(offset),
    )
    if files is not None:
        for f in files:
            if not f.exists():
                raise _error(f, "no such file")
            if f.is_dir():
                raise _error(f, "a list of frames must name image files, not folders")
        if mosaic is not None or bayer is not None:
            raise _error(p, "a mosaic layout needs a single raw frame, not a list of files")
        if angles_deg is not None and len(np.ravel(angles_deg)) != len(files):
            raise _error(p, f"{len(files)} files but {len(np.ravel(angles_deg))} angles")
        data = _read_frame_files(p, files, angles_deg is not None, opts, "files")
    else:
        if not p.exists():
            raise _error(p, "no such file or folder")
        if angles_deg is not None and (mosaic is not None or bayer is not None):
            raise _error(p, "give either the polariser angles or a mosaic layout, not both")
        sensor = sensor_from_name(p) if single_frame_file(p) else None
        if sensor is not None and angles_deg is None:
            mosaic = sensor.layout_deg if mosaic is None else mosaic
            bayer = sensor.bayer if bayer is None else bayer
        if bayer is not None and mosaic is None:
            raise _error(p, "a Bayer order needs a mosaic layout (--mosaic)")
        if mosaic is not None:
            data = _read_mosaic(p, mosaic, demosaic, opts, bayer)
            if sensor is not None:
                data.metadata["sensor"] = sensor.sensor
        elif p.is_dir():
            data = _read_frame_files(p, _folder_frames(p), angles_deg is not None, opts, "folder")
        else:
            suffix = p.suffix.lower()
            if suffix in (".tif", ".tiff"):
                data = _read_tiff_stack(p, opts)
            elif suffix in (".npz", ".npy"):
                data = _read_array_stack(p, opts)
            elif suffix in FRAME_SUFFIXES:
                raise _error(
                    p,
                    "a single image is not an angle stack: give a multi-page TIFF, an .npz, "
                    "a folder of frames, or a mosaic layout for a raw polarisation-camera frame",
                )
            else:
                kinds = ", ".join(sorted(set(STACK_SUFFIXES + FRAME_SUFFIXES)))
                raise _error(p, f"unsupported file type {suffix or '(none)'!r} (expected {kinds})")
    if dark_array is not None:
        data.metadata["dark_frame"] = dark_name or "array"
    if offset is not None:
        data.metadata["offset"] = float(offset)
    if angles_deg is not None:
        data.angles_deg = np.asarray(angles_deg, dtype=np.float64).ravel()
        data.metadata["angles_from"] = "given"
    else:
        kind = data.metadata["format"]
        data.metadata.setdefault("angles_from", "names" if kind == "files" else kind)
    return _check_stack_data(p, data)


def read_mask(
    path: PathLike, shape: Sequence[int], raw_shape: Sequence[int] | None = None
) -> np.ndarray:
    """Read a user mask (a labels image): non-zero = segment here, 0 = leave out.

    Parameters
    ----------
    path : str or path
        ``.tif``/``.tiff``/``.png`` (a napari labels layer saved as an image; colour
        images count a pixel as set if any channel is non-zero), ``.npy``, or ``.npz``
        (the array ``mask`` or ``labels``, or its only array).
    shape : (H, W)
        Size of the frames the mask applies to.
    raw_shape : (2H, 2W) or (4H, 4W), optional
        Size of the raw mosaic the frames come from by super-pixel demosaicing (mono:
        2 × 2, colour-polarisation: 4 × 4 pixels per output pixel); a mask of this size
        is reduced to the frames' size (an output pixel is used only if all the raw
        pixels it comes from are set).

    Returns
    -------
    ndarray (H, W) of bool

    Raises
    ------
    PolarsegError
        If the file is missing or unreadable, not a single 2-D image, or of another size.
    """
    p = Path(path)
    if not p.is_file():
        raise _error(p, "no such file")
    suffix = p.suffix.lower()
    if suffix not in MASK_SUFFIXES:
        raise _error(p, f"unsupported mask file type {suffix!r} ({', '.join(MASK_SUFFIXES)})")
    limit = memory_limit()
    if suffix in (".npy", ".npz"):
        header = _array_header(p) if suffix == ".npy" else None
        if header is not None:
            _check_read_size(p, header[0], header[1], limit)
        try:
            loaded = np.load(p, allow_pickle=False)
            if isinstance(loaded, np.ndarray):
                data = loaded
            else:
                with loaded:
                    names = loaded.files
                    pick = [n for n in ("mask", "labels") if n in names] or (
                        names if len(names) == 1 else []
                    )
                    if not pick:
                        raise _error(
                            p, f"no array named 'mask' or 'labels' (found: {', '.join(names)})"
                        )
                    data = loaded[pick[0]]
        except PolarsegError:
            raise
        except Exception as exc:
            raise _error(p, f"cannot read the NumPy file ({_first_line(exc)})") from exc
        colour = False
    else:
        data, colour, _ = _load_frame(p, limit)
    data = np.asarray(data)
    if data.dtype.kind not in "biuf":
        raise _error(p, f"a mask must hold numbers, got dtype {data.dtype}")
    with np.errstate(invalid="ignore"):
        keep = np.nan_to_num(data.astype(np.float64)) != 0 if data.dtype.kind == "f" else data != 0
    if colour:
        keep = keep.any(axis=-1)
    while keep.ndim > 2 and keep.shape[0] == 1:
        keep = keep[0]
    if keep.ndim != 2:
        raise _error(p, f"a mask must be one 2-D image, got an array of shape {data.shape}")
    h, w = (int(v) for v in shape)
    if keep.shape == (h, w):
        return keep
    if raw_shape is not None and keep.shape == tuple(int(v) for v in raw_shape):
        f = keep.shape[0] // h
        if f in (2, 4) and keep.shape == (f * h, f * w):
            return keep.reshape(h, f, w, f).all(axis=(1, 3))
    raise _error(
        p,
        f"the mask is {keep.shape[0]} x {keep.shape[1]} pixels but the frames are {h} x {w}",
    )


def read_labels(path: PathLike, shape: Sequence[int], what: str) -> np.ndarray:
    """Read a labels image (scribbles, ground truth) of the outputs' size as int64.

    ``.tif``/``.tiff``/``.png`` (single channel, e.g. a napari Labels layer saved as an
    image), ``.npy`` or ``.npz`` (the array ``labels``, ``scribbles`` or ``mask``, or its
    only array). Raises :class:`PolarsegError` naming the file and the problem.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in MASK_SUFFIXES:
        kinds = ", ".join(MASK_SUFFIXES)
        raise PolarsegError(f"{path}: unsupported {what} file type {suffix!r} ({kinds})")
    if not p.is_file():
        raise PolarsegError(f"{path}: no such file")
    colour = False
    if suffix in (".npy", ".npz"):
        try:
            loaded = np.load(p, allow_pickle=False)
            if isinstance(loaded, np.ndarray):
                data = loaded
            else:
                with loaded:
                    names = loaded.files
                    pick = [n for n in ("labels", "scribbles", "mask") if n in names]
                    pick = pick or (names if len(names) == 1 else [])
                    if not pick:
                        raise PolarsegError(
                            f"{path}: no array named 'labels' or 'scribbles' "
                            f"(found: {', '.join(names)})"
                        )
                    data = loaded[pick[0]]
        except PolarsegError:
            raise
        except Exception as exc:
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise PolarsegError(f"{path}: cannot read the {what} ({first})") from None
    else:
        data, colour, _ = _load_frame(p, memory_limit())
    data = np.asarray(data)
    if colour:
        raise PolarsegError(f"{path}: the {what} must be a single-channel labels image")
    while data.ndim > 2 and data.shape[0] == 1:
        data = data[0]
    if data.ndim != 2:
        raise PolarsegError(f"{path}: the {what} must be one 2-D image, got shape {data.shape}")
    if data.dtype == np.bool_:
        data = data.astype(np.uint8)
    if data.dtype.kind == "f":
        if not np.all(np.isfinite(data)) or np.any(data != np.round(data)):
            raise PolarsegError(f"{path}: the {what} must hold integer labels")
    elif data.dtype.kind not in "iu":
        raise PolarsegError(f"{path}: the {what} must hold integer labels, got {data.dtype}")
    h, w = (int(v) for v in shape)
    if data.shape != (h, w):
        raise PolarsegError(
            f"{path}: the {what} image is {data.shape[0]} x {data.shape[1]} pixels but the "
            f"outputs are {h} x {w}"
        )
    return data.astype(np.int64)


# -- writers --------------------------------------------------------------------------------


@contextlib.contextmanager
def atomic_output(path: PathLike) -> Iterator[Path]:
    """Context manager giving a temporary path that replaces ``path`` on success.

    The temporary file lives in the destination's directory (so :func:`os.replace` is
    atomic) and keeps its extension (so writers that look at it pick the right format).
    On any exception it is deleted and ``path`` is left as it was.

    Examples
    --------
    >>> with atomic_output("figure.png") as tmp:        # doctest: +SKIP
    ...     fig.savefig(tmp)
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp{path.suffix}")
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_tiff(path: PathLike, array: np.ndarray, metadata: dict[str, Any] | None = None) -> None:
    """Write an array as a grey (multi-page if 3-D) TIFF, atomically.

    Parameters
    ----------
    path : str or path
        Destination ``.tif``.
    array : array
        (H, W) or (N, H, W), any dtype tifffile writes.
    metadata : dict, optional
        JSON-serialisable items stored in the ImageDescription (tifffile's shaped
        metadata, read back by ``TiffFile.shaped_metadata``).
    """
    array = np.asarray(array)
    with atomic_output(path) as tmp:
        tifffile.imwrite(tmp, array, photometric="minisblack", metadata=dict(metadata or {}))


def write_stack_tiff(path: PathLike, stack: np.ndarray, angles_deg: Sequence[float]) -> None:
    """Write an angle stack as a multi-page TIFF with its angles in the metadata.

    Parameters
    ----------
    path : str or path
        Destination ``.tif``.
    stack : array (N, H, W)
        The frames.
    angles_deg : sequence of N floats
        Polariser angles in degrees; :func:`read_stack` reads them back.
    """
    stack = np.asarray(stack)
    angles = np.asarray(angles_deg, dtype=np.float64).ravel()
    if stack.ndim != 3:
        raise PolarsegError(f"an angle stack must be (frames, rows, columns), got {stack.shape}")
    if angles.size != stack.shape[0]:
        raise PolarsegError(f"{stack.shape[0]} frames but {angles.size} angles")
    write_tiff(path, stack, {"angles": angles.tolist(), "angle_unit": "degrees"})


def _jsonable(obj: Any) -> Any:
    """Plain JSON types from numpy scalars/arrays, paths and tuples; NaN/inf become null."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: PathLike, obj: Any) -> None:
    """Write an object as indented JSON, atomically.

    numpy scalars and arrays become numbers and lists, paths strings, NaN and infinities
    ``null``. Serialisation happens before the file is touched: an object that cannot be
    serialised raises :class:`TypeError` and leaves ``path`` as it was.
    """
    text = json.dumps(_jsonable(obj), indent=2, allow_nan=False) + "\n"
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_png(path: PathLike, image: np.ndarray) -> None:
    """Write a uint8/uint16 image (H, W), (H, W, 3) or (H, W, 4) as PNG, atomically.

    Boolean images are written as 0/255. Other dtypes raise :class:`PolarsegError`
    (scale them to an integer type first).
    """
    from skimage import io as skio

    image = np.asarray(image)
    if image.dtype == np.bool_:
        image = image.astype(np.uint8) * 255
    if image.dtype not in (np.uint8, np.uint16):
        raise PolarsegError(f"PNG images must be uint8 or uint16, got {image.dtype}")
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[-1] in (3, 4))):
        raise PolarsegError(
            f"a PNG image must be (H, W), (H, W, 3) or (H, W, 4), got {image.shape}"
        )
    with atomic_output(path) as tmp:
        skio.imsave(tmp, image, check_contrast=False)
