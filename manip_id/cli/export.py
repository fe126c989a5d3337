"""``manip-id export ROBOT --model RESULT.json --export-urdf OUT.urdf``: a saved result out.

The physically consistent standard parameters of an earlier ``manip-id identify
--consistent --json`` (or a report's ``result.json``) written as the robot's URDF and/or
MJCF with their sidecars, as ``identify --export-urdf`` writes them, without identifying
again; the robot is loaded with the model structure the result records.
"""

from __future__ import annotations

from ._common import add_robot_arguments, command


def register(sub) -> None:
    p = sub.add_parser(
        "export",
        help="write a saved consistent result as the robot's URDF or MJCF",
        description="Write the physically consistent standard parameters of a saved result "
        "(manip-id identify --consistent --json, a report's folder) as the robot's URDF "
        "and/or MuJoCo MJCF with their sidecars, as identify --export-urdf does; the joint "
        "terms and joints are the result's.",
    )
    add_robot_arguments(p)
    p.add_argument(
        "--model",
        metavar="RESULT.json",
        required=True,
        help="the saved result (manip-id identify --consistent --json, or a report folder)",
    )
    p.add_argument(
        "--export-urdf",
        metavar="OUT.urdf",
        help="write the robot's URDF with the identified inertias and friction; armature "
        "and offset go to OUT.identified.json next to it",
    )
    p.add_argument(
        "--export-mjcf",
        metavar="OUT.xml",
        help="write the identified robot as MuJoCo MJCF: inertias, armature, damping, "
        "frictionloss, meshes; sidecar OUT.xml.identified.json",
    )
    p.add_argument(
        "--force", action="store_true", help="replace existing export files [default: refuse]"
    )
    p.set_defaults(func=command("manip_id.cli._export"))
