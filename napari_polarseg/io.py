"""Reading angle stacks and writing results (no napari, no Qt).

Angles are **degrees** in files and on the command line (the engine takes radians:
:attr:`StackData.angles_rad`). Every problem with an input file is raised as
:class:`~napari_polarseg.engine.PolarsegError` with one line that names the file.

Inputs :func:`read_stack` understands
--------------------------------------
- **Multi-page TIFF** ``.tif``/``.tiff``, one page per polariser angle. The angles come
  from the ``angles_deg`` argument or else from the file's ImageDescription: either
  tifffile's shaped JSON metadata (as :func:`write_stack_tiff` writes it,
  ``tifffile.imwrite(path, stack, metadata={"angles": [...]})``) or a plain JSON object
  with an ``"angles"`` key.
- **NumPy** ``.npz`` with arrays ``stack`` (N, H, W) and ``angles`` (degrees), optionally
  ``labels`` (H, W ground truth) and ``params`` (a JSON string of segmentation
  parameters); loaded with ``allow_pickle=False``. A plain ``.npy`` stack needs the angles.
- **A folder of frames** (``.png``, ``.tif``, ``.tiff``, ``.jpg``, ``.jpeg``; hidden
  files are skipped). Unless the angles are given, each frame's angle in degrees is **the
  last number in its file name without the extension**: ``leaf_030.png`` → 30,
  ``nir_45_aligned.tif`` → 45, ``scene-b_22.5deg.png`` → 22.5 (digits with an optional
  decimal part; no sign). Frames are then sorted by angle. With explicit angles the frames
  are taken in natural file-name order (``f2`` before ``f10``).
- **A raw polarisation-camera frame** (any of the image types above) with ``mosaic`` set:
  the four polariser angles of the 2 × 2 super-pixel in row-major order (Sony IMX250MZR:
  90, 45, 135, 0). It is split into four frames at **half resolution** by
  :func:`napari_polarseg.engine.mosaic.demosaic_superpixel`.

Colour frames (H, W, 3 or 4) become grey by the ITU-R BT.601 luma weights
0.299 R + 0.587 G + 0.114 B (alpha ignored) unless ``channel`` picks one channel.

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
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from .engine.errors import PolarsegError
from .engine.mosaic import IMX250MZR_LAYOUT, demosaic_superpixel
from .engine.polarimage import distinct_angle_count

PathLike = str | os.PathLike

#: File types read as single frames (in a folder, or as a raw mosaic).
FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
#: File types read as whole stacks.
STACK_SUFFIXES = (".tif", ".tiff", ".npz", ".npy")
#: ITU-R BT.601 luma weights of R, G, B.
LUMA_BT601 = np.array([0.299, 0.587, 0.114])
#: Default 2 x 2 super-pixel layout (degrees, row-major) of a polarisation camera.
DEFAULT_MOSAIC = IMX250MZR_LAYOUT

_NUMBER = re.compile(r"\d+(?:\.\d+)?")
#: tifffile log messages that mean the file is cut short or damaged.
_CORRUPT_HINTS = ("invalid page offset", "truncat", "corrupt", "failed to read", "invalid ifd")


@dataclass
class StackData:
    """An angle stack as read from disk.

    Attributes
    ----------
    stack : ndarray (N, H, W)
        Grey frames, real numbers (the file's dtype where no conversion was needed).
    angles_deg : ndarray (N,) float64
        Polariser angle of each frame, degrees.
    source : str
        The file or folder read.
    metadata : dict
        What else was learned: ``format``, and per format ``files`` (folder),
        ``mosaic_layout_deg`` and ``raw_shape`` (mosaic), ``params`` (npz), ``warnings``.
    ground_truth : ndarray (H, W) or None
        Reference labels shipped with the stack (``labels`` in an ``.npz``), if any.
    """

    stack: np.ndarray
    angles_deg: np.ndarray
    source: str
    metadata: dict[str, Any] = field(default_factory=dict)
    ground_truth: np.ndarray | None = None

    @property
    def angles_rad(self) -> np.ndarray:
        """Polariser angles in radians, for the engine."""
        return np.deg2rad(self.angles_deg)


# -- small helpers ------------------------------------------------------------------------


def _error(path: PathLike, problem: str) -> PolarsegError:
    return PolarsegError(f"{os.fspath(path)}: {problem}")


def _first_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def _fmt(values: Sequence[float]) -> str:
    return ", ".join(f"{float(v):g}" for v in values)


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


def _natural_key(name: str) -> list:
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


def _json_description(tif: tifffile.TiffFile) -> dict[str, Any]:
    shaped = tif.shaped_metadata
    if shaped:
        return dict(shaped[0])
    description = tif.pages[0].description if len(tif.pages) else ""
    if description.lstrip().startswith("{"):
        with contextlib.suppress(ValueError):
            data = json.loads(description)
            if isinstance(data, dict):
                return data
    return {}


def _read_tiff(path: Path) -> tuple[np.ndarray, str, dict[str, Any]]:
    """Array, axes string and JSON metadata of the first series of a TIFF."""
    with _tifffile_messages() as messages:
        try:
            with tifffile.TiffFile(path) as tif:
                if not tif.series:
                    raise _error(path, "the TIFF file holds no image")
                series = tif.series[0]
                data = series.asarray()
                axes = series.axes
                meta = _json_description(tif)
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
    if messages:
        meta["warnings"] = list(messages)
    return data, axes, meta


def _read_picture(path: Path) -> np.ndarray:
    from skimage import io as skio

    try:
        return np.asarray(skio.imread(path))
    except Exception as exc:
        raise _error(path, f"cannot read the image ({_first_line(exc)})") from exc


def _colour_last(data: np.ndarray, axes: str) -> tuple[np.ndarray, bool]:
    """Move a TIFF samples axis ``S`` last; report whether there is one."""
    if "S" not in axes:
        return data, False
    return np.moveaxis(data, axes.index("S"), -1), True


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
    if not path.is_file():
        raise _error(path, "no such file")
    suffix = path.suffix.lower()
    if suffix not in FRAME_SUFFIXES:
        raise _error(path, f"not an image file type ({', '.join(FRAME_SUFFIXES)})")
    if suffix in (".tif", ".tiff"):
        data, axes, _ = _read_tiff(path)
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
        data = _read_picture(path)
        colour = data.ndim == 3 and data.shape[-1] in (2, 3, 4)
    return _grey_frames(path, data, colour, channel, frames=False)


def _grey_frames(
    path: Path, data: np.ndarray, colour: bool, channel: int | None, frames: bool
) -> np.ndarray:
    """Apply colour conversion and check the dimensions: (H, W) or (N, H, W) if frames."""
    if colour:
        try:
            data = to_grey(data, channel)
        except PolarsegError as exc:
            raise _error(path, str(exc)) from None
    elif channel is not None:
        raise _error(path, f"channel {channel} was chosen but the image is grey")
    want = 3 if frames else 2
    if data.ndim != want:
        what = "a stack of frames (frames, rows, columns)" if frames else "a single 2-D image"
        raise _error(path, f"expected {what}, got an array of shape {data.shape}")
    if not (np.issubdtype(data.dtype, np.number) or data.dtype == np.bool_) or np.iscomplexobj(
        data
    ):
        raise _error(path, f"image data must be real numbers, got dtype {data.dtype}")
    return data.astype(np.uint8) if data.dtype == np.bool_ else data


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


def _read_tiff_stack(path: Path, channel: int | None) -> StackData:
    data, axes, meta = _read_tiff(path)
    data, colour = _colour_last(data, axes)
    if data.ndim == (3 if colour else 2):
        raise _error(
            path,
            "the TIFF holds a single image, not an angle stack "
            "(for a raw polarisation-camera frame give the mosaic layout, --mosaic)",
        )
    stack = _grey_frames(path, data, colour, channel, frames=True)
    info = {"format": "tiff", **{k: v for k, v in meta.items() if k != "description"}}
    angles = _metadata_angles(path, meta["description"])
    return StackData(stack, angles, os.fspath(path), info)


def _read_array_stack(path: Path, channel: int | None) -> StackData:
    info: dict[str, Any] = {"format": path.suffix.lower().lstrip(".")}
    angles = ground_truth = None
    try:
        loaded = np.load(path, allow_pickle=False)
        if isinstance(loaded, np.ndarray):
            data = loaded
        else:
            with loaded:
                names = loaded.files
                if "stack" not in names:
                    found = ", ".join(names) or "none"
                    raise _error(path, f"no array named 'stack' in the .npz file (found: {found})")
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
    stack = _grey_frames(path, data, colour, channel, frames=True)
    if angles is not None:
        angles = _metadata_angles(path, {"angles": angles.tolist()})
    if ground_truth is not None and ground_truth.shape != stack.shape[1:]:
        raise _error(
            path,
            f"ground-truth labels are {ground_truth.shape} but the frames are {stack.shape[1:]}",
        )
    return StackData(stack, angles, os.fspath(path), info, ground_truth)


def _folder_frames(folder: Path) -> list[Path]:
    files = [
        f
        for f in folder.iterdir()
        if f.is_file() and not f.name.startswith(".") and f.suffix.lower() in FRAME_SUFFIXES
    ]
    if not files:
        raise _error(folder, f"no image frames ({', '.join(FRAME_SUFFIXES)}) in the folder")
    return sorted(files, key=lambda f: _natural_key(f.name))


def _read_folder(folder: Path, angles_given: bool, channel: int | None) -> StackData:
    files = _folder_frames(folder)
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
    frames = []
    for f in files:
        frame = read_frame(f, channel)
        if frames and frame.shape != frames[0].shape:
            raise _error(
                f,
                f"frame is {frame.shape[0]} x {frame.shape[1]} pixels but {files[0].name} is "
                f"{frames[0].shape[0]} x {frames[0].shape[1]}; all frames must have one size",
            )
        frames.append(frame)
    info = {"format": "folder", "files": [f.name for f in files]}
    return StackData(np.stack(frames), angles, os.fspath(folder), info)


def _read_mosaic(path: Path, layout: Sequence[float], channel: int | None) -> StackData:
    if path.is_dir():
        raise _error(path, "a mosaic layout needs a single raw frame, not a folder")
    raw = read_frame(path, channel)
    try:
        stack, angles = demosaic_superpixel(raw, layout)
    except PolarsegError as exc:
        raise _error(path, str(exc)) from None
    info = {
        "format": "mosaic",
        "mosaic_layout_deg": [float(a) for a in np.asarray(layout, dtype=float).ravel()],
        "raw_shape": list(raw.shape),
    }
    return StackData(stack, angles, os.fspath(path), info)


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
    if stack.dtype.kind == "f" and not np.isfinite(stack).any():
        raise _error(path, "the data has no finite values (all NaN or infinite)")
    data.angles_deg = angles
    return data


def read_stack(
    path: PathLike,
    angles_deg: Sequence[float] | np.ndarray | None = None,
    mosaic: Sequence[float] | None = None,
    channel: int | None = None,
) -> StackData:
    """Read an angle stack from a TIFF, an ``.npz``/``.npy``, a folder or a raw mosaic.

    See the module docstring for the formats and the file-name rule of folders.

    Parameters
    ----------
    path : str or path
        File or folder.
    angles_deg : sequence of float, optional
        Polariser angle of each frame in degrees, in frame order (for a folder: natural
        file-name order). Overrides angles stored in the file.
    mosaic : sequence of 4 floats, optional
        Read ``path`` as one raw polarisation-camera frame with this 2 × 2 super-pixel
        layout (degrees, row-major; :data:`DEFAULT_MOSAIC` for the Sony IMX250MZR). The
        result has half the height and width of the raw frame.
    channel : int, optional
        Colour channel to use for colour images (default: ITU-R BT.601 luma).

    Returns
    -------
    StackData
        The stack (N, H, W), angles in degrees (N,), source, metadata and, for an
        ``.npz`` with ``labels``, the ground truth.

    Raises
    ------
    PolarsegError
        With one line naming the file and the problem: missing, unreadable, truncated or
        non-image file; angles missing, not matching the frame count, or fewer than 3
        distinct modulo 180 degrees; frames of different sizes; data with no finite value;
        an odd-sized mosaic; angles and a mosaic both given.

    Examples
    --------
    >>> data = read_stack("scene.tif", angles_deg=[0, 45, 90, 135])  # doctest: +SKIP
    >>> data.stack.shape, data.angles_deg                             # doctest: +SKIP
    ((4, 480, 640), array([  0.,  45.,  90., 135.]))
    """
    p = Path(path)
    if not p.exists():
        raise _error(p, "no such file or folder")
    if angles_deg is not None and mosaic is not None:
        raise _error(p, "give either the polariser angles or a mosaic layout, not both")
    if mosaic is not None:
        data = _read_mosaic(p, mosaic, channel)
    elif p.is_dir():
        data = _read_folder(p, angles_deg is not None, channel)
    else:
        suffix = p.suffix.lower()
        if suffix in (".tif", ".tiff"):
            data = _read_tiff_stack(p, channel)
        elif suffix in (".npz", ".npy"):
            data = _read_array_stack(p, channel)
        elif suffix in FRAME_SUFFIXES:
            raise _error(
                p,
                "a single image is not an angle stack: give a multi-page TIFF, an .npz, a "
                "folder of frames, or a mosaic layout for a raw polarisation-camera frame",
            )
        else:
            kinds = ", ".join(sorted(set(STACK_SUFFIXES + FRAME_SUFFIXES)))
            raise _error(p, f"unsupported file type {suffix or '(none)'!r} (expected {kinds})")
    if angles_deg is not None:
        data.angles_deg = np.asarray(angles_deg, dtype=np.float64).ravel()
        data.metadata["angles_from"] = "given"
    else:
        data.metadata.setdefault("angles_from", data.metadata["format"])
    return _check_stack_data(p, data)


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
