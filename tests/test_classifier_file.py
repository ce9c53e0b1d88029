"""Classifier files (napari_polarseg.classifier_file): data in, data out, never code.

Besides round trips, every test of a bad file checks that loading raises a one-line
PolarsegError naming the file. The malicious payloads are shown to be real (they do
create their marker when loaded the careless way) before our loader is shown to refuse
them without creating it.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import skops.io as sio
from sklearn.ensemble import (
    ExtraTreesClassifier,
    GradientBoostingClassifier,
    HistGradientBoostingClassifier,
    RandomForestClassifier,
)
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import FunctionTransformer
from sklearn.svm import SVC
from sklearn.tree import DecisionTreeClassifier
from threadpoolctl import threadpool_limits

from napari_polarseg.classifier_file import (
    FORMAT_NAME,
    FORMAT_VERSION,
    METADATA_NAME,
    MODEL_NAME,
    SUFFIX,
    check_model,
    classifier_metadata,
    describe_classifier,
    load_classifier,
    save_classifier,
)
from napari_polarseg.engine.errors import PolarsegError

N_FEATURES = 6
FEATURES = [f"f{i}" for i in range(N_FEATURES)]


# -- helpers ----------------------------------------------------------------------------


@pytest.fixture(autouse=True)
def _one_openmp_thread() -> Any:
    """Tiny models: OpenMP threads only contend (HistGradientBoosting on a busy host)."""
    with threadpool_limits(limits=1, user_api="openmp"):
        yield


def _data(seed: int, n: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, N_FEATURES))


def _labels(kind: str, n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "binary":
        return rng.integers(0, 2, n)
    values = {
        "int32": np.array([1, 2, 3], dtype=np.int32),
        "int64": np.array([0, 5, 9], dtype=np.int64),
        "str": np.array(["leaf", "metal", "plastic"]),
    }[kind]
    return values[rng.integers(0, 3, n)]


def _fit(model: Any, kind: str = "int64", n: int = 400) -> Any:
    x = _data(0, n)
    y = _labels(kind, n)
    # make the classes learnable so the trees have real splits
    x[:, 0] += np.unique(y, return_inverse=True)[1]
    return model.fit(x, y)


def _rf(**kwargs: Any) -> RandomForestClassifier:
    params = {"n_estimators": 12, "n_jobs": 2, "class_weight": "balanced", "random_state": 0}
    return _fit(RandomForestClassifier(**params), **kwargs)


def _hgb(**kwargs: Any) -> HistGradientBoostingClassifier:
    return _fit(HistGradientBoostingClassifier(max_iter=10, random_state=0), **kwargs)


def _meta(model: Any) -> dict[str, Any]:
    return classifier_metadata(
        model,
        feature_names=FEATURES,
        feature_params={"block": 8, "orders": [0, 2, 4], "weights": {"a": 0.5}},
        n_pixels=400,
        scribbled_labels=[1, 2, 3],
        note="ünïcode ok",
    )


def _refusal(path: Path) -> str:
    """Loading ``path`` is refused with one line that names the file; the line."""
    with pytest.raises(PolarsegError) as info:
        load_classifier(path)
    message = str(info.value)
    assert "\n" not in message and "\r" not in message, message
    assert str(path) in message, message
    return message


def _saved(tmp_path: Path, model: Any = None, name: str = "model") -> Path:
    model = _rf() if model is None else model
    path = tmp_path / f"{name}{SUFFIX}"
    save_classifier(path, model, _meta(model))
    return path


def _members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as zf:
        return {name: zf.read(name) for name in zf.namelist()}


def _write_zip(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
        for name, content in members.items():
            zf.writestr(name, content)
    return path


def _container(
    path: Path,
    payload: bytes,
    metadata: bytes = b"{}",
    model_type: str | None = None,
    **manifest_changes: Any,
) -> Path:
    """A container with *correct* digests, as anyone editing a file could make."""
    if model_type is None:
        model_type = _schema(payload)["__module__"] + "." + _schema(payload)["__class__"]
    manifest = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "model_type": model_type,
        "members": {
            MODEL_NAME: {"sha256": hashlib.sha256(payload).hexdigest(), "size": len(payload)},
            METADATA_NAME: {
                "sha256": hashlib.sha256(metadata).hexdigest(),
                "size": len(metadata),
            },
        },
    }
    manifest.update(manifest_changes)
    return _write_zip(
        path,
        {
            "manifest.json": json.dumps(manifest).encode(),
            MODEL_NAME: payload,
            METADATA_NAME: metadata,
        },
    )


def _schema(payload: bytes) -> dict[str, Any]:
    with zipfile.ZipFile(io.BytesIO(payload)) as zf:
        return json.loads(zf.read("schema.json"))


def _edit_payload(
    payload: bytes,
    schema_edit: Callable[[dict[str, Any]], None] | None = None,
    array_edit: Callable[[str, np.ndarray], np.ndarray | None] | None = None,
) -> bytes:
    """A skops payload with its schema and/or arrays edited (a crafted file)."""
    src = zipfile.ZipFile(io.BytesIO(payload))
    schema = json.loads(src.read("schema.json"))
    if schema_edit is not None:
        schema_edit(schema)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as dst:
        for name in src.namelist():
            content = src.read(name)
            if name == "schema.json":
                content = json.dumps(schema).encode()
            elif array_edit is not None:
                array = np.load(io.BytesIO(content), allow_pickle=False)
                edited = array_edit(name, array)
                if edited is not None:
                    buffer = io.BytesIO()
                    np.save(buffer, edited, allow_pickle=False)
                    content = buffer.getvalue()
            dst.writestr(name, content)
    return out.getvalue()


def _json_node(value: Any) -> dict[str, Any]:
    return {
        "__class__": "str",
        "__module__": "builtins",
        "__loader__": "JsonNode",
        "content": json.dumps(value),
        "is_json": True,
    }


def _mkdir_node(marker: Path) -> dict[str, Any]:
    """A skops node that calls ``os.mkdir(marker)`` when the object is constructed."""
    return {
        "__class__": "mkdir",
        "__module__": "os",
        "__loader__": "ConstructorFromReduceNode",
        "content": {
            "__class__": "tuple",
            "__module__": "builtins",
            "__loader__": "TupleNode",
            "content": [_json_node(str(marker))],
        },
    }


def _malicious_payload(marker: Path) -> bytes:
    """A genuine random-forest payload whose ``criterion`` would be ``os.mkdir(marker)``."""

    def plant(schema: dict[str, Any]) -> None:
        schema["content"]["content"]["criterion"] = _mkdir_node(marker)

    return _edit_payload(sio.dumps(_rf()), schema_edit=plant)


class _MkdirOnUnpickle:
    """Unpickling this calls ``os.mkdir(marker)``: the classic pickle payload."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self) -> tuple[Any, ...]:
        return (os.mkdir, (self.marker,))


