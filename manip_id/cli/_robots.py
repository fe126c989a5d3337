"""``manip-id robots`` once it runs: the robots that load, with their sizes and profiles
(the options are declared in :mod:`.robots`).
"""

from __future__ import annotations

import argparse

from ..errors import RobotError
from ..robot.model import available_robots, load_robot


def run(args: argparse.Namespace) -> int:
    named = list(getattr(args, "names", None) or [])
    # a robot the user names must load (an unknown name is one error line, exit 2); in the
    # full list a robot this install cannot load is shown as unavailable
    robots = {name: load_robot(name) for name in named}
    print(f"{'name':28s} {'nq':>4s} {'nv':>4s} {'parameters':>11s}  profile")
    for name in named or available_robots():
        try:
            robot = robots[name] if name in robots else load_robot(name)
        except RobotError as exc:
            print(f"{name:28s} unavailable: {exc}")
            continue
        profile = f"{robot.profile.name}.toml" if robot.profile is not None else "-"
        print(f"{name:28s} {robot.nq:4d} {robot.nv:4d} {robot.n_parameters:11d}  {profile}")
    print("any fixed-base URDF also loads by path; 'msd' is the mass-spring-damper")
    return 0
