"""The shell commands of README.md and of the docs pages run as written.

Each fenced ``sh`` (or ``bash``) block is a list of commands a reader types. The blocks of
one page run in the order written, each in its own ``bash -euo pipefail``, all in one
temporary folder, so a later block may use what an earlier one wrote (as a reader's
terminal would). ``manip-id`` and ``python`` are the interpreter's own (the venv of the
test run) and import this checkout. ``../shared`` resolves, as from the repository, to
the shared data beside the checkout (``tmp/shared`` links to it); a block that reads
``../shared`` is skipped, with the reason, when that data is absent.

An HTML comment ``<!-- commands: slow -->`` on the line before a block marks its page's
test slow. Nothing may be written outside the temporary folder: the repository's
top-level listing is compared before and after.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
_FENCE = re.compile(
    r"(?:^<!-- commands: (?P<mark>[a-z]+) -->\n)?^```(?:sh|bash)[ \t]*\n(?P<code>.*?)^```[ \t]*$",
    re.MULTILINE | re.DOTALL,
)
BIN = Path(sys.executable).parent


@dataclass(frozen=True)
class Block:
    """One shell block of a page: where it starts, its commands and its mark."""

    page: Path
    line: int
    code: str
    slow: bool

    @property
    def needs_shared(self) -> bool:
        return "../shared" in self.code


def blocks(page: Path) -> list[Block]:
    """The shell blocks of a Markdown page, in the order written."""
    text = page.read_text(encoding="utf-8")
    return [
        Block(page, text.count("\n", 0, m.start("code")) + 1, m.group("code"), m["mark"] == "slow")
        for m in _FENCE.finditer(text)
    ]


def _param(page: Path):
    found = blocks(page)
    marks = [pytest.mark.slow] if any(b.slow for b in found) else []
    return pytest.param(page, found, id=str(page.relative_to(ROOT)), marks=marks)


CASES = [_param(page) for page in PAGES if blocks(page)]


def test_the_readme_shows_both_commands_and_runnable_blocks():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "make demo" in text and "make test" in text
    readme = blocks(ROOT / "README.md")
    assert readme, "README.md has no sh block"
    assert all("manip-id" in b.code or "python" in b.code for b in readme)


def test_a_mark_is_read():
    page = ROOT / "docs" / "fleet.md"
    assert any(b.slow for b in blocks(page))


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(ROOT)  # this checkout, also when the venv's install is another
    env["MPLBACKEND"] = "Agg"
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return env


def _listing() -> set[str]:
    return {p.name for p in ROOT.iterdir()}


@pytest.mark.parametrize(("page", "page_blocks"), CASES)
def test_commands_run_in_order(page, page_blocks, tmp_path):
    if not (BIN / "manip-id").exists():
        pytest.skip(f"no manip-id console script beside {sys.executable}")
    work = tmp_path / "work"
    work.mkdir()
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED)
    before = _listing()
    skipped = []
    for block in page_blocks:
        where = f"{page.relative_to(ROOT)}:{block.line}"
        if block.needs_shared and not SHARED.is_dir():
            skipped.append(f"{where} reads ../shared, and {SHARED} is absent")
            continue
        run = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", block.code],
            cwd=work,
            env=_environment(),
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert run.returncode == 0, (
            f"{where} failed (status {run.returncode}):\n{block.code}\n"
            f"stdout:\n{run.stdout[-3000:]}\nstderr:\n{run.stderr[-3000:]}"
        )
    assert _listing() == before, f"{page.name}'s commands wrote into {ROOT}"
    if skipped:
        pytest.skip("; ".join(skipped))