# -- round trips ------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["int32", "int64", "str", "binary"])
def test_random_forest_round_trip(tmp_path: Path, kind: str) -> None:
    model = _rf(kind=kind)
    meta = _meta(model)
    path = tmp_path / f"rf{SUFFIX}"
    save_classifier(path, model, meta)
    loaded, loaded_meta = load_classifier(path)
    assert type(loaded) is RandomForestClassifier
    assert loaded.n_jobs == 2 and loaded.class_weight == "balanced"
    assert loaded_meta == meta
    x_other = _data(7, 300)
    assert np.array_equal(loaded.predict_proba(x_other), model.predict_proba(x_other))
    assert np.array_equal(loaded.predict(x_other), model.predict(x_other))
    assert loaded.classes_.dtype == model.classes_.dtype
    assert np.array_equal(loaded.classes_, model.classes_)


@pytest.mark.parametrize("kind", ["int32", "int64", "str", "binary"])
@pytest.mark.parametrize(
    "params",
    [
        {"class_weight": "balanced"},
        {"early_stopping": True, "validation_fraction": 0.2, "max_features": 0.5},
        {"random_state": np.random.RandomState(3), "l2_regularization": 0.1},
    ],
)
def test_hist_gradient_boosting_round_trip(tmp_path: Path, kind: str, params: dict) -> None:
    model = _fit(HistGradientBoostingClassifier(max_iter=12, **params), kind=kind)
    meta = _meta(model)
    path = tmp_path / f"hgb{SUFFIX}"
    save_classifier(path, model, meta)
    loaded, loaded_meta = load_classifier(path)
    assert type(loaded) is HistGradientBoostingClassifier
    assert loaded_meta == meta
    x_other = _data(8, 300)
    x_other[::17, 2] = np.nan  # missing values take the learnt side in both
    assert np.array_equal(loaded.predict_proba(x_other), model.predict_proba(x_other))
    assert np.array_equal(loaded.predict(x_other), model.predict(x_other))


