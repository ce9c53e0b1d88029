"""Classifier files: a trained pixel classifier saved as data, never as code.

A pixel classifier trained on scribbles (scikit-learn's ``RandomForestClassifier`` or
``HistGradientBoostingClassifier``) is saved with :func:`save_classifier` and applied to
other images after :func:`load_classifier`. Such files get sent around, so loading one
must never run code from it: no :mod:`pickle` (or joblib) anywhere on the load path.

The file (suffix :data:`SUFFIX`, ``.polarseg-clf``)
---------------------------------------------------
A zip container with exactly three members, stored uncompressed:

``manifest.json``
    ``{"format": "napari-polarseg classifier", "format_version": 1, "model_type": ...,
    "members": {"model.skops": {"sha256": ..., "size": ...}, "metadata.json": {...}},
    "created_with": {"napari-polarseg": ..., "scikit-learn": ..., "skops": ...,
    "numpy": ...}}``.
``model.skops``
    The fitted estimator in the `skops <https://skops.readthedocs.io>`_ format
    (``skops.io.dumps``): a zip of a JSON schema and ``.npy`` arrays that describes the
    object tree by type names and attribute values instead of pickle opcodes.
``metadata.json``
    The caller's metadata: a JSON object of plain JSON values (see
    :func:`classifier_metadata` for the keys the package uses).

How a file is checked before anything in it is used
---------------------------------------------------
:func:`load_classifier` refuses, with a :class:`~napari_polarseg.engine.PolarsegError`
whose one line names the file and the problem, anything that is not exactly such a file:

1. empty, not a zip, a damaged or truncated zip (zip CRC-32), encrypted or compressed
   members (the three are stored as they are, so every byte of them is under the CRC; the
   skops payload is compressed inside), a member other than the three above, or a zip
   without our manifest (any other zip, including a bare ``.skops`` file);
2. a manifest of another format or of a format version other than
   :data:`FORMAT_VERSION`;
3. members whose SHA-256 digests differ from the manifest's. This is an **integrity**
   check (it catches a damaged or edited file), **not a signature**: anyone can edit a
   file and recompute the digests, so it says nothing about who made the file. Safety
   against a crafted file comes from the next steps, which do not trust the digests;
4. a model payload whose object tree (read as JSON, nothing imported) names a type
   outside :data:`ALLOWED_TYPES` or a skops loader outside :data:`ALLOWED_LOADERS`
   (functions, methods, ``functools.partial``, constructor calls ... are never
   allowed), whose root is not one of :data:`ALLOWED_MODEL_TYPES`, or for which
   ``skops.io.get_untrusted_types`` reports a type outside :data:`ALLOWED_TYPES`;
5. only then ``skops.io.loads(payload, trusted=SKOPS_TRUSTED)`` with that fixed,
   explicit list (never ``trusted=True``, never the file's own list of types);
6. a loaded model whose trees are not well formed (:func:`check_model`): skops can only
   check types, and scikit-learn walks tree node arrays without bounds checks, so a
   crafted child or feature index could crash the process at the first prediction;
7. metadata that is not a JSON object of plain JSON values, or that disagrees with the
   model (number of features, class values).

Examples
--------
>>> meta = classifier_metadata(model, feature_names=names, n_pixels=1234)  # doctest: +SKIP
>>> save_classifier("leaf.polarseg-clf", model, meta)                     # doctest: +SKIP
>>> model, meta = load_classifier("leaf.polarseg-clf")                     # doctest: +SKIP
>>> describe_classifier("leaf.polarseg-clf")                               # doctest: +SKIP
'leaf.polarseg-clf: RandomForestClassifier (100 trees), 3 classes (1, 2, 3), ...'
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import zipfile
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import sklearn
import skops
import skops.io as sio
from sklearn.ensemble import (
    ExtraTreesClassifier,
    HistGradientBoostingClassifier,
    RandomForestClassifier,
)
from sklearn.ensemble._hist_gradient_boosting.binning import _BinMapper
from sklearn.ensemble._hist_gradient_boosting.common import PREDICTOR_RECORD_DTYPE
from sklearn.ensemble._hist_gradient_boosting.predictor import TreePredictor
from sklearn.tree import DecisionTreeClassifier, ExtraTreeClassifier
from sklearn.tree._tree import Tree

from . import __version__
from .engine.analysis.pixel_classifier import PixelClassifier
from .engine.errors import PolarsegError
from .engine.limits import format_bytes, memory_limit
from .io import atomic_output

PathLike = str | os.PathLike

#: File name suffix of classifier files.
SUFFIX = ".polarseg-clf"
#: The manifest's ``format`` value.
FORMAT_NAME = "napari-polarseg classifier"
#: The format version this module writes and the only one it reads.
FORMAT_VERSION = 1

MANIFEST_NAME = "manifest.json"
MODEL_NAME = "model.skops"
METADATA_NAME = "metadata.json"
#: The members a classifier file holds, no more, no fewer.
MEMBERS = (MANIFEST_NAME, MODEL_NAME, METADATA_NAME)

_RF = "sklearn.ensemble._forest.RandomForestClassifier"
_ET = "sklearn.ensemble._forest.ExtraTreesClassifier"
_HGB = "sklearn.ensemble._hist_gradient_boosting.gradient_boosting.HistGradientBoostingClassifier"
#: The estimators a classifier file may hold (the type at the root of the payload).
ALLOWED_MODEL_TYPES = MappingProxyType(
    {
        _RF: RandomForestClassifier,
        _ET: ExtraTreesClassifier,
        _HGB: HistGradientBoostingClassifier,
    }
)

#: Every type the payload's object tree may name, as skops writes it
#: (``module.class``). skops itself trusts *every* scikit-learn estimator by default
#: (``sklearn.svm.SVC``, ``Pipeline``, ``FunctionTransformer`` holding any numpy
#: function, ...), so this list, not skops's default, decides what a file may contain:
#: the two classifiers and exactly the parts their fitted state is made of.
ALLOWED_TYPES = frozenset(
    {
        # containers and scalars
        "builtins.dict",
        "builtins.list",
        "builtins.tuple",
        "builtins.str",
        "builtins.int",
        "builtins.float",
        "builtins.bool",
        "builtins.NoneType",
        "numpy.ndarray",
        "numpy.bool",
        "numpy.bool_",
        "numpy.str_",
        "numpy.int8",
        "numpy.int16",
        "numpy.int32",
        "numpy.int64",
        "numpy.uint8",
        "numpy.uint16",
        "numpy.uint32",
        "numpy.uint64",
        "numpy.float32",
        "numpy.float64",
        # random_state=RandomState(...) and HGB's feature-subsampling generator
        "numpy.random.mtrand.RandomState",
        "numpy.random._generator.Generator",
        # the random forests (and extremely randomised trees)
        _RF,
        _ET,
        "sklearn.tree._classes.DecisionTreeClassifier",
        "sklearn.tree._classes.ExtraTreeClassifier",
        "sklearn.tree._tree.Tree",
        # histogram gradient boosting
        _HGB,
        "sklearn.ensemble._hist_gradient_boosting.binning._BinMapper",
        "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
        "sklearn.preprocessing._label.LabelEncoder",
        "sklearn._loss.loss.HalfBinomialLoss",
        "sklearn._loss.loss.HalfMultinomialLoss",
        "sklearn._loss._loss.CyHalfBinomialLoss",
        "sklearn._loss._loss.CyHalfMultinomialLoss",
        "sklearn._loss.link.Interval",
        "sklearn._loss.link.LogitLink",
        "sklearn._loss.link.MultinomialLogit",
    }
)

#: The skops node kinds ("loaders") a payload may use. Left out on purpose: the ones that
#: resolve and hand out callables (``FunctionNode``, ``MethodNode``, ``PartialNode``,
#: ``OperatorFuncNode``) or call a named type with arguments from the file
#: (``ConstructorFromReduceNode``), and every kind these two models never need.
ALLOWED_LOADERS = frozenset(
    {
        "ObjectNode",
        "DictNode",
        "ListNode",
        "TupleNode",
        "JsonNode",
        "NdArrayNode",
        "TypeNode",
        "TreeNode",
        "LossNode",
        "RandomStateNode",
        "RandomGeneratorNode",
        "CachedNode",
    }
)

#: The explicit ``trusted`` list given to ``skops.io.loads``: the two allowed types that
#: skops does not trust by default because their node arrays are indexed without bounds
#: checks. They are trusted here only because :func:`check_model` validates those arrays
#: right after loading, before the model is returned or used.
SKOPS_TRUSTED = (
    "sklearn.tree._tree.Tree",
    "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
)

# skops protocol 2 (skops 0.10+) is the first whose audits are as strict as today's; the
# protocol number comes from the file and selects which (older) node code audits it, so
# an older number would let a file opt into laxer audits. skops refuses newer numbers.
_MIN_SKOPS_PROTOCOL = 2

# Bounds on what a file may make us read, before reading it.
_MAX_MANIFEST_BYTES = 1 << 20
_MAX_METADATA_BYTES = 16 << 20
# Nesting of the metadata (JSON) and of the model's object tree (skops schema).
_MAX_METADATA_DEPTH = 64
_MAX_SCHEMA_DEPTH = 200

_SHA256_RE = re.compile(r"[0-9a-f]{64}")
_NPY_MEMBER_RE = re.compile(r"[0-9A-Za-z_.-]{1,200}\.npy")

# The metadata keys the package gives a meaning to (all optional; checked when present).
#: List of str, one per feature column the model takes.
KEY_FEATURE_NAMES = "feature_names"
#: JSON object: the parameters the features were computed with.
KEY_FEATURE_PARAMS = "feature_params"
#: List of the class values (``model.classes_.tolist()``).
KEY_CLASSES = "classes"
#: str: napari-polarseg version that trained the model.
KEY_PACKAGE_VERSION = "package_version"
#: int: :data:`FORMAT_VERSION` of the file the metadata was made for.
KEY_FORMAT_VERSION = "format_version"
#: JSON object: training summary; ``"n_pixels"`` (int) is the number of training pixels.
KEY_TRAINING = "training"


# -- public API -------------------------------------------------------------------------


def save_classifier(path: PathLike, model: Any, metadata: dict[str, Any]) -> None:
    """Write a fitted classifier and its metadata to a ``.polarseg-clf`` file, atomically.

    Parameters
    ----------
    path : str or path
        Destination; must end with :data:`SUFFIX` (``.polarseg-clf``).
    model : RandomForestClassifier or HistGradientBoostingClassifier
        A fitted estimator of exactly one of these types (no subclass, no pipeline).
    metadata : dict
        JSON object of plain JSON values (str keys; str, int, float, bool, None, lists
        and dicts of them; no NaN or infinity, no tuples or numpy scalars), returned
        as it is by :func:`load_classifier`. The keys of :func:`classifier_metadata`
        are checked against the model when present.

    Raises
    ------
    PolarsegError
        If the path, the model or the metadata cannot make a file that
        :func:`load_classifier` accepts, or the file cannot be written. Nothing is
        written then, and an existing file at ``path`` is left as it was.
    """
    path = Path(path)
    if not path.name.endswith(SUFFIX) or path.name == SUFFIX:
        raise _error(path, f"a classifier file name must end with {SUFFIX}")
    _check_model_or_raise(path, model)
    _check_metadata(path, metadata, model)
    metadata_bytes = json.dumps(metadata, allow_nan=False, ensure_ascii=False, indent=1).encode(
        "utf-8"
    )
    try:
        payload = sio.dumps(model, compression=zipfile.ZIP_DEFLATED)
    except Exception as exc:  # skops raises assorted errors for unsupported contents
        raise _error(path, f"skops cannot save this model ({_first_line(exc)})") from None
    # The same static checks as loading: never write a file that would then be refused
    # (e.g. a model whose state holds a scorer function or an unexpected type).
    model_type = _check_payload(path, payload, _type_name(type(model)))
    manifest = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "model_type": model_type,
        "members": {
            MODEL_NAME: {"sha256": _sha256(payload), "size": len(payload)},
            METADATA_NAME: {"sha256": _sha256(metadata_bytes), "size": len(metadata_bytes)},
        },
        "created_with": {
            "napari-polarseg": __version__,
            "scikit-learn": sklearn.__version__,
            "skops": skops.__version__,
            "numpy": np.__version__,
        },
    }
    manifest_bytes = json.dumps(manifest, indent=1).encode("utf-8")
    try:
        # Members are stored, not compressed (the skops payload is compressed inside):
        # then every byte of a member is content under the zip's CRC-32, so any flipped
        # byte there is caught, and reading inflates nothing.
        with atomic_output(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as zf:
            zf.writestr(MANIFEST_NAME, manifest_bytes)
            zf.writestr(MODEL_NAME, payload)
            zf.writestr(METADATA_NAME, metadata_bytes)
    except OSError as exc:
        raise _error(path, f"cannot write the classifier file ({_first_line(exc)})") from None


def load_classifier(path: PathLike) -> tuple[Any, dict[str, Any]]:
    """Read a ``.polarseg-clf`` file written by :func:`save_classifier`, running no code.

    Parameters
    ----------
    path : str or path
        The classifier file (the suffix is not required; the content is checked).

    Returns
    -------
    model : RandomForestClassifier or HistGradientBoostingClassifier
        The fitted estimator, its trees validated.
    metadata : dict
        The metadata given to :func:`save_classifier`.

    Raises
    ------
    PolarsegError
        One line naming the file and the problem, for anything that is not exactly such
        a file (see the module docstring for the checks).
    """
    model, metadata, _ = _read(path)
    return model, metadata


def describe_classifier(path: PathLike) -> str:
    """One line saying what a classifier file holds, after loading it fully.

    Parameters
    ----------
    path : str or path
        The classifier file.

    Returns
    -------
    str
        E.g. ``"leaf.polarseg-clf: RandomForestClassifier (100 trees), 3 classes (1, 2,
        3), 12 features, trained on 5321 pixels"``.

    Raises
    ------
    PolarsegError
        As :func:`load_classifier`.
    """
    model, metadata, _ = _read(path)
    if isinstance(model, RandomForestClassifier | ExtraTreesClassifier):
        kind = f"{type(model).__name__} ({len(model.estimators_)} trees)"
    else:
        kind = f"HistGradientBoostingClassifier ({len(model._predictors)} iterations)"
    classes = [str(c) for c in model.classes_.tolist()]
    shown = ", ".join(classes[:8]) + (", ..." if len(classes) > 8 else "")
    training = metadata.get(KEY_TRAINING)
    n_pixels = training.get("n_pixels") if isinstance(training, dict) else None
    trained = (
        f"trained on {n_pixels} pixels"
        if isinstance(n_pixels, int) and not isinstance(n_pixels, bool)
        else "trained on an unknown number of pixels"
    )
    return _one_line(
        f"{_show(path)}: {kind}, {len(classes)} classes ({shown}), "
        f"{model.n_features_in_} features, {trained}"
    )


def classifier_metadata(
    model: Any,
    feature_names: list[str] | None = None,
    feature_params: dict[str, Any] | None = None,
    n_pixels: int | None = None,
    **training: Any,
) -> dict[str, Any]:
    """The metadata dict the package writes with a classifier.

    Parameters
    ----------
    model : RandomForestClassifier or HistGradientBoostingClassifier
        The fitted model (for its class values).
    feature_names : list of str, optional
        One name per feature column.
    feature_params : dict, optional
        Plain JSON parameters the features were computed with.
    n_pixels : int, optional
        Number of training pixels (shown by :func:`describe_classifier`).
    **training
        More plain JSON items of the training summary.

    Returns
    -------
    dict
        Keys :data:`KEY_FEATURE_NAMES`, :data:`KEY_FEATURE_PARAMS`, :data:`KEY_CLASSES`,
        :data:`KEY_PACKAGE_VERSION`, :data:`KEY_FORMAT_VERSION`, :data:`KEY_TRAINING`.
    """
    summary = dict(training)
    if n_pixels is not None:
        summary["n_pixels"] = int(n_pixels)
    meta: dict[str, Any] = {
        KEY_CLASSES: np.asarray(model.classes_).tolist(),
        KEY_PACKAGE_VERSION: __version__,
        KEY_FORMAT_VERSION: FORMAT_VERSION,
        KEY_TRAINING: summary,
    }
    if feature_names is not None:
        meta[KEY_FEATURE_NAMES] = [str(name) for name in feature_names]
    if feature_params is not None:
        meta[KEY_FEATURE_PARAMS] = dict(feature_params)
    return meta


def check_model(model: Any) -> None:
    """Check that a model is an allowed, fitted classifier with well-formed trees.

    scikit-learn predicts by walking node arrays in compiled code without bounds checks,
    trusting that child indices point inside the array and feature indices inside the
    input's columns. A model built by scikit-learn satisfies this; a model read from a
    crafted file need not, and would then read out of bounds (crash) at the first
    prediction. So every node is checked: a split node's children lie *after* it in the
    array (true of every tree scikit-learn grows, and it also rules out cycles, so a
    walk ends within ``node_count`` steps) and its feature index is a column of the
    input.

    Parameters
    ----------
    model : object
        The estimator to check.

    Raises
    ------
    ValueError
        With a one-line description of the first problem found.
    """
    name = _type_name(type(model))
    if name not in ALLOWED_MODEL_TYPES or type(model) is not ALLOWED_MODEL_TYPES[name]:
        raise ValueError(
            f"the model is a {name}; only RandomForestClassifier, ExtraTreesClassifier and "
            "HistGradientBoostingClassifier (not subclasses or pipelines) are allowed"
        )
    n_features = getattr(model, "n_features_in_", None)
    if not _is_int(n_features) or n_features < 1:
        raise ValueError("the model is not fitted (no n_features_in_)")
    classes = getattr(model, "classes_", None)
    if not isinstance(classes, np.ndarray) or classes.ndim != 1 or classes.size < 2:
        raise ValueError("the model's classes_ is not a 1-D array of at least two classes")
    if classes.dtype.kind not in "iufU":
        raise ValueError(
            f"the model's class values have dtype {classes.dtype}; train on integer, float "
            "or str labels"
        )
    if isinstance(model, RandomForestClassifier | ExtraTreesClassifier):
        _check_forest(model, n_features, classes.size)
    else:
        _check_boosting(model, n_features, classes.size)


# -- reading ----------------------------------------------------------------------------


def _read(path: PathLike) -> tuple[Any, dict[str, Any], dict[str, Any]]:
    """Model, metadata and manifest of a classifier file, after every check."""
    path = Path(path)
    data = _read_bytes(path)
    if not data.startswith(b"PK\x03\x04"):
        raise _error(path, "not a napari-polarseg classifier file (not a zip container)")
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except Exception as exc:  # BadZipFile, struct.error, ...: a broken directory
        raise _error(path, f"damaged or truncated file ({_first_line(exc)})") from None
    with zf:
        names = [info.filename for info in infos]
        if MANIFEST_NAME not in names:
            raise _error(path, f"not a napari-polarseg classifier file (no {MANIFEST_NAME})")
        if len(set(names)) != len(names) or set(names) != set(MEMBERS):
            raise _error(
                path,
                f"not a napari-polarseg classifier file (members {sorted(set(names))}, "
                f"expected {sorted(MEMBERS)})",
            )
        limits = {
            MANIFEST_NAME: _MAX_MANIFEST_BYTES,
            METADATA_NAME: _MAX_METADATA_BYTES,
            MODEL_NAME: memory_limit(),
        }
        for info in infos:
            _check_member_info(path, info, limits[info.filename])
        manifest = _parse_json(path, _read_member(path, zf, MANIFEST_NAME), MANIFEST_NAME)
        _check_manifest(path, manifest)
        members = {name: _read_member(path, zf, name) for name in (MODEL_NAME, METADATA_NAME)}
    for name, content in members.items():
        expected = manifest["members"][name]
        if len(content) != expected["size"] or _sha256(content) != expected["sha256"]:
            raise _error(
                path,
                f"{name} does not match its SHA-256 digest in the manifest (the file was "
                "edited or damaged)",
            )
    metadata = _parse_json(path, members[METADATA_NAME], METADATA_NAME)
    _check_plain_json(path, metadata)
    payload = members[MODEL_NAME]
    _check_payload(path, payload, manifest["model_type"])
    try:
        model = sio.loads(payload, trusted=list(SKOPS_TRUSTED))
    except Exception as exc:  # any failure of skops on a payload is a bad file
        raise _error(path, f"cannot load the model ({_first_line(exc)})") from None
    _check_model_or_raise(path, model)
    if _type_name(type(model)) != manifest["model_type"]:
        raise _error(path, "the model's type differs from the manifest's model_type")
    _check_metadata(path, metadata, model)
    return model, metadata, manifest


def _read_bytes(path: Path) -> bytes:
    """The whole file, size-checked first (one read: no change between checks and use)."""
    try:
        size = path.stat().st_size
        if not path.is_file():
            raise _error(path, "not a file")
        if size == 0:
            raise _error(path, "empty file (not a napari-polarseg classifier file)")
        limit = memory_limit()
        if size > limit:
            raise _error(
                path,
                f"file of {format_bytes(size)} is larger than the memory limit of "
                f"{format_bytes(limit)}",
            )
        with open(path, "rb") as handle:
            return handle.read(limit + 1)
    except OSError as exc:
        reason = exc.strerror or _first_line(exc)
        raise _error(path, f"cannot read the classifier file ({reason})") from None


def _check_member_info(path: Path, info: zipfile.ZipInfo, limit: int) -> None:
    if info.flag_bits & 0x1:
        raise _error(path, f"{info.filename} is encrypted")
    if info.compress_type != zipfile.ZIP_STORED:
        raise _error(path, f"{info.filename} is compressed (classifier files store members)")
    # file_size is what zipfile will read for the member (no more), so checking it first
    # bounds the memory a crafted file can claim.
    if info.file_size > limit:
        raise _error(
            path,
            f"{info.filename} would inflate to {format_bytes(info.file_size)}, more than "
            f"{format_bytes(limit)}",
        )


def _read_member(path: Path, zf: zipfile.ZipFile, name: str) -> bytes:
    try:
        return zf.read(name)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, RuntimeError) as exc:
        raise _error(path, f"damaged or truncated file ({_first_line(exc)})") from None
    except Exception as exc:  # zlib.error and other decoder failures
        raise _error(path, f"damaged or truncated file ({_first_line(exc)})") from None


def _parse_json(path: Path, raw: bytes, name: str) -> Any:
    """Strict JSON: UTF-8, no NaN/Infinity, no repeated keys."""

    def no_constants(token: str) -> Any:
        raise ValueError(f"{token} is not plain JSON")

    def no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        result = dict(pairs)
        if len(result) != len(pairs):
            raise ValueError("repeated key")
        return result

    try:
        return json.loads(
            raw.decode("utf-8"), parse_constant=no_constants, object_pairs_hook=no_duplicates
        )
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise _error(path, f"{name} is not valid JSON ({_first_line(exc)})") from None


def _check_manifest(path: Path, manifest: Any) -> None:
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT_NAME:
        raise _error(
            path, f"not a napari-polarseg classifier file ({MANIFEST_NAME} of another format)"
        )
    version = manifest.get("format_version")
    if version != FORMAT_VERSION or not _is_int(version):
        raise _error(
            path,
            f"classifier format version {version!r} is not supported (this napari-polarseg "
            f"{__version__} reads version {FORMAT_VERSION})",
        )
    model_type = manifest.get("model_type")
    if not isinstance(model_type, str) or model_type not in ALLOWED_MODEL_TYPES:
        raise _error(path, f"model type {_short(model_type)} is not on the allow-list")
    members = manifest.get("members")
    if not isinstance(members, dict) or set(members) != {MODEL_NAME, METADATA_NAME}:
        raise _error(path, f"{MANIFEST_NAME} does not list the digests of the members")
    for name, entry in members.items():
        if (
            not isinstance(entry, dict)
            or not isinstance(entry.get("sha256"), str)
            or not _SHA256_RE.fullmatch(entry["sha256"])
            or not _is_int(entry.get("size"))
        ):
            raise _error(path, f"{MANIFEST_NAME} has no valid SHA-256 digest and size of {name}")


def _check_payload(path: Path, payload: bytes, model_type: str) -> str:
    """Static checks of a skops payload: structure and every type, before skops reads it.

    Returns the payload's root type name.
    """
    if not payload.startswith(b"PK\x03\x04"):
        raise _error(path, f"{MODEL_NAME} is not a skops payload (not a zip)")
    try:
        with zipfile.ZipFile(io.BytesIO(payload)) as inner:
            infos = inner.infolist()
            names = [info.filename for info in infos]
            if "schema.json" not in names or len(set(names)) != len(names):
                raise _error(path, f"{MODEL_NAME} is not a skops payload (no schema.json)")
            if any(n != "schema.json" and not _NPY_MEMBER_RE.fullmatch(n) for n in names):
                raise _error(path, f"{MODEL_NAME} holds members other than skops arrays")
            total = sum(info.file_size for info in infos)
            if total > memory_limit():
                raise _error(path, f"{MODEL_NAME} would inflate to {format_bytes(total)} of arrays")
            for info in infos:
                if info.flag_bits & 0x1 or info.compress_type not in (
                    zipfile.ZIP_STORED,
                    zipfile.ZIP_DEFLATED,
                ):
                    raise _error(path, f"{MODEL_NAME} has an encrypted or odd member")
            raw_schema = inner.read("schema.json")
    except PolarsegError:
        raise
    except Exception as exc:  # BadZipFile, zlib.error, ...
        raise _error(path, f"{MODEL_NAME} is damaged ({_first_line(exc)})") from None
    schema = _parse_json(path, raw_schema, f"{MODEL_NAME} schema")
    if not isinstance(schema, dict):
        raise _error(path, f"{MODEL_NAME} schema is not a JSON object")
    protocol = schema.get("protocol")
    if not _is_int(protocol) or protocol < _MIN_SKOPS_PROTOCOL:
        raise _error(path, f"{MODEL_NAME} uses skops protocol {protocol!r} (need 2 or newer)")
    root = _node_type(schema)
    if root not in ALLOWED_MODEL_TYPES or schema.get("__loader__") != "ObjectNode":
        raise _error(path, f"model type {_short(root)} is not on the allow-list")
    if root != model_type:
        raise _error(path, f"the model is a {root}, not the manifest's {model_type}")
    _check_schema_types(path, schema)
    # skops's own view of the types (it resolves some names from values, e.g. the bit
    # generator of a numpy Generator): nothing outside our list either.
    try:
        untrusted = sio.get_untrusted_types(data=payload)
    except Exception as exc:
        raise _error(path, f"{MODEL_NAME} cannot be audited ({_first_line(exc)})") from None
    outside = sorted(set(untrusted) - ALLOWED_TYPES)
    if outside:
        raise _error(path, f"the model holds types outside the allow-list: {_short_list(outside)}")
    return root


def _check_schema_types(path: Path, schema: dict[str, Any]) -> None:
    """Every node of the skops object tree: an allowed loader naming an allowed type."""
    # Iterative walk: a crafted, deeply nested schema must not hit the recursion limit.
    stack: list[tuple[Any, int]] = [(schema, 0)]
    while stack:
        item, depth = stack.pop()
        if depth > _MAX_SCHEMA_DEPTH:
            raise _error(path, f"{MODEL_NAME} schema is nested too deeply")
        if isinstance(item, dict):
            if "__loader__" in item:
                loader = item["__loader__"]
                if not isinstance(loader, str) or loader not in ALLOWED_LOADERS:
                    raise _error(
                        path,
                        f"the model uses skops node {_short(loader)}, which is not allowed "
                        "(functions, methods and constructor calls never are)",
                    )
                # a CachedNode only points back at a node already checked
                if loader != "CachedNode" and _node_type(item) not in ALLOWED_TYPES:
                    raise _error(
                        path,
                        f"the model holds type {_short(_node_type(item))}, not on the allow-list",
                    )
            stack.extend((value, depth + 1) for value in item.values())
        elif isinstance(item, list):
            stack.extend((value, depth + 1) for value in item)


def _node_type(node: dict[str, Any]) -> str:
    module, name = node.get("__module__"), node.get("__class__")
    if not isinstance(module, str) or not isinstance(name, str):
        return repr((module, name))
    return f"{module}.{name}"


# -- model checks -----------------------------------------------------------------------


def _check_model_or_raise(path: Path, model: Any) -> None:
    try:
        check_model(model)
    except ValueError as exc:
        raise _error(path, _first_line(exc)) from None
    except Exception as exc:  # a crafted attribute of the wrong kind (TypeError, ...)
        raise _error(path, f"the model is malformed ({_first_line(exc)})") from None


#: The tree type of each forest type.
FOREST_TREES = MappingProxyType(
    {RandomForestClassifier: DecisionTreeClassifier, ExtraTreesClassifier: ExtraTreeClassifier}
)


def _check_forest(
    model: RandomForestClassifier | ExtraTreesClassifier, n_features: int, n_classes: int
) -> None:
    if model.n_outputs_ != 1 or model.n_classes_ != n_classes:
        raise ValueError("the forest is not a single-output classifier of its classes")
    if model.n_jobs is not None and not _is_int(model.n_jobs):
        raise ValueError(f"the forest's n_jobs is {model.n_jobs!r}")
    trees = model.estimators_
    if not isinstance(trees, list) or not trees:
        raise ValueError("the forest has no trees")
    for i, est in enumerate(trees):
        if type(est) is not FOREST_TREES[type(model)]:
            raise ValueError(f"tree {i} of the forest is a {_type_name(type(est))}")
        if est.n_features_in_ != n_features or est.n_outputs_ != 1 or est.n_classes_ != n_classes:
            raise ValueError(f"tree {i} of the forest does not match the forest's shape")
        if type(est.tree_) is not Tree:
            raise ValueError(f"tree {i} of the forest has no tree structure")
        _check_tree(est.tree_, n_features, n_classes, f"tree {i}")


def _check_tree(tree: Tree, n_features: int, n_classes: int, what: str) -> None:
    # node_count comes from the file, capacity from the node array actually stored; the
    # node properties read node_count entries, so check it before touching any of them
    # (scikit-learn's __setstate__ clamps node_count today; this does not rely on it).
    count, capacity = tree.node_count, tree.capacity
    if not 1 <= count <= capacity:
        raise ValueError(f"{what} claims {count} nodes but stores {capacity}")
    if tree.n_outputs != 1 or tree.n_features != n_features:
        raise ValueError(f"{what} has {tree.n_features} features, expected {n_features}")
    if tree.max_n_classes != n_classes or tree.n_classes.tolist() != [n_classes]:
        raise ValueError(f"{what} has {tree.max_n_classes} classes, expected {n_classes}")
    left = np.asarray(tree.children_left, dtype=np.int64)
    right = np.asarray(tree.children_right, dtype=np.int64)
    feature = np.asarray(tree.feature, dtype=np.int64)
    # sklearn's TREE_LEAF is -1; the walk stops only where left_child is -1 and otherwise
    # follows either child, so a node with just one -1 child would send it to index -1.
    leaf = left == -1
    if np.any(leaf != (right == -1)):
        raise ValueError(f"{what} has a node with only one child")
    _check_nodes(what, count, ~leaf, left, right, feature, n_features)
    if tree.value.shape != (count, 1, n_classes):
        raise ValueError(f"{what} has a value array of the wrong shape")


def _check_nodes(
    what: str,
    count: int,
    split: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    feature: np.ndarray,
    n_features: int,
) -> None:
    """Split nodes' children after them and inside the array, their features in range."""
    index = np.arange(count)
    for child in (left, right):
        if np.any((child[split] <= index[split]) | (child[split] >= count)):
            raise ValueError(f"{what} has a child index outside the tree")
    if np.any((feature[split] < 0) | (feature[split] >= n_features)):
        raise ValueError(f"{what} splits on a feature the model does not have")


