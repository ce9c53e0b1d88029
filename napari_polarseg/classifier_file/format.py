"""The classifier file format: member names, allow-lists, metadata keys, one-line errors.

What a ``.polarseg-clf`` file may hold (:data:`MEMBERS`, :data:`ALLOWED_MODEL_TYPES`,
:data:`ALLOWED_TYPES`, :data:`ALLOWED_LOADERS`, :data:`SKOPS_TRUSTED`), the metadata keys
the package gives a meaning to (``KEY_*``), and the small helpers every part of
:mod:`napari_polarseg.classifier_file` shares: :func:`file_error` (a
:class:`~napari_polarseg.engine.errors.PolarsegError` of one line naming the file),
:func:`first_line`, :func:`is_int`, :func:`type_name`, :func:`sha256_hex`.
"""

from __future__ import annotations

import hashlib
import os
from types import MappingProxyType
from typing import Any

import numpy as np
from sklearn.ensemble import (
    ExtraTreesClassifier,
    HistGradientBoostingClassifier,
    RandomForestClassifier,
)

from ..engine.errors import PolarsegError

PathLike = str | os.PathLike


#: File name suffix of classifier files.
SUFFIX = ".polarseg-clf"


#: The manifest's ``format`` value.
FORMAT_NAME = "napari-polarseg classifier"


#: The format version this package writes and the only one it reads.
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


# The metadata keys the package gives a meaning to (all optional; checked when present).
#: List of str, one per feature column the model takes.
KEY_FEATURE_NAMES = "feature_names"


#: JSON object: the parameters the features were computed with.
KEY_FEATURE_PARAMS = "feature_params"


#: List of the class values (``model.classes_.tolist()``).
KEY_CLASSES = "classes"


#: List of str, the material name of each class (in the order of :data:`KEY_CLASSES`).
KEY_CLASS_NAMES = "class_names"


#: str: napari-polarseg version that trained the model.
KEY_PACKAGE_VERSION = "package_version"


#: int: :data:`FORMAT_VERSION` of the file the metadata was made for.
KEY_FORMAT_VERSION = "format_version"


#: JSON object: training summary; ``"n_pixels"`` (int) is the number of training pixels.
KEY_TRAINING = "training"


def type_name(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def is_int(value: Any) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def shown_path(path: PathLike) -> str:
    return one_line(os.fspath(path))


def one_line(text: str) -> str:
    return text.replace("\r", "\\r").replace("\n", "\\n")


def file_error(path: PathLike, problem: str) -> PolarsegError:
    return PolarsegError(one_line(f"{shown_path(path)}: {problem}"))


def first_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = lines[0] if lines else type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def short_text(value: Any) -> str:
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= 120 else text[:117] + "..."
