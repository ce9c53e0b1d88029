"""Every cross-reference in the package's docstrings (``:func:`…```, ``:class:`…```,
``:meth:`…```, ``:mod:`…```, ``:data:`…```, ``:attr:`…```, ``:exc:`…```) names
something that exists: a module, or an object reachable from one."""

from __future__ import annotations

import ast
import builtins
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import napari_polarseg

ROLE = re.compile(r":(func|class|meth|mod|data|attr|exc|obj):`([^`]+)`")
PACKAGE = napari_polarseg.__name__
#: Modules that need a GUI (napari, Qt) to import: their references are read, and
#: resolved against the module's source text instead of an import.
GUI_PREFIXES = (f"{PACKAGE}.widgets", f"{PACKAGE}._")


def _lookup(dotted: str) -> bool:
    """True if ``dotted`` is a module or an attribute path below an importable module
    (dataclass fields and attributes an ``__init__`` assigns count as attributes)."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        name = ".".join(parts[:cut])
        try:
            obj = importlib.import_module(name)
        except Exception:  # noqa: BLE001 - not a module: try a shorter prefix
            continue
        for attr in parts[cut:]:
            if hasattr(obj, attr):
                obj = getattr(obj, attr)
            elif attr in getattr(obj, "__dataclass_fields__", {}) or attr in getattr(
                obj, "__annotations__", {}
            ):
                return attr == parts[-1]
            elif inspect.isclass(obj) and f"self.{attr} " in _source(obj.__init__):
                return attr == parts[-1]
            else:
                return False
        return True
    return False


def _source(obj: object) -> str:
    try:
        return inspect.getsource(obj)
    except (OSError, TypeError):
        return ""


def _candidates(target: str, module: str, context: list[str]) -> list[str]:
    """Where Sphinx would look for ``target`` written in ``module`` (inside the classes
    ``context``): relative to the module and every package above it, the class."""
    stripped = target.lstrip(".")
    scopes = module.split(".")
    prefixes = [".".join(scopes[:k]) for k in range(len(scopes), 0, -1)]
    found = [stripped] if not target.startswith(".") else []
    found += [f"{p}.{stripped}" for p in prefixes]
    if context:
        found.insert(0, f"{module}.{'.'.join(context)}.{stripped}")
    return found


def _references(path: Path):
    """(line, role, target, class context) of every docstring reference in a file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))

    def visit(node: ast.AST, context: list[str]):
        doc = (
            ast.get_docstring(node, clean=False)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            else None
        )
        if doc:
            line = getattr(node, "lineno", 1)
            for match in ROLE.finditer(doc):
                target = match.group(2)
                if "<" in target:  # "text <target>"
                    target = target[target.index("<") + 1 : target.rindex(">")]
                yield line, match.group(1), target.lstrip("~!"), context
        for child in ast.iter_child_nodes(node):
            inner = [*context, child.name] if isinstance(child, ast.ClassDef) else context
            yield from visit(child, inner)

    yield from visit(tree, [])


def _modules() -> dict[str, Path]:
    found = {PACKAGE: Path(napari_polarseg.__file__)}
    for info in pkgutil.walk_packages(napari_polarseg.__path__, PACKAGE + "."):
        spec = importlib.util.find_spec(info.name)
        if spec and spec.origin and spec.origin.endswith(".py"):
            found[info.name] = Path(spec.origin)
    return found


def _resolves(target: str, module: str, context: list[str], gui: bool) -> bool:
    if hasattr(builtins, target):  # ValueError, TypeError, …
        return True
    root = target.lstrip(".").split(".")[0]
    if not target.startswith(".") and root not in (PACKAGE, *module.split(".")[:1]):
        try:  # another package: numpy, scipy, napari, …; only its top level is checked
            importlib.util.find_spec(root)
        except (ImportError, ValueError):
            return False
        if importlib.util.find_spec(root) is not None:
            return True
    if gui:  # a GUI module: a name defined in its own text, or elsewhere in the package
        text = _modules()[module].read_text(encoding="utf-8")
        last = target.split(".")[-1]
        if re.search(rf"(def|class) {re.escape(last)}\b|\b{re.escape(last)}\s*[:=]", text):
            return True
    return any(_lookup(c) for c in _candidates(target, module, context))


def test_every_docstring_reference_resolves() -> None:
    broken = []
    for module, path in _modules().items():
        gui = module.startswith(GUI_PREFIXES)
        for line, role, target, context in _references(path):
            if not _resolves(target, module, context, gui):
                broken.append(
                    f"{path.relative_to(Path(napari_polarseg.__file__).parents[1])}"
                    f":{line} :{role}:`{target}`"
                )
    assert not broken, f"{len(broken)} references do not resolve:\n" + "\n".join(broken)
