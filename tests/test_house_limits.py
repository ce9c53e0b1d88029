"""House limits (issue 15): no package module over 600 lines, no function over 80 lines.

Walks every module of ``napari_polarseg`` with :mod:`ast`. A function's length counts
from its ``def`` line to its last line, docstring included. No exceptions.
"""

import ast
from pathlib import Path

import napari_polarseg

MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80

PACKAGE = Path(napari_polarseg.__file__).parent


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _functions(tree: ast.AST, prefix: str = "") -> list[tuple[str, int]]:
    """(qualified name, length in lines) of every function, methods and nested ones too."""
    found = []
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            name = prefix + node.name
            found.append((name, node.end_lineno - node.lineno + 1))
            found += _functions(node, name + ".")
        elif isinstance(node, ast.ClassDef):
            found += _functions(node, prefix + node.name + ".")
        else:
            found += _functions(node, prefix)
    return found


def test_no_module_over_the_line_limit():
    over = {}
    for path in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_MODULE_LINES:
            over[rel] = n
    assert over == {}, f"modules over {MAX_MODULE_LINES} lines: {over}"


def test_no_function_over_the_line_limit():
    over = {}
    for path in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for name, n in _functions(tree):
            key = f"{rel}:{name}"
            if n > MAX_FUNCTION_LINES:
                over[key] = n
    assert over == {}, f"functions over {MAX_FUNCTION_LINES} lines: {over}"