def _check_boosting(model: HistGradientBoostingClassifier, n_features: int, n_classes: int) -> None:
    per_iter = 1 if n_classes == 2 else n_classes
    if model.n_trees_per_iteration_ != per_iter:
        raise ValueError("the model's trees per iteration do not match its classes")
    if getattr(model, "_preprocessor", None) is not None:
        raise ValueError("the model has a categorical preprocessor (not supported)")
    if model.is_categorical_ is not None and np.any(model.is_categorical_):
        raise ValueError("the model has categorical features (not supported)")
    mapper = model._bin_mapper
    if type(mapper) is not _BinMapper:
        raise ValueError("the model has no bin mapper")
    cats = mapper.is_categorical_
    # predict() builds per-feature category bitsets from this array; with no categorical
    # feature those bitsets are never indexed.
    if not isinstance(cats, np.ndarray) or cats.shape != (n_features,) or np.any(cats):
        raise ValueError("the model's bin mapper has categorical features (not supported)")
    baseline = model._baseline_prediction
    if not isinstance(baseline, np.ndarray) or baseline.shape != (1, per_iter):
        raise ValueError("the model's baseline prediction has the wrong shape")
    iterations = model._predictors
    if not isinstance(iterations, list) or not iterations:
        raise ValueError("the model has no trees")
    for i, predictors in enumerate(iterations):
        if not isinstance(predictors, list) or len(predictors) != per_iter:
            raise ValueError(f"iteration {i} of the model has the wrong number of trees")
        for k, predictor in enumerate(predictors):
            if type(predictor) is not TreePredictor:
                raise ValueError(f"tree {i}/{k} is a {_type_name(type(predictor))}")
            _check_predictor(predictor, n_features, f"tree {i}/{k}")


