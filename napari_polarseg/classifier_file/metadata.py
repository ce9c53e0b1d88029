"""A classifier file's metadata: what the package writes, and its checks.

:func:`classifier_metadata` makes the metadata dict; :func:`check_plain_json` and
:func:`check_metadata` refuse anything but plain JSON values and the package's keys
disagreeing with the model (step 7 of :mod:`napari_polarseg.classifier_file`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .format import (
    FORMAT_VERSION,
    KEY_CLASS_NAMES,
    KEY_CLASSES,
    KEY_FEATURE_NAMES,
    KEY_FEATURE_PARAMS,
    KEY_FORMAT_VERSION,
    KEY_PACKAGE_VERSION,
    KEY_TRAINING,
    file_error,
    is_int,
)

# Nesting of the metadata (JSON) and of the model's object tree (skops schema).
_MAX_METADATA_DEPTH = 64


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


def check_plain_json(path: Path, metadata: Any) -> None:
    """A dict of plain JSON values: exact builtin types, finite floats, str keys."""
    if type(metadata) is not dict:
        raise file_error(
            path, f"metadata must be a JSON object (dict), not {type(metadata).__name__}"
        )
    stack: list[tuple[Any, str, int]] = [(metadata, "metadata", 0)]
    while stack:
        value, where, depth = stack.pop()
        if depth > _MAX_METADATA_DEPTH:
            raise file_error(path, f"{where} is nested too deeply")
        kind = type(value)
        # exact types: a numpy scalar, a tuple or a subclass would not come back as it went
        if kind is dict:
            for key, item in value.items():
                if type(key) is not str:
                    raise file_error(path, f"{where} has a key {key!r} that is not a str")
                stack.append((item, f"{where}[{key!r}]", depth + 1))
        elif kind is list:
            stack.extend((item, f"{where}[{i}]", depth + 1) for i, item in enumerate(value))
        elif kind is float:
            if not math.isfinite(value):
                raise file_error(path, f"{where} is {value!r}, not a finite number")
        elif kind not in (str, int, bool, type(None)):
            raise file_error(
                path,
                f"{where} is a {kind.__name__}, not a plain JSON value (str, int, "
                "float, bool, None, list, dict)",
            )


def check_metadata(path: Path, metadata: Any, model: Any) -> None:
    """Plain JSON, and the package's keys (when present) agreeing with the model."""
    check_plain_json(path, metadata)
    names = metadata.get(KEY_FEATURE_NAMES)
    if names is not None and (
        type(names) is not list
        or any(type(n) is not str for n in names)
        or len(names) != model.n_features_in_
    ):
        raise file_error(
            path,
            f"metadata {KEY_FEATURE_NAMES!r} must be {model.n_features_in_} names, one per "
            "feature of the model",
        )
    classes = metadata.get(KEY_CLASSES)
    if classes is not None and classes != model.classes_.tolist():
        raise file_error(path, f"metadata {KEY_CLASSES!r} differs from the model's class values")
    names = metadata.get(KEY_CLASS_NAMES)
    n_classes = len(model.classes_)
    if names is not None and (
        type(names) is not list or any(type(n) is not str for n in names) or len(names) != n_classes
    ):
        raise file_error(
            path, f"metadata {KEY_CLASS_NAMES!r} must be {n_classes} names, one per class"
        )
    version = metadata.get(KEY_FORMAT_VERSION)
    if version is not None and (not is_int(version) or version != FORMAT_VERSION):
        raise file_error(
            path, f"metadata {KEY_FORMAT_VERSION!r} is {version!r}, not {FORMAT_VERSION}"
        )
    for key in (KEY_FEATURE_PARAMS, KEY_TRAINING):
        if metadata.get(key) is not None and type(metadata[key]) is not dict:
            raise file_error(path, f"metadata {key!r} must be a JSON object")
