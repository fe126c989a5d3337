"""Every Python snippet of README.md and of the docs pages runs as written.

Each fenced ``python`` block is executed on its own (a fresh namespace, in a
temporary working directory), so a snippet must hold its own imports and set-up:
a reader can paste any one of them. A snippet that fails names its file and line.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
_FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)


def snippets(path: Path) -> list[tuple[int, str]]:
    """``(line, code)`` of each fenced python block of a Markdown file."""
    text = path.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start()) + 2, m.group(1)) for m in _FENCE.finditer(text)]


CASES = [
    pytest.param(page, line, code, id=f"{page.relative_to(ROOT)}:{line}")
    for page in PAGES
    for line, code in snippets(page)
]


def test_the_pages_hold_snippets():
    assert snippets(ROOT / "README.md"), "README.md has no python snippet"
    assert sum(len(snippets(p)) for p in PAGES[1:]) >= 15, "the docs pages lost snippets"


@pytest.mark.slow
@pytest.mark.parametrize(("page", "line", "code"), CASES)
def test_snippet_runs(page, line, code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    compiled = compile(code, f"{page.name}:{line}", "exec")
    namespace: dict = {"__name__": "__main__"}
    before = {p.name for p in ROOT.iterdir()}
    try:
        exec(compiled, namespace)  # noqa: S102 - the documentation's own code
    finally:
        import matplotlib.pyplot as plt

        plt.close("all")
    assert {p.name for p in ROOT.iterdir()} == before, f"{page.name}:{line} wrote into {ROOT}"
    assert not any(tmp_path.iterdir()), f"{page.name}:{line} wrote into the working directory"