def _check_predictor(predictor: TreePredictor, n_features: int, what: str) -> None:
    nodes = predictor.nodes
    if not isinstance(nodes, np.ndarray) or nodes.dtype != PREDICTOR_RECORD_DTYPE:
        raise ValueError(f"{what} has no node array of scikit-learn's node type")
    if nodes.ndim != 1 or nodes.size < 1:
        raise ValueError(f"{what} has an empty or misshapen node array")
    for name in ("binned_left_cat_bitsets", "raw_left_cat_bitsets"):
        bitsets = getattr(predictor, name)
        if (
            not isinstance(bitsets, np.ndarray)
            or bitsets.dtype != np.uint32
            or bitsets.ndim != 2
            or bitsets.shape[1] != 8
        ):
            raise ValueError(f"{what} has a malformed {name}")
    if np.any(nodes["is_categorical"]):
        raise ValueError(f"{what} has a categorical split (not supported)")
    split = nodes["is_leaf"] == 0
    _check_nodes(
        what,
        nodes.size,
        split,
        nodes["left"].astype(np.int64),
        nodes["right"].astype(np.int64),
        nodes["feature_idx"].astype(np.int64),
        n_features,
    )


# -- metadata ---------------------------------------------------------------------------


def _check_plain_json(path: Path, metadata: Any) -> None:
    """A dict of plain JSON values: exact builtin types, finite floats, str keys."""
    if type(metadata) is not dict:
        raise _error(path, f"metadata must be a JSON object (dict), not {type(metadata).__name__}")
    stack: list[tuple[Any, str, int]] = [(metadata, "metadata", 0)]
    while stack:
        value, where, depth = stack.pop()
        if depth > _MAX_METADATA_DEPTH:
            raise _error(path, f"{where} is nested too deeply")
        kind = type(value)
        # exact types: a numpy scalar, a tuple or a subclass would not come back as it went
        if kind is dict:
            for key, item in value.items():
                if type(key) is not str:
                    raise _error(path, f"{where} has a key {key!r} that is not a str")
                stack.append((item, f"{where}[{key!r}]", depth + 1))
        elif kind is list:
            stack.extend((item, f"{where}[{i}]", depth + 1) for i, item in enumerate(value))
        elif kind is float:
            if not math.isfinite(value):
                raise _error(path, f"{where} is {value!r}, not a finite number")
        elif kind not in (str, int, bool, type(None)):
            raise _error(
                path,
                f"{where} is a {kind.__name__}, not a plain JSON value (str, int, "
                "float, bool, None, list, dict)",
            )


