"""``manip-id robots``: the robots that load by name."""

from __future__ import annotations

from ._common import command


def register(sub) -> None:
    p = sub.add_parser(
        "robots",
        help="list the robots available by name",
        description="List the robots available by name with nv, the number "
        "of rigid-body parameters and their identification profile (robots/NAME.toml).",
    )
    p.add_argument(
        "names", nargs="*", metavar="ROBOT", help="list only these robots [default: all]"
    )
    p.set_defaults(func=command("manip_id.cli._robots"))
