"""The documentation: a short README, docs/ pages whose links resolve, commands that exist.

Issue 15: the README is the first screen (≤ 12 KB) and links every page of ``docs/``; the
relative links of all of them point at files (and headings) that exist; the two commands
the README gives are the ones ``.ci/run`` and ``scripts/`` run; the table block that
``benchmarks/evaluate.py --docs`` rewrites is in ``docs/quality.md``.
"""

from __future__ import annotations

import importlib.util
import re
import shutil
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
DOCS = REPO / "docs"
#: Issue 15's bound on the README's size, in bytes.
README_MAX_BYTES = 12_000

#: A Markdown link or image target: ``[text](target)`` / ``![alt](target "title")``.
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^\s*(```|~~~)")


def pages() -> list[Path]:
    """README.md, CHANGELOG.md and every page of docs/."""
    return [README, REPO / "CHANGELOG.md", *sorted(DOCS.glob("*.md"))]


def without_fences(text: str) -> str:
    """``text`` without its fenced code blocks."""
    kept, in_fence = [], False
    for line in text.splitlines():
        if FENCE.match(line):
            in_fence = not in_fence
        elif not in_fence:
            kept.append(line)
    return "\n".join(kept)


def links(path: Path) -> list[str]:
    """The link targets of a Markdown file, outside code blocks and code spans."""
    text = re.sub(r"`[^`]*`", "", without_fences(path.read_text(encoding="utf-8")))
    return LINK.findall(text)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The anchors of every heading of a Markdown file (outside code)."""
    text = without_fences(path.read_text(encoding="utf-8"))
    return {slug(m.group(1)) for m in re.finditer(r"^#+\s+(.+?)\s*#*$", text, re.M)}


def bash_blocks(path: Path) -> list[list[str]]:
    """The commands (comments stripped) of every fenced ``bash`` block."""
    blocks, current = [], None
    for line in path.read_text(encoding="utf-8").splitlines():
        if current is None and line.strip() == "```bash":
            current = []
        elif current is not None and line.strip().startswith("```"):
            blocks.append(current)
            current = None
        elif current is not None:
            command = line.split("#", 1)[0].strip()
            if command:
                current.append(command)
    return blocks


def test_slug_follows_github():
    assert slug("Unsupervised default (preset `auto`)") == "unsupervised-default-preset-auto"
    assert slug("Physics, and where the thesis is corrected") == (
        "physics-and-where-the-thesis-is-corrected"
    )
    assert slug("Many scenes: `polarseg batch`") == "many-scenes-polarseg-batch"


def test_readme_is_at_most_12_kb():
    size = len(README.read_bytes())
    assert size <= README_MAX_BYTES, f"README.md is {size} bytes; move detail into docs/"


@pytest.mark.parametrize("page", pages(), ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(page):
    assert page.is_file(), f"{page} is missing"
    broken = []
    for target in links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (page.parent / file_part).resolve() if file_part else page
        if not dest.exists():
            broken.append(f"{target}: no file {dest}")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target}: no heading #{anchor} in {dest.name}")
    assert not broken, f"{page.name}: " + "; ".join(broken)


def test_readme_links_every_docs_page_and_the_screenshot():
    linked = {(REPO / t.partition("#")[0]).resolve() for t in links(README)}
    missing = [p.name for p in DOCS.glob("*.md") if p.resolve() not in linked]
    assert not missing, f"README.md does not link docs/{missing}"
    assert (DOCS / "screenshot-viewer.png").resolve() in linked
    assert (REPO / "CHANGELOG.md").resolve() in linked


def test_readme_commands_are_the_ones_ci_and_scripts_run():
    first = bash_blocks(README)[0]
    assert first == ["bash scripts/demo.sh", "bash scripts/test.sh"]
    for command in first:
        assert (REPO / command.split()[1]).is_file(), command
    ci = [line.strip() for line in (REPO / ".ci" / "run").read_text().splitlines()]
    assert "exec bash scripts/test.sh" in ci
    assert ".venv/bin/polarseg demo" in (REPO / "scripts" / "demo.sh").read_text()


def test_skip_messages_name_an_existing_section():
    """Tests skipped without the real frames say where to read about them."""
    cited = set()
    for test_file in (REPO / "tests").glob("test_*.py"):
        for page, section in re.findall(r"(docs/\w+\.md), '([^']+)'", test_file.read_text()):
            cited.add((page, section))
    assert ("docs/data.md", "Optional real data") in cited
    for page, section in cited:
        assert slug(section) in anchors(REPO / page), f"{page} has no section {section!r}"


def load_evaluate(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """``benchmarks/evaluate.py`` as a module (it imports its siblings by name)."""
    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    spec = importlib.util.spec_from_file_location("evaluate", REPO / "benchmarks" / "evaluate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_evaluate_rewrites_the_table_block_of_docs_quality(monkeypatch, tmp_path):
    evaluate = load_evaluate(monkeypatch)
    assert evaluate.QUALITY_PAGE == DOCS / "quality.md"
    text = evaluate.QUALITY_PAGE.read_text(encoding="utf-8")
    assert text.count(evaluate.BEGIN) == 1 and text.count(evaluate.END) == 1
    assert text.index(evaluate.BEGIN) < text.index(evaluate.END)
    assert evaluate.BEGIN not in README.read_text(encoding="utf-8")

    page = tmp_path / "quality.md"
    shutil.copy(evaluate.QUALITY_PAGE, page)
    evaluate.write_docs("| a |\n|---|\n| 1 |", "python benchmarks/evaluate.py --docs", page)
    new = page.read_text(encoding="utf-8")
    head, end = text.split(evaluate.BEGIN)[0], text.split(evaluate.END)[1]
    assert new.startswith(head) and new.endswith(end)
    assert "| 1 |" in new and "0.804" not in new.split(evaluate.END)[0][len(head) :]
