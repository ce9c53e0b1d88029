"""Reading a classifier file safely: every check before anything in it is used.

:func:`read_classifier_file` does steps 1 to 7 of :mod:`napari_polarseg.classifier_file`
(zip container, manifest, digests, a static audit of the skops payload
(:func:`check_payload`), ``skops.io.loads`` with a fixed trusted list, the model's trees,
the metadata). Nothing here unpickles or imports anything named by the file.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from pathlib import Path
from typing import Any

import skops.io as sio

from .. import __version__
from ..engine.errors import PolarsegError
from ..engine.limits import format_bytes, memory_limit
from .format import (
    ALLOWED_LOADERS,
    ALLOWED_MODEL_TYPES,
    ALLOWED_TYPES,
    FORMAT_NAME,
    FORMAT_VERSION,
    MANIFEST_NAME,
    MEMBERS,
    METADATA_NAME,
    MODEL_NAME,
    SKOPS_TRUSTED,
    PathLike,
    file_error,
    first_line,
    is_int,
    sha256_hex,
    short_text,
    type_name,
)
from .metadata import check_metadata, check_plain_json
from .model_checks import check_model_or_raise

# skops protocol 2 (skops 0.10+) is the first whose audits are as strict as today's; the
# protocol number comes from the file and selects which (older) node code audits it, so
# an older number would let a file opt into laxer audits. skops refuses newer numbers.
_MIN_SKOPS_PROTOCOL = 2


# Bounds on what a file may make us read, before reading it.
_MAX_MANIFEST_BYTES = 1 << 20


_MAX_METADATA_BYTES = 16 << 20


_MAX_SCHEMA_DEPTH = 200


_SHA256_RE = re.compile(r"[0-9a-f]{64}")


_NPY_MEMBER_RE = re.compile(r"[0-9A-Za-z_.-]{1,200}\.npy")


def read_classifier_file(path: PathLike) -> tuple[Any, dict[str, Any], dict[str, Any]]:
    """Model, metadata and manifest of a classifier file, after every check."""
    path = Path(path)
    data = _read_bytes(path)
    if not data.startswith(b"PK\x03\x04"):
        raise file_error(path, "not a napari-polarseg classifier file (not a zip container)")
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except Exception as exc:  # BadZipFile, struct.error, ...: a broken directory
        raise file_error(path, f"damaged or truncated file ({first_line(exc)})") from None
    with zf:
        names = [info.filename for info in infos]
        if MANIFEST_NAME not in names:
            raise file_error(path, f"not a napari-polarseg classifier file (no {MANIFEST_NAME})")
        if len(set(names)) != len(names) or set(names) != set(MEMBERS):
            raise file_error(
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
        if len(content) != expected["size"] or sha256_hex(content) != expected["sha256"]:
            raise file_error(
                path,
                f"{name} does not match its SHA-256 digest in the manifest (the file was "
                "edited or damaged)",
            )
    metadata = _parse_json(path, members[METADATA_NAME], METADATA_NAME)
    check_plain_json(path, metadata)
    payload = members[MODEL_NAME]
    check_payload(path, payload, manifest["model_type"])
    try:
        model = sio.loads(payload, trusted=list(SKOPS_TRUSTED))
    except Exception as exc:  # any failure of skops on a payload is a bad file
        raise file_error(path, f"cannot load the model ({first_line(exc)})") from None
    check_model_or_raise(path, model)
    if type_name(type(model)) != manifest["model_type"]:
        raise file_error(path, "the model's type differs from the manifest's model_type")
    check_metadata(path, metadata, model)
    return model, metadata, manifest


def _read_bytes(path: Path) -> bytes:
    """The whole file, size-checked first (one read: no change between checks and use)."""
    try:
        size = path.stat().st_size
        if not path.is_file():
            raise file_error(path, "not a file")
        if size == 0:
            raise file_error(path, "empty file (not a napari-polarseg classifier file)")
        limit = memory_limit()
        if size > limit:
            raise file_error(
                path,
                f"file of {format_bytes(size)} is larger than the memory limit of "
                f"{format_bytes(limit)}",
            )
        with open(path, "rb") as handle:
            return handle.read(limit + 1)
    except OSError as exc:
        reason = exc.strerror or first_line(exc)
        raise file_error(path, f"cannot read the classifier file ({reason})") from None


def _check_member_info(path: Path, info: zipfile.ZipInfo, limit: int) -> None:
    if info.flag_bits & 0x1:
        raise file_error(path, f"{info.filename} is encrypted")
    if info.compress_type != zipfile.ZIP_STORED:
        raise file_error(path, f"{info.filename} is compressed (classifier files store members)")
    # file_size is what zipfile will read for the member (no more), so checking it first
    # bounds the memory a crafted file can claim.
    if info.file_size > limit:
        raise file_error(
            path,
            f"{info.filename} would inflate to {format_bytes(info.file_size)}, more than "
            f"{format_bytes(limit)}",
        )


def _read_member(path: Path, zf: zipfile.ZipFile, name: str) -> bytes:
    try:
        return zf.read(name)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, RuntimeError) as exc:
        raise file_error(path, f"damaged or truncated file ({first_line(exc)})") from None
    except Exception as exc:  # zlib.error and other decoder failures
        raise file_error(path, f"damaged or truncated file ({first_line(exc)})") from None


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
        raise file_error(path, f"{name} is not valid JSON ({first_line(exc)})") from None


def _check_manifest(path: Path, manifest: Any) -> None:
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT_NAME:
        raise file_error(
            path, f"not a napari-polarseg classifier file ({MANIFEST_NAME} of another format)"
        )
    version = manifest.get("format_version")
    if version != FORMAT_VERSION or not is_int(version):
        raise file_error(
            path,
            f"classifier format version {version!r} is not supported (this napari-polarseg "
            f"{__version__} reads version {FORMAT_VERSION})",
        )
    model_type = manifest.get("model_type")
    if not isinstance(model_type, str) or model_type not in ALLOWED_MODEL_TYPES:
        raise file_error(path, f"model type {short_text(model_type)} is not on the allow-list")
    members = manifest.get("members")
    if not isinstance(members, dict) or set(members) != {MODEL_NAME, METADATA_NAME}:
        raise file_error(path, f"{MANIFEST_NAME} does not list the digests of the members")
    for name, entry in members.items():
        if (
            not isinstance(entry, dict)
            or not isinstance(entry.get("sha256"), str)
            or not _SHA256_RE.fullmatch(entry["sha256"])
            or not is_int(entry.get("size"))
        ):
            raise file_error(
                path, f"{MANIFEST_NAME} has no valid SHA-256 digest and size of {name}"
            )


def check_payload(path: Path, payload: bytes, model_type: str) -> str:
    """Static checks of a skops payload: structure and every type, before skops reads it.

    Returns the payload's root type name.
    """
    if not payload.startswith(b"PK\x03\x04"):
        raise file_error(path, f"{MODEL_NAME} is not a skops payload (not a zip)")
    try:
        with zipfile.ZipFile(io.BytesIO(payload)) as inner:
            infos = inner.infolist()
            names = [info.filename for info in infos]
            if "schema.json" not in names or len(set(names)) != len(names):
                raise file_error(path, f"{MODEL_NAME} is not a skops payload (no schema.json)")
            if any(n != "schema.json" and not _NPY_MEMBER_RE.fullmatch(n) for n in names):
                raise file_error(path, f"{MODEL_NAME} holds members other than skops arrays")
            total = sum(info.file_size for info in infos)
            if total > memory_limit():
                raise file_error(
                    path, f"{MODEL_NAME} would inflate to {format_bytes(total)} of arrays"
                )
            for info in infos:
                if info.flag_bits & 0x1 or info.compress_type not in (
                    zipfile.ZIP_STORED,
                    zipfile.ZIP_DEFLATED,
                ):
                    raise file_error(path, f"{MODEL_NAME} has an encrypted or odd member")
            raw_schema = inner.read("schema.json")
    except PolarsegError:
        raise
    except Exception as exc:  # BadZipFile, zlib.error, ...
        raise file_error(path, f"{MODEL_NAME} is damaged ({first_line(exc)})") from None
    schema = _parse_json(path, raw_schema, f"{MODEL_NAME} schema")
    if not isinstance(schema, dict):
        raise file_error(path, f"{MODEL_NAME} schema is not a JSON object")
    protocol = schema.get("protocol")
    if not is_int(protocol) or protocol < _MIN_SKOPS_PROTOCOL:
        raise file_error(path, f"{MODEL_NAME} uses skops protocol {protocol!r} (need 2 or newer)")
    root = _node_type(schema)
    if root not in ALLOWED_MODEL_TYPES or schema.get("__loader__") != "ObjectNode":
        raise file_error(path, f"model type {short_text(root)} is not on the allow-list")
    if root != model_type:
        raise file_error(path, f"the model is a {root}, not the manifest's {model_type}")
    _check_schema_types(path, schema)
    # skops's own view of the types (it resolves some names from values, e.g. the bit
    # generator of a numpy Generator): nothing outside our list either.
    try:
        untrusted = sio.get_untrusted_types(data=payload)
    except Exception as exc:
        raise file_error(path, f"{MODEL_NAME} cannot be audited ({first_line(exc)})") from None
    outside = sorted(set(untrusted) - ALLOWED_TYPES)
    if outside:
        raise file_error(
            path, f"the model holds types outside the allow-list: {_short_list(outside)}"
        )
    return root


def _check_schema_types(path: Path, schema: dict[str, Any]) -> None:
    """Every node of the skops object tree: an allowed loader naming an allowed type."""
    # Iterative walk: a crafted, deeply nested schema must not hit the recursion limit.
    stack: list[tuple[Any, int]] = [(schema, 0)]
    while stack:
        item, depth = stack.pop()
        if depth > _MAX_SCHEMA_DEPTH:
            raise file_error(path, f"{MODEL_NAME} schema is nested too deeply")
        if isinstance(item, dict):
            if "__loader__" in item:
                loader = item["__loader__"]
                if not isinstance(loader, str) or loader not in ALLOWED_LOADERS:
                    raise file_error(
                        path,
                        f"the model uses skops node {short_text(loader)}, which is not allowed "
                        "(functions, methods and constructor calls never are)",
                    )
                # a CachedNode only points back at a node already checked
                if loader != "CachedNode" and _node_type(item) not in ALLOWED_TYPES:
                    raise file_error(
                        path,
                        f"the model holds type {short_text(_node_type(item))}, not on the "
                        "allow-list",
                    )
            stack.extend((value, depth + 1) for value in item.values())
        elif isinstance(item, list):
            stack.extend((value, depth + 1) for value in item)


def _node_type(node: dict[str, Any]) -> str:
    module, name = node.get("__module__"), node.get("__class__")
    if not isinstance(module, str) or not isinstance(name, str):
        return repr((module, name))
    return f"{module}.{name}"


def _short_list(names: list[str]) -> str:
    shown = ", ".join(short_text(n) for n in names[:5])
    return shown + (f" and {len(names) - 5} more" if len(names) > 5 else "")
