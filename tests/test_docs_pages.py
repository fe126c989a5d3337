"""The README stays a short start, and every link of the README and the docs pages resolves.

The README holds what the project is, the install, the two commands and a quick start
(at most 200 lines, issue 22); the rest lives in docs/, whose pages every relative
Markdown link must reach (a page moved or renamed breaks a link here first).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: ``[text](target)`` outside code; the target's anchor is dropped.
_LINK = re.compile(r"\[[^\]\n]+\]\(([^)\s]+)\)")
_FENCED = re.compile(r"^```.*?^```[ \t]*$", re.MULTILINE | re.DOTALL)


def _links(page: Path) -> list[str]:
    text = _FENCED.sub("", page.read_text(encoding="utf-8"))
    text = re.sub(r"`[^`\n]*`", "", text)  # inline code is not a link
    return [m.group(1) for m in _LINK.finditer(text)]


def test_the_readme_is_short_and_shows_both_commands():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines: move sections to docs/"
    assert any("make demo" in line for line in lines)
    assert any("make test" in line for line in lines)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    broken = []
    for target in _links(page):
        if re.match(r"^[a-z]+://|^mailto:|^#", target):
            continue
        path = (page.parent / target.split("#", 1)[0]).resolve()
        if not path.exists():
            broken.append(target)
    assert not broken, f"{page.relative_to(ROOT)} links to missing files: {broken}"


def test_a_broken_link_is_found(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("see [a](a.md), [b](https://example.org), `[c](c.md)`\n")
    assert _links(page) == ["a.md", "https://example.org"]
