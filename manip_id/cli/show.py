"""``manip-id show RESULT.json``: print a saved identification result again."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError


def register(sub) -> None:
    p = sub.add_parser(
        "show",
        help="print a saved identification result (manip-id identify --json, result.json)",
        description="Print a saved identification result: errors of the identified and the "
        "nominal model in percent, the reference torques, the base parameters with units, "
        "nominal values, std and flags, and the warnings. RESULT is the JSON of manip-id "
        "identify --json or the result.json of a report folder (or the folder itself).",
    )
    p.add_argument("result", metavar="RESULT", help="result JSON file or report folder")
    p.add_argument(
        "--rows", type=int, default=None, metavar="N", help="show the first N parameters only"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..identification import load_result, result_text  # pinocchio: heavy, not for --help

    path = Path(args.result)
    if path.is_dir():
        path = path / "result.json"
    if args.rows is not None and args.rows < 1:
        raise InputError(f"--rows must be >= 1, got {args.rows}")
    doc = load_result(path).to_dict()  # read through the result type: the one schema
    print(result_text(doc, max_rows=args.rows))
    return 0
