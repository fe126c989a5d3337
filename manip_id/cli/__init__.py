"""The ``manip-id`` command.

Each module of this package that defines ``register(subparsers)`` adds one
subcommand; ``register`` creates its parser and sets ``func`` to a callable
``func(args) -> int | None``. Bad input (any :class:`~manip_id.errors.ManipIdError`)
prints one line on stderr and exits with status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from ..errors import ManipIdError

PROG = "manip-id"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand found in this package."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Identify the dynamic parameters of robot manipulators.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        status = args.func(args)
    except ManipIdError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    return int(status or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