@pytest.mark.parametrize(
    "model",
    [
        RandomForestClassifier(
            n_estimators=3, class_weight={np.int32(1): 2.0, np.int32(2): 1.0, np.int32(3): 1.5}
        ),
        RandomForestClassifier(
            n_estimators=3,
            class_weight="balanced_subsample",
            max_samples=0.5,
            oob_score=True,
            random_state=np.random.RandomState(0),
            criterion="entropy",
            max_features=None,
            n_jobs=-1,
        ),
        RandomForestClassifier(n_estimators=3, max_leaf_nodes=8, bootstrap=False),
        HistGradientBoostingClassifier(max_iter=5, interaction_cst=[[0, 1], [2, 3, 4, 5]]),
        ExtraTreesClassifier(n_estimators=5, n_jobs=-1, random_state=0),
        ExtraTreesClassifier(n_estimators=3, class_weight="balanced", bootstrap=True),
    ],
    ids=[
        "class-weight-dict",
        "oob-randomstate",
        "max-leaf-nodes",
        "interaction-cst",
        "extra-trees",
        "extra-trees-bootstrap",
    ],
)
@pytest.mark.filterwarnings("ignore:Some inputs do not have OOB scores")
def test_more_settings_round_trip(tmp_path: Path, model: Any) -> None:
    model = _fit(model, kind="int32", n=200)
    path = tmp_path / f"v{SUFFIX}"
    save_classifier(path, model, {})
    x_other = _data(5, 100)
    assert np.array_equal(
        load_classifier(path)[0].predict_proba(x_other), model.predict_proba(x_other)
    )


def test_save_refuses_categorical_boosting(tmp_path: Path) -> None:
    x = _data(0, 200)
    x[:, 5] = np.round(np.abs(x[:, 5]) * 3)
    model = HistGradientBoostingClassifier(max_iter=3, categorical_features=[5])
    model.fit(x, _labels("int32", 200))
    with pytest.raises(PolarsegError, match="categorical"):
        save_classifier(tmp_path / f"c{SUFFIX}", model, {})


def test_metadata_round_trips_as_given(tmp_path: Path) -> None:
    model = _rf()
    meta = {"anything": [1, 2.5, "x", None, True, {"nested": []}], "empty": {}}
    path = tmp_path / f"m{SUFFIX}"
    save_classifier(path, model, meta)
    assert load_classifier(path)[1] == meta


def test_describe_classifier(tmp_path: Path) -> None:
    rf = _rf(kind="str")
    line = describe_classifier(_saved(tmp_path, rf, "rf"))
    assert "\n" not in line
    assert f"rf{SUFFIX}" in line
    assert "RandomForestClassifier (12 trees)" in line
    assert "3 classes (leaf, metal, plastic)" in line
    assert f"{N_FEATURES} features" in line and "trained on 400 pixels" in line
    hgb_path = tmp_path / f"hgb{SUFFIX}"
    save_classifier(hgb_path, _hgb(), {})
    line = describe_classifier(hgb_path)
    assert "HistGradientBoostingClassifier (10 iterations)" in line
    assert "unknown number of pixels" in line


