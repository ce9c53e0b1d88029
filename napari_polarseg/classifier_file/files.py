"""Saving, loading and describing classifier files (and pixel classifiers).

:func:`save_classifier` writes a ``.polarseg-clf`` file atomically, after the same
static checks loading makes; :func:`load_classifier` and :func:`describe_classifier`
read one through :func:`~napari_polarseg.classifier_file.reader.read_classifier_file`
(never any code from the file); :func:`save_pixel_classifier` and
:func:`load_pixel_classifier` do the same for a
:class:`~napari_polarseg.engine.classifier.pixel_classifier.PixelClassifier`.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import sklearn
import skops
import skops.io as sio
from sklearn.ensemble import ExtraTreesClassifier, RandomForestClassifier

from .. import __version__
from ..engine.classifier.pixel_classifier import PixelClassifier
from ..engine.errors import PolarsegError
from ..io import atomic_output
from .format import (
    FORMAT_NAME,
    FORMAT_VERSION,
    KEY_TRAINING,
    MANIFEST_NAME,
    METADATA_NAME,
    MODEL_NAME,
    SUFFIX,
    PathLike,
    file_error,
    first_line,
    one_line,
    sha256_hex,
    shown_path,
    type_name,
)
from .metadata import check_metadata, classifier_metadata
from .model_checks import check_model_or_raise
from .reader import check_payload, read_classifier_file


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
        raise file_error(path, f"a classifier file name must end with {SUFFIX}")
    check_model_or_raise(path, model)
    check_metadata(path, metadata, model)
    metadata_bytes = json.dumps(metadata, allow_nan=False, ensure_ascii=False, indent=1).encode(
        "utf-8"
    )
    try:
        payload = sio.dumps(model, compression=zipfile.ZIP_DEFLATED)
    except Exception as exc:  # skops raises assorted errors for unsupported contents
        raise file_error(path, f"skops cannot save this model ({first_line(exc)})") from None
    # The same static checks as loading: never write a file that would then be refused
    # (e.g. a model whose state holds a scorer function or an unexpected type).
    model_type = check_payload(path, payload, type_name(type(model)))
    manifest = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "model_type": model_type,
        "members": {
            MODEL_NAME: {"sha256": sha256_hex(payload), "size": len(payload)},
            METADATA_NAME: {"sha256": sha256_hex(metadata_bytes), "size": len(metadata_bytes)},
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
        raise file_error(path, f"cannot write the classifier file ({first_line(exc)})") from None


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
        a file (see :mod:`napari_polarseg.classifier_file` for the checks).
    """
    model, metadata, _ = read_classifier_file(path)
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
    model, metadata, _ = read_classifier_file(path)
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
    return one_line(
        f"{shown_path(path)}: {kind}, {len(classes)} classes ({shown}), "
        f"{model.n_features_in_} features, {trained}"
    )


def save_pixel_classifier(path: PathLike, classifier: PixelClassifier) -> None:
    """Write a trained :class:`~napari_polarseg.engine.classifier.pixel_classifier.PixelClassifier`.

    Its :meth:`~napari_polarseg.engine.classifier.pixel_classifier.PixelClassifier.metadata`
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
        raise file_error(path, f"not a pixel classifier of this package ({exc})") from None
