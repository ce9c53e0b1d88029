"""No import cycles between the package's modules (module-level or inside functions)."""

from __future__ import annotations

import ast
import importlib
import pkgutil
from pathlib import Path

import napari_polarseg

PACKAGE = napari_polarseg.__name__
#: Conditions of the blocks that only type checkers import.
TYPE_CHECKING_TESTS = ("TYPE_CHECKING", "typing.TYPE_CHECKING")


def _modules() -> dict[str, Path]:
    """Every module of the package and its source file (each one imported once)."""
    found = {PACKAGE: Path(napari_polarseg.__file__)}
    for info in pkgutil.walk_packages(napari_polarseg.__path__, PACKAGE + "."):
        module = importlib.import_module(info.name)
        if getattr(module, "__file__", None):
            found[info.name] = Path(module.__file__)
    return found


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The package modules ``name`` imports anywhere in its file (function-level imports
    too), except under ``if TYPE_CHECKING:``: annotations only, never run."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typing_only = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and ast.unparse(node.test) in TYPE_CHECKING_TESTS
        for stmt in node.body
        for inner in ast.walk(stmt)
    }
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            targets = [base] + [f"{base}.{a.name}" for a in node.names]
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                out.add(target)
    return out


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                found.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    known = set(modules)
    graph = {name: _imports(name, path, known) for name, path in modules.items()}
    # a package's __init__ importing its own submodules is not a cycle with them
    for name in graph:
        graph[name] = {t for t in graph[name] if not name.startswith(t + ".")}
    return graph


def test_the_graph_sees_relative_and_function_level_imports() -> None:
    graph = _graph()
    assert "napari_polarseg.jobs" in graph["napari_polarseg.cli.running"]
    assert "napari_polarseg.classifier_file" in graph["napari_polarseg.jobs"]  # in a function
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles() -> None:
    cycles = _cycles(_graph())
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def _room(module: str) -> str | None:
    """The engine room of a module: its sub-package (``engine.graph``) or, for a module
    directly in the engine, the module (``engine.pipeline``); None outside the engine."""
    prefix = f"{PACKAGE}.engine."
    if not module.startswith(prefix):
        return None
    return prefix + module[len(prefix) :].split(".", 1)[0]


def engine_rooms() -> dict[str, set[str]]:
    """Import arrows between the engine's rooms (function-level imports too)."""
    rooms: dict[str, set[str]] = {}
    for name, targets in _graph().items():
        here = _room(name)
        if here is None:
            continue
        rooms.setdefault(here, set())
        for target in targets:
            there = _room(target)
            if there is not None and there != here:
                rooms[here].add(there)
    return rooms


def test_no_cycle_between_engine_rooms() -> None:
    rooms = engine_rooms()
    assert f"{PACKAGE}.engine.methods" in rooms and f"{PACKAGE}.engine.unsupervised" in rooms
    cycles = _cycles(rooms)
    assert not cycles, "engine rooms in a cycle: " + "; ".join(" <-> ".join(c) for c in cycles)