def _check_metadata(path: Path, metadata: Any, model: Any) -> None:
    """Plain JSON, and the package's keys (when present) agreeing with the model."""
    _check_plain_json(path, metadata)
    names = metadata.get(KEY_FEATURE_NAMES)
    if names is not None and (
        type(names) is not list
        or any(type(n) is not str for n in names)
        or len(names) != model.n_features_in_
    ):
        raise _error(
            path,
            f"metadata {KEY_FEATURE_NAMES!r} must be {model.n_features_in_} names, one per "
            "feature of the model",
        )
    classes = metadata.get(KEY_CLASSES)
    if classes is not None and classes != model.classes_.tolist():
        raise _error(path, f"metadata {KEY_CLASSES!r} differs from the model's class values")
    version = metadata.get(KEY_FORMAT_VERSION)
    if version is not None and (not _is_int(version) or version != FORMAT_VERSION):
        raise _error(path, f"metadata {KEY_FORMAT_VERSION!r} is {version!r}, not {FORMAT_VERSION}")
    for key in (KEY_FEATURE_PARAMS, KEY_TRAINING):
        if metadata.get(key) is not None and type(metadata[key]) is not dict:
            raise _error(path, f"metadata {key!r} must be a JSON object")


# -- small helpers ----------------------------------------------------------------------


