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
   model (number of features, class values, one material name per class).

The package
-----------
:mod:`~napari_polarseg.classifier_file.format` (names, allow-lists, metadata keys),
:mod:`~napari_polarseg.classifier_file.reader` (steps 1-7),
:mod:`~napari_polarseg.classifier_file.model_checks` (:func:`check_model`),
:mod:`~napari_polarseg.classifier_file.metadata` (:func:`classifier_metadata` and its
checks), :mod:`~napari_polarseg.classifier_file.files` (save, load, describe). The names
in ``__all__`` are importable from here.

Examples
--------
>>> meta = classifier_metadata(model, feature_names=names, n_pixels=1234)  # doctest: +SKIP
>>> save_classifier("leaf.polarseg-clf", model, meta)                     # doctest: +SKIP
>>> model, meta = load_classifier("leaf.polarseg-clf")                     # doctest: +SKIP
>>> describe_classifier("leaf.polarseg-clf")                               # doctest: +SKIP
'leaf.polarseg-clf: RandomForestClassifier (100 trees), 3 classes (1, 2, 3), ...'
"""

from .files import (
    describe_classifier,
    load_classifier,
    load_pixel_classifier,
    save_classifier,
    save_pixel_classifier,
)
from .format import (
    ALLOWED_LOADERS,
    ALLOWED_MODEL_TYPES,
    ALLOWED_TYPES,
    FORMAT_NAME,
    FORMAT_VERSION,
    KEY_CLASS_NAMES,
    KEY_CLASSES,
    KEY_FEATURE_NAMES,
    KEY_FEATURE_PARAMS,
    KEY_FORMAT_VERSION,
    KEY_PACKAGE_VERSION,
    KEY_TRAINING,
    MANIFEST_NAME,
    MEMBERS,
    METADATA_NAME,
    MODEL_NAME,
    SKOPS_TRUSTED,
    SUFFIX,
    PathLike,
)
from .metadata import classifier_metadata
from .model_checks import FOREST_TREES, check_model

__all__ = [
    "ALLOWED_LOADERS",
    "ALLOWED_MODEL_TYPES",
    "ALLOWED_TYPES",
    "FOREST_TREES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "KEY_CLASS_NAMES",
    "KEY_CLASSES",
    "KEY_FEATURE_NAMES",
    "KEY_FEATURE_PARAMS",
    "KEY_FORMAT_VERSION",
    "KEY_PACKAGE_VERSION",
    "KEY_TRAINING",
    "MANIFEST_NAME",
    "MEMBERS",
    "METADATA_NAME",
    "MODEL_NAME",
    "SKOPS_TRUSTED",
    "SUFFIX",
    "PathLike",
    "check_model",
    "classifier_metadata",
    "describe_classifier",
    "load_classifier",
    "load_pixel_classifier",
    "save_classifier",
    "save_pixel_classifier",
]
