"""No import cycle anywhere in the package: between its modules, and between the parts
(sub-packages and modules) of every package in it.

Every import statement counts, wherever it stands: at module level, inside a function,
and under ``if TYPE_CHECKING:`` (annotations only, but still an arrow between two
modules). The sources are parsed with :mod:`ast`, nothing is imported, so the same
checker runs on a planted package below. Imports by name at run time
(``importlib.import_module``: the registry's and the engine's lazy loaders) are not
statements and are not seen.
"""

from __future__ import annotations

import ast
from pathlib import Path

import napari_polarseg

PACKAGE = napari_polarseg.__name__
ROOT = Path(napari_polarseg.__file__).parent


def package_modules(root: Path, package: str) -> dict[str, Path]:
    """Every module of the package in the folder ``root`` (named ``package``) and its
    source file: the ``.py`` files whose folders all have an ``__init__.py``."""
    found: dict[str, Path] = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        folders = [root.joinpath(*parts[:i]) for i in range(len(parts))]
        if not all((folder / "__init__.py").is_file() for folder in folders):
            continue
        names = parts[:-1] if parts[-1] == "__init__" else parts
        found[".".join([package, *names])] = path
    return found


def module_imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The modules of ``known`` that the module ``name`` (source ``path``) imports, in
    any statement of its file: module level, functions, ``if TYPE_CHECKING:``."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
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


def module_graph(root: Path, package: str) -> dict[str, set[str]]:
    """Module → the modules it imports. An import of an enclosing package (``from ..
    import __version__``) is left out: Python runs a package's ``__init__`` before any
    of its modules in any case, so it says nothing about the order between modules."""
    modules = package_modules(root, package)
    known = set(modules)
    graph = {name: module_imports(name, path, known) for name, path in modules.items()}
    return {name: {t for t in out if not name.startswith(t + ".")} for name, out in graph.items()}


def part_of(package: str, module: str) -> str | None:
    """The part of ``package`` that holds ``module``: the sub-package or module directly
    in it (``engine.classifier`` for ``engine.classifier.region_walk`` in ``engine``);
    None for the package itself and modules outside it."""
    if not module.startswith(package + "."):
        return None
    return f"{package}.{module[len(package) + 1 :].split('.', 1)[0]}"


def part_graph(graph: dict[str, set[str]], package: str) -> dict[str, set[str]]:
    """Import arrows between the parts of ``package``: part A → part B when a module in
    A imports one in B (an ``__init__`` of ``package`` itself is in no part)."""
    parts: dict[str, set[str]] = {}
    for name, targets in graph.items():
        here = part_of(package, name)
        if here is None:
            continue
        parts.setdefault(here, set())
        for target in targets:
            there = part_of(package, target)
            if there is not None and there != here:
                parts[here].add(there)
    return parts


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
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


def import_cycles(root: Path, package: str) -> list[str]:
    """Every import cycle of the package in ``root``: between modules, then between the
    parts of each package (the package itself and every sub-package), one line each."""
    graph = module_graph(root, package)
    found = [f"modules: {' <-> '.join(c)}" for c in cycles(graph)]
    packages = sorted(n for n, p in package_modules(root, package).items() if p.stem == "__init__")
    for name in packages:
        found += [f"parts of {name}: {' <-> '.join(c)}" for c in cycles(part_graph(graph, name))]
    return found


def test_the_graph_sees_every_kind_of_import() -> None:
    graph = module_graph(ROOT, PACKAGE)
    assert "napari_polarseg.jobs" in graph["napari_polarseg.cli.running"]  # relative
    assert "napari_polarseg.classifier_file" in graph["napari_polarseg.jobs"]  # in a function
    # ``from .. import __version__``: an enclosing package, no arrow
    assert PACKAGE not in graph["napari_polarseg.classifier_file.files"]
    engine = part_graph(graph, f"{PACKAGE}.engine")
    assert f"{PACKAGE}.engine.classifier" in engine[f"{PACKAGE}.engine.methods"]
    top = part_graph(graph, PACKAGE)
    assert f"{PACKAGE}.engine" in top[f"{PACKAGE}.classifier_file"]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycle_anywhere_in_the_package() -> None:
    found = import_cycles(ROOT, PACKAGE)
    assert not found, "import cycles:\n" + "\n".join(found)


def test_the_classifier_has_its_own_engine_package_below_the_analyses() -> None:
    engine = part_graph(module_graph(ROOT, PACKAGE), f"{PACKAGE}.engine")
    classifier, analysis = f"{PACKAGE}.engine.classifier", f"{PACKAGE}.engine.analysis"
    assert classifier in engine and analysis in engine
    assert analysis not in engine[classifier]
    # the engine imports nothing above it (the classifier file, io, outputs, widgets)
    top = part_graph(module_graph(ROOT, PACKAGE), PACKAGE)
    assert top[f"{PACKAGE}.engine"] == set()


def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")


def test_a_planted_cycle_is_found(tmp_path: Path) -> None:
    """A cycle closed by a ``TYPE_CHECKING`` import and a function-level one, and a
    cycle between two sub-packages whose modules form none."""
    pkg = tmp_path / "pkg"
    _write(
        pkg,
        {
            "__init__.py": "",
            "low/__init__.py": "",
            "low/base.py": (
                "from typing import TYPE_CHECKING\n"
                "if TYPE_CHECKING:\n    from ..high.user import User\n"
            ),
            "low/other.py": "import pkg.high.tool\n",
            "high/__init__.py": "",
            "high/user.py": "def f():\n    from ..low import base\n",
            "high/tool.py": "X = 1\n",
            "notes/readme.py": "import pkg.low.base\n",  # no __init__.py: not a module
        },
    )
    graph = module_graph(pkg, "pkg")
    assert "pkg.notes.readme" not in graph
    assert graph["pkg.low.base"] == {"pkg.high.user"}
    assert graph["pkg.high.user"] == {"pkg.low", "pkg.low.base"}
    found = import_cycles(pkg, "pkg")
    assert found == [
        "modules: pkg.high.user <-> pkg.low.base",
        "parts of pkg: pkg.high <-> pkg.low",
    ]
    # without the TYPE_CHECKING arrow the modules are acyclic, the sub-packages are not
    _write(pkg, {"low/base.py": "X = 1\n"})
    assert import_cycles(pkg, "pkg") == ["parts of pkg: pkg.high <-> pkg.low"]
    _write(pkg, {"low/other.py": "X = 1\n"})
    assert import_cycles(pkg, "pkg") == []
