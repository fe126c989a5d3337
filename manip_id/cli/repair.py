"""``manip-id repair ROBOT OUT.urdf``: a URDF whose non-physical inertias are made physical.

The bodies of ROBOT that fail the eigenvalue test of their pseudo-inertia are
replaced by their nearest physical ones (:func:`manip_id.repair.repair_nominal`:
mass and centre of mass kept, the second moments about the centre of mass
projected onto the physical ones); the others are left as they are. The table
says what changed per body; OUT (and its sidecar, :func:`manip_id.export.export_urdf`)
is checked before the work and written atomically.
"""

from __future__ import annotations

import argparse

from ._common import add_robot_arguments, robot_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "repair",
        help="write a copy of a URDF whose non-physical inertias are made physical",
        description="Make the nominal model of ROBOT physically consistent: each body whose "
        "pseudo-inertia is not positive definite (negative mass or inertia, broken triangle "
        "inequalities) gets the nearest physical inertia with the same mass and centre of "
        "mass; the other bodies are unchanged. Writes OUT (a .urdf) and its sidecar.",
    )
    add_robot_arguments(p)
    p.add_argument("out", metavar="OUT.urdf", help="the repaired URDF to write")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.add_argument("--json", metavar="OUT", help="write what changed per body as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..errors import InputError
    from ..export import check_output, export_urdf, sidecar_path
    from ..repair import repair_nominal
    from ._common import reserve_outputs

    check_output(args.out, args.force)  # before the work
    if args.json and Path(args.json).resolve() == Path(args.out).resolve():
        raise InputError(f"--json {args.json} is OUT.urdf")
    outputs = reserve_outputs(args)
    robot = robot_from_args(args)
    result = repair_nominal(robot)
    print(f"repair of {robot.name}:")
    print(result.table())
    written = export_urdf(robot, result.theta, args.out, force=args.force)
    if args.json:
        outputs.write_json(args.json, {"robot": robot.name, "repair": result.to_dict()})
    outputs.publish()
    print(f"wrote {written.urdf} and its sidecar {sidecar_path(written.urdf).name}")
    if args.json:
        print(f"wrote {args.json}")
    return 0