def test_save_is_atomic_and_overwrites(tmp_path: Path) -> None:
    path = _saved(tmp_path)
    first = path.read_bytes()
    save_classifier(path, _hgb(), {})  # replaces the file
    assert path.read_bytes() != first
    assert type(load_classifier(path)[0]) is HistGradientBoostingClassifier
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no temporary left
    with pytest.raises(PolarsegError):
        save_classifier(path, _rf(), {"bad": float("nan")})
    assert type(load_classifier(path)[0]) is HistGradientBoostingClassifier  # untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


# -- saving refuses what could not be loaded ----------------------------------------------


@pytest.mark.parametrize(
    ("model", "meta", "problem"),
    [
        (lambda: SVC().fit(_data(0, 50), _labels("int64", 50)), {}, "only RandomForest"),
        (
            lambda: GradientBoostingClassifier(n_estimators=2).fit(
                _data(0, 50), _labels("int64", 50)
            ),
            {},
            "only RandomForest",
        ),
        (lambda: RandomForestClassifier(), {}, "not fitted"),
        (_rf, {"t": (1, 2)}, "tuple"),
        (_rf, {"x": np.float64(1.0)}, "float64"),
        (_rf, {"x": float("inf")}, "finite"),
        (_rf, {1: "x"}, "not a str"),
        (_rf, {"x": {"y": {1, 2}}}, "set"),
        (_rf, {"feature_names": ["a"]}, "feature_names"),
        (_rf, {"classes": [7, 8, 9]}, "classes"),
        (_rf, {"format_version": 99}, "format_version"),
        (_rf, ["not", "a", "dict"], "JSON object"),
    ],
)
def test_save_refuses(tmp_path: Path, model: Callable[[], Any], meta: Any, problem: str) -> None:
    path = tmp_path / f"x{SUFFIX}"
    with pytest.raises(PolarsegError, match=problem) as info:
        save_classifier(path, model(), meta)
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    assert not path.exists()


def test_save_refuses_wrong_suffix(tmp_path: Path) -> None:
    with pytest.raises(PolarsegError, match=SUFFIX):
        save_classifier(tmp_path / "model.pkl", _rf(), {})
    assert list(tmp_path.iterdir()) == []


# -- files that would run code ------------------------------------------------------------


def test_malicious_skops_payload_is_real(tmp_path: Path) -> None:
    """Positive control: trusting what get_untrusted_types reports runs the payload."""
    marker = tmp_path / "pwned-by-skops"
    payload = _malicious_payload(marker)
    assert "os.mkdir" in sio.get_untrusted_types(data=payload)
    sio.loads(payload, trusted=sio.get_untrusted_types(data=payload))
    assert marker.is_dir()


def test_malicious_skops_payload_is_refused(tmp_path: Path) -> None:
    marker = tmp_path / "pwned-by-skops"
    payload = _malicious_payload(marker)
    # correct digests and manifest: only the type and loader allow-lists stand in the way
    message = _refusal(_container(tmp_path / f"evil{SUFFIX}", payload))
    assert "ConstructorFromReduceNode" in message
    assert not marker.exists()

    # the same call behind an ObjectNode, i.e. only the type allow-list can stop it
    def as_object(schema: dict[str, Any]) -> None:
        node = _mkdir_node(marker)
        node["__loader__"] = "ObjectNode"
        schema["content"]["content"]["criterion"] = node

    payload = _edit_payload(sio.dumps(_rf()), schema_edit=as_object)
    assert "os.mkdir" in _refusal(_container(tmp_path / f"evil2{SUFFIX}", payload))
    assert not marker.exists()


