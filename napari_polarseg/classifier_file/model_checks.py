"""Checks of a classifier model: an allowed type whose trees are well formed.

scikit-learn walks tree node arrays without bounds checks, so a model read from a file
is only used after :func:`check_model` (step 6 of :mod:`napari_polarseg.classifier_file`).
"""

from __future__ import annotations

from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
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

from .format import ALLOWED_MODEL_TYPES, file_error, first_line, is_int, type_name


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
    name = type_name(type(model))
    if name not in ALLOWED_MODEL_TYPES or type(model) is not ALLOWED_MODEL_TYPES[name]:
        raise ValueError(
            f"the model is a {name}; only RandomForestClassifier, ExtraTreesClassifier and "
            "HistGradientBoostingClassifier (not subclasses or pipelines) are allowed"
        )
    n_features = getattr(model, "n_features_in_", None)
    if not is_int(n_features) or n_features < 1:
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


def check_model_or_raise(path: Path, model: Any) -> None:
    try:
        check_model(model)
    except ValueError as exc:
        raise file_error(path, first_line(exc)) from None
    except Exception as exc:  # a crafted attribute of the wrong kind (TypeError, ...)
        raise file_error(path, f"the model is malformed ({first_line(exc)})") from None


#: The tree type of each forest type.
FOREST_TREES = MappingProxyType(
    {RandomForestClassifier: DecisionTreeClassifier, ExtraTreesClassifier: ExtraTreeClassifier}
)


def _check_forest(
    model: RandomForestClassifier | ExtraTreesClassifier, n_features: int, n_classes: int
) -> None:
    if model.n_outputs_ != 1 or model.n_classes_ != n_classes:
        raise ValueError("the forest is not a single-output classifier of its classes")
    if model.n_jobs is not None and not is_int(model.n_jobs):
        raise ValueError(f"the forest's n_jobs is {model.n_jobs!r}")
    trees = model.estimators_
    if not isinstance(trees, list) or not trees:
        raise ValueError("the forest has no trees")
    for i, est in enumerate(trees):
        if type(est) is not FOREST_TREES[type(model)]:
            raise ValueError(f"tree {i} of the forest is a {type_name(type(est))}")
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
                raise ValueError(f"tree {i}/{k} is a {type_name(type(predictor))}")
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
