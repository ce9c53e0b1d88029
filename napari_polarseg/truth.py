"""Hand-labelled ground truth for real polarisation-camera frames.

A truth file is a small JSON document (format and drawing method:
``sample_data/truth/README.md``) that names one raw frame and holds, per material class,
polygons drawn inside the objects and a few short strokes such as a user would paint.
:func:`read_truth_file` validates it and rasterises it into two label images on the
frame's super-pixel grid:

- ``truth``: 0 = unlabelled (ignored by any evaluation, e.g. near object boundaries),
  k = class ``classes[k - 1]`` inside that class's polygons;
- ``strokes``: 0 = no stroke, k = a stroke of class ``classes[k - 1]``.

The file is read strictly as data (``json.load``, then type, shape and name checks);
every problem is raised as :class:`~napari_polarseg.engine.errors.PolarsegError` with one
line naming the file. This module uses numpy and scikit-image only (no napari).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from skimage.draw import line as draw_line
from skimage.draw import polygon as draw_polygon

from .engine.errors import PolarsegError
from .engine.limits import check_bytes

if TYPE_CHECKING:
    from .engine.physics.polarimage import PolarisationImage

#: Folder of the bundled truth files.
TRUTH_DIR = Path(__file__).resolve().parent / "sample_data" / "truth"

#: Keys of a truth file; ``coordinates`` is the only optional one.
REQUIRED_KEYS = ("frame", "mosaic", "shape", "classes", "regions", "strokes")
OPTIONAL_KEYS = ("coordinates",)

#: The only coordinate convention (documented in the file itself as ``coordinates``).
COORDINATES = "superpixel frame, (row, col) pixels"

#: Largest truth file read (bytes): the format holds a few hundred vertices.
MAX_FILE_BYTES = 4 * 2**20

#: Most classes (labels must fit the uint8 PNGs written by ``scripts/rasterise_truth.py``).
MAX_CLASSES = 255


@dataclass(frozen=True, eq=False)
class TruthFile:
    """A validated, rasterised truth file.

    Attributes
    ----------
    path : Path
        The file read.
    frame : str
        File name of the raw frame the labels belong to (no folder).
    mosaic : tuple of float
        The frame's 2 × 2 super-pixel layout in degrees, row-major (for
        :func:`napari_polarseg.io.read_stack`'s ``mosaic``).
    shape : tuple of int
        (H, W) of the super-pixel (demosaiced) frame the coordinates refer to.
    classes : tuple of str
        Class names; class ``classes[k]`` has label ``k + 1``.
    regions : dict
        Class name → tuple of polygons, each a read-only float64 array (n, 2) of
        (row, col) vertices, as in the file.
    stroke_paths : dict
        Class name → tuple of polylines, each a read-only float64 array (n, 2).
    truth : ndarray (H, W) int32
        0 = unlabelled / ignored, k = class ``classes[k - 1]``. Read-only.
    strokes : ndarray (H, W) int32
        0 = no stroke, k = stroke of class ``classes[k - 1]``. Read-only.
    """

    path: Path
    frame: str
    mosaic: tuple[float, ...]
    shape: tuple[int, int]
    classes: tuple[str, ...]
    regions: dict[str, tuple[np.ndarray, ...]]
    stroke_paths: dict[str, tuple[np.ndarray, ...]]
    truth: np.ndarray
    strokes: np.ndarray

    def label(self, name: str) -> int:
        """Label value (1..K) of class ``name``.

        Parameters
        ----------
        name : str
            A class name of this file.

        Returns
        -------
        int
            ``classes.index(name) + 1``.

        Raises
        ------
        PolarsegError
            If ``name`` is not one of :attr:`classes`.
        """
        if name not in self.classes:
            known = ", ".join(self.classes)
            raise PolarsegError(
                f"truth file {self.path}: unknown class {name!r}; classes are {known}"
            )
        return self.classes.index(name) + 1

    def pixel_counts(self, layer: str = "truth") -> dict[str, int]:
        """Labelled pixels per class.

        Parameters
        ----------
        layer : {"truth", "strokes"}
            Which label image to count.

        Returns
        -------
        dict
            Class name → number of pixels with that class's label, in class order.
        """
        if layer not in ("truth", "strokes"):
            raise PolarsegError(f"layer must be 'truth' or 'strokes', not {layer!r}")
        labels = self.truth if layer == "truth" else self.strokes
        counts = np.bincount(labels.ravel(), minlength=len(self.classes) + 1)
        return {name: int(counts[k + 1]) for k, name in enumerate(self.classes)}


def truth_files() -> list[Path]:
    """The truth files bundled with the package.

    Returns
    -------
    list of Path
        ``sample_data/truth/*.json``, sorted by name.
    """
    return sorted(TRUTH_DIR.glob("*.json"))


def real_frame_path(truth: TruthFile, folder: str | PathLike[str], must_exist: bool = True) -> Path:
    """Path of the raw frame a truth file labels.

    Parameters
    ----------
    truth : TruthFile
        A file read by :func:`read_truth_file`.
    folder : str or path
        Folder that holds the raw frames (e.g. the polanalyser captures).
    must_exist : bool
        Raise if the frame is not there.

    Returns
    -------
    Path
        ``folder / truth.frame``.

    Raises
    ------
    PolarsegError
        If ``must_exist`` and the file does not exist.
    """
    path = Path(folder) / truth.frame
    if must_exist and not path.is_file():
        raise PolarsegError(f"truth file {truth.path}: frame {truth.frame} not found in {folder}")
    return path


def frame_polarisation_image(truth: TruthFile, folder: str | PathLike[str]) -> PolarisationImage:
    """Polarisation image (Î, ρ, φ) of the raw frame a truth file labels.

    The frame is read with the file's mosaic layout and super-pixel demosaicing, and
    fitted by least squares with its saturated samples left out.

    Parameters
    ----------
    truth : TruthFile
        A file read by :func:`read_truth_file`.
    folder : str or path
        Folder that holds the raw frames.

    Returns
    -------
    napari_polarseg.engine.PolarisationImage
        On the grid of :attr:`TruthFile.truth`.

    Raises
    ------
    PolarsegError
        If the frame is missing or its super-pixel grid is not :attr:`TruthFile.shape`.
    """
    from .engine.physics.pixel_mask import validity_mask
    from .engine.physics.polarimage import polarisation_image
    from .io import read_stack

    data = read_stack(real_frame_path(truth, folder), mosaic=list(truth.mosaic))
    if tuple(data.stack.shape[1:]) != truth.shape:
        got = data.stack.shape[1:]
        raise PolarsegError(
            f"truth file {truth.path}: 'shape' is {truth.shape[0]} x {truth.shape[1]} but "
            f"frame {truth.frame} demosaics to {got[0]} x {got[1]}"
        )
    mask = validity_mask(data.stack, saturated=data.saturated)
    return polarisation_image(data.stack, data.angles_rad, weights=mask.sample_weights)


#: A function that makes the one-line error about a truth file from a problem.
Fail = Callable[[str], PolarsegError]


def read_truth_file(
    path: str | PathLike[str], expected_shape: Sequence[int] | None = None
) -> TruthFile:
    """Read, validate and rasterise a truth file.

    Polygons are filled with :func:`skimage.draw.polygon` (pixels whose centres lie
    inside), strokes drawn with :func:`skimage.draw.line` from vertex to vertex
    (vertices rounded to the nearest pixel). Polygons of one class may overlap each
    other; polygons of different classes may not, and a stroke may not cross another
    class's stroke or polygon.

    Parameters
    ----------
    path : str or path
        The JSON file.
    expected_shape : sequence of 2 int, optional
        (H, W) of the frame the labels will be compared with (e.g. the stack read with
        the file's mosaic); a different ``shape`` in the file is an error.

    Returns
    -------
    TruthFile

    Raises
    ------
    PolarsegError
        ``"truth file <path>: <problem>"`` (one line) for an unreadable or malformed
        file, or one whose ``shape`` is not ``expected_shape``.
    """
    path = Path(path)
    doc = _load_json(path)

    def fail(problem: str) -> PolarsegError:
        return PolarsegError(f"truth file {path}: {problem}")

    frame = _read_header(doc, fail)
    mosaic = doc["mosaic"]
    shape = _read_shape(doc["shape"], expected_shape, fail)
    height, width = shape
    check_bytes(3.0 * 4 * height * width, f"rasterising truth file {path} ({height} x {width})")
    classes = _read_classes(doc["classes"], fail)
    regions = _read_shapes(doc["regions"], "regions", 3, classes, shape, fail)
    stroke_paths = _read_shapes(doc["strokes"], "strokes", 2, classes, shape, fail)
    regions = {name: regions.get(name, ()) for name in classes}
    stroke_paths = {name: stroke_paths.get(name, ()) for name in classes}
    truth = _fill_regions(regions, classes, shape, fail)
    strokes = _draw_strokes(stroke_paths, classes, truth, fail)
    truth.setflags(write=False)
    strokes.setflags(write=False)
    return TruthFile(
        path=path,
        frame=frame,
        mosaic=tuple(float(a) for a in mosaic),
        shape=shape,
        classes=tuple(classes),
        regions=regions,
        stroke_paths=stroke_paths,
        truth=truth,
        strokes=strokes,
    )


def _read_header(doc: Any, fail: Fail) -> str:
    """Check the keys, ``frame``, ``coordinates`` and ``mosaic``; the frame's name."""
    if not isinstance(doc, dict):
        raise fail(f"the top level must be a JSON object, not {_json_type(doc)}")
    missing = [key for key in REQUIRED_KEYS if key not in doc]
    if missing:
        raise fail(f"missing key(s) {', '.join(missing)}")
    unknown = sorted(set(doc) - set(REQUIRED_KEYS) - set(OPTIONAL_KEYS))
    if unknown:
        raise fail(f"unknown key(s) {', '.join(map(repr, unknown))}")
    frame = doc["frame"]
    if not isinstance(frame, str) or not frame.strip() or not frame.isprintable():
        raise fail("'frame' must be a non-empty file name")
    if "/" in frame or "\\" in frame or frame in (".", ".."):
        raise fail(f"'frame' must be a file name without folders, not {_short(frame)}")
    if "coordinates" in doc and doc["coordinates"] != COORDINATES:
        raise fail(f"'coordinates' must be {COORDINATES!r}, not {_short(doc['coordinates'])}")
    mosaic = doc["mosaic"]
    if not isinstance(mosaic, list) or len(mosaic) != 4 or not all(_is_number(a) for a in mosaic):
        raise fail("'mosaic' must be a list of 4 angles in degrees")
    return frame


def _read_shape(shape: Any, expected_shape: Sequence[int] | None, fail: Fail) -> tuple[int, int]:
    """``shape`` as (rows, columns), checked against ``expected_shape``."""
    if (
        not isinstance(shape, list)
        or len(shape) != 2
        or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape)
    ):
        raise fail("'shape' must be [rows, columns], two positive integers")
    height, width = shape
    if expected_shape is not None and tuple(expected_shape) != (height, width):
        exp = tuple(int(n) for n in expected_shape)
        raise fail(f"'shape' is {height} x {width} but the frame is {exp[0]} x {exp[1]}")
    return height, width


def _read_classes(classes: Any, fail: Fail) -> list[str]:
    """``classes``: a non-empty list of unique, printable names (at most MAX_CLASSES)."""
    if not isinstance(classes, list) or not classes:
        raise fail("'classes' must be a non-empty list of names")
    if not all(isinstance(c, str) and c.strip() and c.isprintable() for c in classes):
        raise fail("every class name must be a non-empty string of printable characters")
    if len(set(classes)) != len(classes):
        raise fail("class names must be unique")
    if len(classes) > MAX_CLASSES:
        raise fail(f"at most {MAX_CLASSES} classes, not {len(classes)}")
    return classes


def _most_common_class(labels: np.ndarray, classes: list[str]) -> str:
    """The class most of ``labels`` (all non-zero) belong to, for messages."""
    return classes[int(np.bincount(labels).argmax()) - 1]


def _fill_regions(
    regions: dict[str, tuple[np.ndarray, ...]],
    classes: list[str],
    shape: tuple[int, int],
    fail: Fail,
) -> np.ndarray:
    """The ``truth`` image: each class's polygons filled with its label."""
    truth = np.zeros(shape, np.int32)
    for k, name in enumerate(classes, start=1):
        mine = np.zeros(shape, bool)
        for poly in regions[name]:
            rr, cc = draw_polygon(poly[:, 0], poly[:, 1], shape=shape)
            mine[rr, cc] = True
        clash = mine & (truth != 0)
        if clash.any():
            other = _most_common_class(truth[clash], classes)
            raise fail(
                f"polygons of classes {other!r} and {name!r} overlap in {int(clash.sum())} pixels"
            )
        truth[mine] = k
    return truth


def _draw_strokes(
    stroke_paths: dict[str, tuple[np.ndarray, ...]],
    classes: list[str],
    truth: np.ndarray,
    fail: Fail,
) -> np.ndarray:
    """The ``strokes`` image: each class's polylines drawn with its label."""
    strokes = np.zeros(truth.shape, np.int32)
    for k, name in enumerate(classes, start=1):
        mine = np.zeros(truth.shape, bool)
        for i, path_ in enumerate(stroke_paths[name], start=1):
            pts = np.rint(path_).astype(np.intp)
            for (r0, c0), (r1, c1) in zip(pts[:-1], pts[1:], strict=True):
                rr, cc = draw_line(int(r0), int(c0), int(r1), int(c1))
                mine[rr, cc] = True
            wrong = mine & (truth != 0) & (truth != k)
            if wrong.any():
                other = _most_common_class(truth[wrong], classes)
                raise fail(f"stroke {i} of class {name!r} crosses a polygon of class {other!r}")
        clash = mine & (strokes != 0)
        if clash.any():
            other = _most_common_class(strokes[clash], classes)
            raise fail(f"strokes of classes {other!r} and {name!r} cross")
        strokes[mine] = k
    return strokes


def _load_json(path: Path) -> Any:
    """Parse ``path`` as JSON, raising one-line errors."""
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise PolarsegError(
                f"truth file {path}: {size} bytes, more than the {MAX_FILE_BYTES} a "
                "truth file may have"
            )
        with open(path, encoding="utf-8") as fh:
            return json.load(fh, object_pairs_hook=_no_duplicate_keys)
    except PolarsegError:
        raise
    except _DuplicateKey as exc:
        raise PolarsegError(f"truth file {path}: key {exc.args[0]!r} appears twice") from None
    except json.JSONDecodeError as exc:
        raise PolarsegError(
            f"truth file {path}: not valid JSON ({exc.msg} at line {exc.lineno}, "
            f"column {exc.colno})"
        ) from None
    except RecursionError:
        raise PolarsegError(f"truth file {path}: JSON nested too deeply") from None
    except UnicodeDecodeError:
        raise PolarsegError(f"truth file {path}: not UTF-8 text") from None
    except OSError as exc:
        raise PolarsegError(f"truth file {path}: cannot be read ({exc.strerror or exc})") from None


class _DuplicateKey(Exception):
    """A JSON object with the same key twice (json.load would keep the last silently)."""


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``object_pairs_hook`` for :func:`json.load` that refuses repeated keys."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def _read_shapes(
    value: Any,
    key: str,
    min_points: int,
    classes: list[str],
    shape: tuple[int, int],
    fail: Fail,
) -> dict[str, tuple[np.ndarray, ...]]:
    """Validate ``regions`` (polygons) or ``strokes`` (polylines) of a truth file."""
    kind = "polygon" if key == "regions" else "stroke"
    if not isinstance(value, dict):
        raise fail(f"{key!r} must be an object mapping class names to lists of {kind}s")
    out: dict[str, tuple[np.ndarray, ...]] = {}
    for name, shapes in value.items():
        if name not in classes:
            known = ", ".join(classes)
            raise fail(f"{key!r} names unknown class {_short(name)}; classes are {known}")
        if not isinstance(shapes, list):
            raise fail(f"{key}[{_short(name)}] must be a list of {kind}s")
        arrays = []
        for i, pts in enumerate(shapes, start=1):
            what = f"{kind} {i} of class {name!r}"
            arrays.append(_read_points(pts, what, min_points, shape, fail))
        out[name] = tuple(arrays)
    return out


def _read_points(
    pts: Any, what: str, min_points: int, shape: tuple[int, int], fail: Fail
) -> np.ndarray:
    """Validate one vertex list: ``[[row, col], ...]`` inside the frame."""
    if not isinstance(pts, list):
        raise fail(f"{what} must be a list of [row, col] points")
    if len(pts) < min_points:
        raise fail(f"{what} has {len(pts)} point(s); it needs at least {min_points}")
    for p in pts:
        if not isinstance(p, list) or len(p) != 2 or not all(_is_number(v) for v in p):
            raise fail(f"{what}: every point must be [row, col] (two numbers), not {_short(p)}")
    arr = np.asarray(pts, dtype=np.float64)
    height, width = shape
    bad = (arr[:, 0] < 0) | (arr[:, 0] > height - 1) | (arr[:, 1] < 0) | (arr[:, 1] > width - 1)
    if bad.any():
        r, c = arr[int(np.argmax(bad))]
        raise fail(f"{what}: point [{r:g}, {c:g}] lies outside the {height} x {width} frame")
    arr.setflags(write=False)
    return arr


def _is_number(value: Any) -> bool:
    """A finite JSON number (bool excluded)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _short(value: Any, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters, for one-line messages."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _json_type(value: Any) -> str:
    """JSON name of a parsed value's type, for messages."""
    names: Mapping[type, str] = {
        list: "an array",
        str: "a string",
        int: "a number",
        float: "a number",
        bool: "a boolean",
        type(None): "null",
    }
    return names.get(type(value), type(value).__name__)
