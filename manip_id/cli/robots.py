"""``manip-id robots``: the robots that load by name."""

from __future__ import annotations

import argparse

from ..errors import RobotError


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
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..robot import available_robots, load_robot  # pinocchio: heavy, not for --help

    print(f"{'name':28s} {'nq':>4s} {'nv':>4s} {'parameters':>11s}  profile")
    for name in getattr(args, "names", None) or available_robots():
        try:
            robot = load_robot(name)
        except RobotError as exc:
            print(f"{name:28s} unavailable: {exc}")
            continue
        profile = f"{robot.profile.name}.toml" if robot.profile is not None else "-"
        print(f"{name:28s} {robot.nq:4d} {robot.nv:4d} {robot.n_parameters:11d}  {profile}")
    print("any fixed-base URDF also loads by path; 'msd' is the mass-spring-damper")
    return 0