def _type_name(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _is_int(value: Any) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _show(path: PathLike) -> str:
    return _one_line(os.fspath(path))


def _one_line(text: str) -> str:
    return text.replace("\r", "\\r").replace("\n", "\\n")


def _error(path: PathLike, problem: str) -> PolarsegError:
    return PolarsegError(_one_line(f"{_show(path)}: {problem}"))


def _first_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = lines[0] if lines else type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def _short(value: Any) -> str:
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= 120 else text[:117] + "..."


def _short_list(names: list[str]) -> str:
    shown = ", ".join(_short(n) for n in names[:5])
    return shown + (f" and {len(names) - 5} more" if len(names) > 5 else "")


def save_pixel_classifier(path: PathLike, classifier: PixelClassifier) -> None:
    """Write a trained :class:`~napari_polarseg.engine.analysis.pixel_classifier.PixelClassifier`.

    Its :meth:`~napari_polarseg.engine.analysis.pixel_classifier.PixelClassifier.metadata`
    (classes, feature names and parameters, training summary) is the file's metadata,
    with the package and format versions of :func:`classifier_metadata`.
    """
    meta = classifier.metadata()
    base = classifier_metadata(classifier.model, meta["feature_names"], meta["feature_params"])
    save_classifier(path, classifier.model, {**base, **meta})


def load_pixel_classifier(path: PathLike) -> PixelClassifier:
    """Read a file of :func:`save_pixel_classifier` (checked as :func:`load_classifier`)."""
    model, meta = load_classifier(path)
    try:
        return PixelClassifier.from_metadata(model, meta)
    except PolarsegError as exc:
        raise _error(path, f"not a pixel classifier of this package ({exc})") from None