def test_malicious_pickle_is_refused(tmp_path: Path) -> None:
    marker = tmp_path / "pwned-by-pickle"
    evil = pickle.dumps(_MkdirOnUnpickle(marker))
    pickle.loads(evil)  # positive control: unpickling does run it
    assert marker.is_dir()
    marker.rmdir()
    # as a whole file, and as the model payload of a container with correct digests
    (tmp_path / f"evil{SUFFIX}").write_bytes(evil)
    assert "not a zip" in _refusal(tmp_path / f"evil{SUFFIX}")
    assert "skops" in _refusal(
        _container(
            tmp_path / f"evil2{SUFFIX}",
            evil,
            model_type=("sklearn.ensemble._forest.RandomForestClassifier"),
        )
    )
    assert not marker.exists()


def test_crafted_tree_indices_are_refused(tmp_path: Path) -> None:
    """Allowed types with out-of-range node indices: refused before any prediction."""
    rf_payload = sio.dumps(_rf())
    tree_arrays = set()

    def find_nodes(schema: dict[str, Any]) -> None:
        first_tree = schema["content"]["content"]["estimators_"]["content"][0]
        tree_arrays.add(
            first_tree["content"]["content"]["tree_"]["content"]["content"]["nodes"]["file"]
        )

    _edit_payload(rf_payload, schema_edit=find_nodes)

    def bad_child(name: str, array: np.ndarray) -> np.ndarray | None:
        if name not in tree_arrays:
            return None
        array = array.copy()
        array["left_child"][0] = 10**9
        return array

    crafted = _edit_payload(rf_payload, array_edit=bad_child)
    assert "child index outside the tree" in _refusal(_container(tmp_path / f"rf{SUFFIX}", crafted))

    def bad_feature(name: str, array: np.ndarray) -> np.ndarray | None:
        if array.dtype.names is None or "feature_idx" not in array.dtype.names:
            return None
        array = array.copy()
        array["feature_idx"][array["is_leaf"] == 0] = 1000
        return array

    crafted = _edit_payload(sio.dumps(_hgb()), array_edit=bad_feature)
    message = _refusal(_container(tmp_path / f"hgb{SUFFIX}", crafted))
    assert "feature the model does not have" in message

    def fewer_nodes(schema: dict[str, Any]) -> None:
        first_tree = schema["content"]["content"]["estimators_"]["content"][0]
        state = first_tree["content"]["content"]["tree_"]["content"]["content"]
        state["node_count"] = _json_node(1)  # the root's children now lie past the end

    crafted = _edit_payload(rf_payload, schema_edit=fewer_nodes)
    assert "child index outside the tree" in _refusal(
        _container(tmp_path / f"rf2{SUFFIX}", crafted)
    )


def test_check_model_on_valid_models() -> None:
    for model in (_rf(), _rf(kind="str"), _hgb(), _hgb(kind="binary")):
        check_model(model)
    with pytest.raises(ValueError, match="only RandomForest"):
        check_model(DecisionTreeClassifier().fit(_data(0, 20), _labels("int64", 20)))


# -- damaged, foreign and edited files ----------------------------------------------------


def _data_ranges(path: Path) -> dict[str, tuple[int, int]]:
    """Byte range of each member's stored data in the file."""
    ranges = {}
    raw = path.read_bytes()
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            start = info.header_offset
            name_len = int.from_bytes(raw[start + 26 : start + 28], "little")
            extra_len = int.from_bytes(raw[start + 28 : start + 30], "little")
            begin = start + 30 + name_len + extra_len
            ranges[info.filename] = (begin, begin + info.compress_size)
    return ranges


@pytest.mark.parametrize("member", ["manifest.json", MODEL_NAME, METADATA_NAME])
@pytest.mark.parametrize("where", [0.0, 0.3, 0.7, 0.999])
def test_one_flipped_byte_is_refused(tmp_path: Path, member: str, where: float) -> None:
    path = _saved(tmp_path)
    begin, end = _data_ranges(path)[member]
    raw = bytearray(path.read_bytes())
    raw[begin + int((end - begin - 1) * where)] ^= 0x01
    path.write_bytes(bytes(raw))
    _refusal(path)


