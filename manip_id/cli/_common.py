"""Options and helpers shared by the subcommands."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from .._io import write_json  # noqa: F401 (the commands import it from here)

if TYPE_CHECKING:
    from ..robot import Robot


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ROBOT and the joint-term options ``--friction``, ``--armature``, ``--spring``."""
    parser.add_argument(
        "robot",
        metavar="ROBOT",
        help="example-robot-data name (see 'manip-id robots'), a .urdf path, or 'msd'",
    )
    parser.add_argument(
        "--friction",
        default=None,
        help="comma-separated friction terms per joint: viscous,coulomb,offset",
    )
    parser.add_argument(
        "--armature",
        action="store_true",
        default=None,
        help="model a rotor inertia (armature) per joint",
    )
    parser.add_argument(
        "--spring", action="store_true", default=None, help="model a linear spring per joint"
    )
    parser.add_argument(
        "--joints", default=None, help="comma-separated active joints (the others are locked)"
    )
    parser.add_argument(
        "--package-dir",
        action="append",
        default=[],
        help="folder where package:// paths of a URDF resolve (repeatable)",
    )


def robot_from_args(args: argparse.Namespace) -> Robot:
    """Load the robot named by :func:`add_robot_arguments` options."""
    from ..robot import load_robot

    joints = [j for j in args.joints.split(",") if j] if getattr(args, "joints", None) else None
    return load_robot(
        args.robot,
        armature=args.armature,
        friction=args.friction,
        spring=args.spring,
        active_joints=joints,
        package_dirs=args.package_dir,
    )
