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
        help="comma-separated friction laws per joint: viscous, coulomb, offset, asymmetric, "
        "stribeck, sigmoid, position[:K] (docs/friction.md); 'auto' (identify --data): "
        "chosen per joint by validation error, else BIC",
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
        "--profile",
        default=None,
        help="identification profile: a robot name or a .toml file, 'none' for none "
        "[default robots/ROBOT.toml when ROBOT is a name]; options given here override it",
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
    from . import native_stderr_captured

    joints = [j for j in args.joints.split(",") if j] if getattr(args, "joints", None) else None
    with native_stderr_captured("urdfdom"):  # its C++ messages become one warning line
        return load_robot(
            args.robot,
            armature=args.armature,
            friction=None if args.friction == "auto" else args.friction,
            spring=args.spring,
            active_joints=joints,
            package_dirs=args.package_dir,
            profile=_profile_option(args),
        )


def _profile_option(args: argparse.Namespace):
    value = getattr(args, "profile", None)
    return False if value == "none" else value


def profile_from_args(args: argparse.Namespace):
    """The :class:`~manip_id.profiles.RobotProfile` the options select, without loading the robot.

    ``--profile`` when given (``none``: no profile), else ``robots/ROBOT.toml`` for a
    robot given by name; None when there is none.
    """
    from ..profiles import find_profile, load_profile

    value = _profile_option(args)
    if value is False:
        return None
    if value is not None:
        return load_profile(value)
    return find_profile(str(getattr(args, "robot", "") or ""))


#: Options naming input files or folders (the outputs must not be one of them).
INPUT_OPTIONS = ("robot", "data", "validate", "urdf", "package_dir")
#: Options naming output files, and the option naming a report folder.
FILE_OUTPUT_OPTIONS = ("json", "html", "export_urdf")


def input_paths(args: argparse.Namespace) -> list[str]:
    """Every existing path among the input options of ``args`` (``FILE@WINDOW``: FILE)."""
    import os

    paths = []
    for name in INPUT_OPTIONS + ("torque_scale_from", "known_base", "input"):
        value = getattr(args, name, None)
        for item in value if isinstance(value, list) else [value]:
            if not isinstance(item, str) or not item:
                continue
            if not os.path.exists(item) and "@" in item:  # a window of a file
                item = item.rsplit("@", 1)[0]
            if os.path.exists(item):
                paths.append(item)
    return paths


def reserve_outputs(args: argparse.Namespace):
    """Check and reserve every output option of ``args`` before the work; returns the set.

    ``--json``, ``--html``, ``--export-urdf`` (files) and ``--report`` (a folder, claimed
    atomically, replaced with ``--force`` only when manip-id wrote it) are checked
    against each other and against the inputs (:mod:`manip_id._io`). The command writes
    them with ``outputs.write_json(...)`` / ``claim.write(...)`` and publishes them all
    with ``outputs.publish()`` at the end. Also checks ``--seed`` and caps ``--workers``.
    """
    from .._io import OutputSet

    check_seed_and_workers(args)
    outputs = getattr(args, "outputs", None)
    if outputs is None:
        outputs = args.outputs = OutputSet()
    outputs.add_inputs(input_paths(args))
    args.report_claim = None
    if getattr(args, "report", None) is not None:  # first: a file inside it then collides
        args.report_claim = outputs.report(args.report, "--report", force=args.force)
    for name in FILE_OUTPUT_OPTIONS:
        value = getattr(args, name, None)
        if value is not None:
            outputs.file(value, "--" + name.replace("_", "-"))
    return outputs


def check_seed_and_workers(args: argparse.Namespace) -> None:
    """A negative ``--seed`` is an error; ``--workers`` above the core count is capped."""
    import os

    from ..errors import InputError

    seed = getattr(args, "seed", None)
    if seed is not None and not 0 <= seed < 2**63:
        raise InputError(f"--seed must be an integer in [0, 2**63), got {seed}")
    workers = getattr(args, "workers", None)
    if workers is not None:
        if workers < 1:
            raise InputError(f"--workers must be >= 1, got {workers}")
        affinity = getattr(os, "sched_getaffinity", None)  # the cores this process may use
        cores = len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)
        if workers > cores:
            from . import warn

            warn(f"--workers {workers} capped at the {cores} cores of this machine")
            args.workers = cores
