"""Options and helpers shared by the subcommands."""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from ..robot import Robot, load_robot


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
    joints = [j for j in args.joints.split(",") if j] if getattr(args, "joints", None) else None
    return load_robot(
        args.robot,
        armature=args.armature,
        friction=args.friction,
        spring=args.spring,
        active_joints=joints,
        package_dirs=args.package_dir,
    )


def _jsonable(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename: never a partial file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: str | Path, obj) -> None:
    """Write ``obj`` as indented JSON atomically (numpy arrays become lists)."""
    atomic_write_text(path, json.dumps(obj, indent=2, default=_jsonable) + "\n")
