"""``manip-id show RESULT.json``: print a saved identification result again."""

from __future__ import annotations

from ._common import command


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
    p.set_defaults(func=command("manip_id.cli._show"))
