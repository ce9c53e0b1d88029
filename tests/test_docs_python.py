"""Every Python block of docs/python.md runs on its own, as a reader pastes it (issue 40,
point 5): each in a fresh process, from a folder holding the repository's example data,
so a block that leans on a name from an earlier block fails here."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "python.md"


def python_blocks(path: Path) -> list[tuple[int, str]]:
    """(first line, code) of every fenced ``python`` block of ``path``."""
    blocks, code, start = [], None, 0
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if code is None and line.strip() == "```python":
            code, start = [], number + 1
        elif code is not None and line.strip().startswith("```"):
            blocks.append((start, "\n".join(code) + "\n"))
            code = None
        elif code is not None:
            code.append(line)
    return blocks


def test_the_page_has_python_blocks():
    assert len(python_blocks(PAGE)) >= 4


@pytest.mark.parametrize("start,code", python_blocks(PAGE), ids=lambda v: str(v)[:8])
def test_each_python_block_runs_on_its_own(start, code, tmp_path):
    (tmp_path / "examples").symlink_to(REPO / "examples")
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, f"docs/python.md line {start}:\n{done.stderr[-3000:]}"
