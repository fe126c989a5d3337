"""Write the per-command part of docs/cli.md from the CLI's own parser.

``python docs/cli_reference.py`` rewrites every ``### manip-id COMMAND`` section after
the shared options from ``manip-id COMMAND --help`` (its one-line summary, each argument
and option with its help text; the shared options named on one line);
``--check`` exits 1 when the page differs from what the parser says
(tests/test_first_contact.py runs it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "cli.md"
#: Where the generated sections start.
FIRST = "### Options shared by several commands"
#: Options described once under "Options shared by several commands".
SHARED = (
    "ROBOT",
    "--friction",
    "--armature",
    "--spring",
    "--joints",
    "--profile",
    "--package-dir",
    "--delay",
    "--time-unit",
    "--transmission",
)


def _expand(action: argparse.Action, text: str) -> str:
    """The help text as ``--help`` prints it (``%(default)s`` and the like filled in)."""
    params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
    if params.get("choices") is not None:
        params["choices"] = ", ".join(map(str, params["choices"]))
    return text % params if "%" in text else text


def _markdown(text: str) -> str:
    """Inline text safe in a Markdown list item (a literal ``*`` stays a star)."""
    return " ".join(text.split()).replace("*", "\\*")


def _item(action: argparse.Action) -> tuple[str, str]:
    """``(name, line)`` of one argument or option."""
    if not action.option_strings:  # positional
        name = action.metavar or action.dest.upper()
        label = name
    else:
        name = max(action.option_strings, key=len)
        if action.nargs == 0:
            label = name
        elif action.metavar is not None:
            meta = action.metavar if isinstance(action.metavar, str) else " ".join(action.metavar)
            label = f"{name} {meta}"
        elif action.choices is not None:
            label = f"{name} {{{','.join(map(str, action.choices))}}}"
        else:
            label = f"{name} {action.dest.upper()}"
    return name, f"- `{label}`: {_markdown(_expand(action, action.help or ''))}"


def section(name: str, parser: argparse.ArgumentParser, summary: str) -> str:
    """The Markdown section of one command."""
    summary = _markdown(summary)
    summary = summary[:1].upper() + summary[1:] + ("" if summary.endswith(".") else ".")
    lines = [f"### manip-id {name}", "", summary, ""]
    shared = []
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or "--help" in action.option_strings:
            continue
        opt, line = _item(action)
        if opt in SHARED:
            shared.append(f"`{opt}`")
        else:
            lines.append(line)
    if shared:
        lines.append("- shared: " + ", ".join(shared))
    return "\n".join(lines) + "\n"


def shared_section(parsers: dict) -> str:
    """The options several commands share, each once (its help from the first command, in
    alphabetical order, that takes it)."""
    lines = [FIRST, "", "Where a command takes them (its `--help` lists which):", ""]
    for option in SHARED:
        for name in sorted(parsers):
            found = [
                a
                for a in parsers[name]._actions
                if option in a.option_strings or (not a.option_strings and a.metavar == option)
            ]
            if found:
                lines.append(_item(found[0])[1])
                break
    return "\n".join(lines) + "\n"


def reference() -> str:
    """The shared options, then every command's section, alphabetical."""
    from manip_id.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    summaries = {c.dest: c.help or "" for c in sub._choices_actions}
    parts = [shared_section(sub.choices)]
    parts += [section(n, p, summaries.get(n, "")) for n, p in sorted(sub.choices.items())]
    return "\n".join(parts)


def page(current: str) -> str:
    """The page with its command sections written from the parser."""
    at = current.index(FIRST)
    return current[:at] + reference()


def main(argv: list[str]) -> int:
    current = PAGE.read_text(encoding="utf-8")
    new = page(current)
    if "--check" in argv:
        if new != current:
            print(f"{PAGE} differs from the CLI's parser: run python docs/cli_reference.py")
            return 1
        return 0
    PAGE.write_text(new, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))


__all__ = ["SHARED", "page", "reference", "section"]