def test_flipped_bytes_anywhere_are_refused_or_harmless(tmp_path: Path) -> None:
    """Bytes outside the members' data (zip bookkeeping) either break the file or not."""
    path = _saved(tmp_path)
    good = path.read_bytes()
    x_other = _data(9, 50)
    expected = load_classifier(path)[0].predict_proba(x_other)
    for offset in range(0, len(good), max(1, len(good) // 80)):
        raw = bytearray(good)
        raw[offset] ^= 0xFF
        path.write_bytes(bytes(raw))
        try:
            model, _ = load_classifier(path)
        except PolarsegError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc)
        else:  # e.g. a timestamp: the content, checked by CRC and SHA-256, is the same
            assert np.array_equal(model.predict_proba(x_other), expected)


def test_edited_content_with_valid_zip_is_refused(tmp_path: Path) -> None:
    """Edits that keep the zip consistent (CRCs recomputed) are caught by the digests."""
    path = _saved(tmp_path)
    members = _members(path)
    meta = json.loads(members[METADATA_NAME])
    meta["training"]["n_pixels"] = 1
    edited = dict(members, **{METADATA_NAME: json.dumps(meta).encode()})
    message = _refusal(_write_zip(tmp_path / f"meta{SUFFIX}", edited))
    assert "SHA-256" in message

    def more_trees(schema: dict[str, Any]) -> None:
        schema["content"]["content"]["n_estimators"] = _json_node(1000)

    edited = dict(members, **{MODEL_NAME: _edit_payload(members[MODEL_NAME], more_trees)})
    assert "SHA-256" in _refusal(_write_zip(tmp_path / f"model{SUFFIX}", edited))


@pytest.mark.parametrize("keep", [1, 4, 22, 100, 0.5, -22, -1])
def test_truncated_file_is_refused(tmp_path: Path, keep: float) -> None:
    path = _saved(tmp_path)
    raw = path.read_bytes()
    n = int(len(raw) * keep) if isinstance(keep, float) else keep % len(raw)
    path.write_bytes(raw[:n])
    _refusal(path)


def test_empty_missing_and_directory_are_refused(tmp_path: Path) -> None:
    empty = tmp_path / f"empty{SUFFIX}"
    empty.write_bytes(b"")
    assert "empty" in _refusal(empty)
    assert "cannot read" in _refusal(tmp_path / f"missing{SUFFIX}")
    folder = tmp_path / f"folder{SUFFIX}"
    folder.mkdir()
    assert "not a file" in _refusal(folder)


def test_foreign_files_are_refused(tmp_path: Path) -> None:
    model = _rf()
    plain_zip = _write_zip(tmp_path / f"plain{SUFFIX}", {"readme.txt": b"hello"})
    assert "no manifest.json" in _refusal(plain_zip)
    bare_skops = tmp_path / f"bare{SUFFIX}"
    sio.dump(model, bare_skops)
    assert "not a napari-polarseg classifier file" in _refusal(bare_skops)
    pickled = tmp_path / f"pickled{SUFFIX}"
    pickled.write_bytes(pickle.dumps(model))
    assert "not a zip" in _refusal(pickled)
    as_json = tmp_path / f"json{SUFFIX}"
    as_json.write_text(json.dumps({"format": FORMAT_NAME, "format_version": 1}))
    assert "not a zip" in _refusal(as_json)
    npz = tmp_path / f"arrays{SUFFIX}"
    with open(npz, "wb") as handle:
        np.savez(handle, a=np.zeros(3))
    assert "no manifest.json" in _refusal(npz)
    other_manifest = _write_zip(
        tmp_path / f"other{SUFFIX}",
        {"manifest.json": b'{"format": "something else"}', MODEL_NAME: b"", METADATA_NAME: b""},
    )
    assert "another format" in _refusal(other_manifest)


def test_wrong_members_are_refused(tmp_path: Path) -> None:
    members = _members(_saved(tmp_path))
    extra = _write_zip(tmp_path / f"extra{SUFFIX}", dict(members, **{"run.py": b"print(1)"}))
    assert "members" in _refusal(extra)
    missing = dict(members)
    del missing[METADATA_NAME]
    assert "members" in _refusal(_write_zip(tmp_path / f"missing{SUFFIX}", missing))


def test_compressed_members_are_refused(tmp_path: Path) -> None:
    members = _members(_saved(tmp_path))
    path = tmp_path / f"deflated{SUFFIX}"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, content in members.items():
            zf.writestr(name, content)
    assert "compressed" in _refusal(path)


@pytest.mark.parametrize("version", [0, 2, "1", 1.5, True, None])
def test_wrong_format_version_is_refused(tmp_path: Path, version: Any) -> None:
    payload = _members(_saved(tmp_path))[MODEL_NAME]
    path = _container(tmp_path / f"v{SUFFIX}", payload, format_version=version)
    assert "format version" in _refusal(path)


def test_bad_digests_in_manifest_are_refused(tmp_path: Path) -> None:
    payload = _members(_saved(tmp_path))[MODEL_NAME]
    no_digest = {MODEL_NAME: {"size": len(payload)}, METADATA_NAME: {"sha256": "0" * 64, "size": 2}}
    path = _container(tmp_path / f"d{SUFFIX}", payload, members=no_digest)
    assert "SHA-256" in _refusal(path)


@pytest.mark.parametrize(
    "make",
    [
        lambda x, y: SVC().fit(x, y),
        lambda x, y: make_pipeline(
            FunctionTransformer(np.log1p), RandomForestClassifier(n_estimators=2)
        ).fit(np.abs(x), y),
        lambda x, y: GradientBoostingClassifier(n_estimators=2).fit(x, y),
        lambda x, y: DecisionTreeClassifier().fit(x, y),
    ],
    ids=["SVC", "Pipeline-FunctionTransformer", "GradientBoosting", "DecisionTree"],
)
def test_disallowed_estimators_are_refused(tmp_path: Path, make: Callable) -> None:
    x, y = _data(0, 80), _labels("int64", 80)
    payload = sio.dumps(make(x, y))
    # the manifest telling the truth, and lying that it holds a random forest
    assert "allow-list" in _refusal(_container(tmp_path / f"a{SUFFIX}", payload))
    lying = _container(
        tmp_path / f"b{SUFFIX}",
        payload,
        model_type="sklearn.ensemble._forest.RandomForestClassifier",
    )
    assert "allow-list" in _refusal(lying)


def test_disallowed_type_inside_an_allowed_model_is_refused(tmp_path: Path) -> None:
    model = _rf()
    model.estimators_[0] = SVC().fit(_data(0, 40), _labels("int64", 40))
    message = _refusal(_container(tmp_path / f"x{SUFFIX}", sio.dumps(model)))
    assert "sklearn.svm._classes.SVC" in message


@pytest.mark.parametrize(
    "metadata",
    [
        b"[1, 2]",
        b'"text"',
        b'{"x": NaN}',
        b'{"x": Infinity}',
        b'{"a": 1, "a": 2}',
        b"\xff\xfe{}",
        b"{",
        b'{"feature_names": ["a"]}',
        b'{"classes": ["no"]}',
    ],
)
def test_bad_metadata_is_refused(tmp_path: Path, metadata: bytes) -> None:
    payload = _members(_saved(tmp_path))[MODEL_NAME]
    message = _refusal(_container(tmp_path / f"m{SUFFIX}", payload, metadata=metadata))
    assert "metadata" in message


def test_error_names_a_path_with_a_newline_on_one_line(tmp_path: Path) -> None:
    path = tmp_path / f"two\nlines{SUFFIX}"
    path.write_bytes(b"junk")
    with pytest.raises(PolarsegError) as info:
        load_classifier(path)
    assert "\n" not in str(info.value) and "two\\nlines" in str(info.value)
