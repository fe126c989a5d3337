"""``manip-id repair`` once it runs (the options are declared in :mod:`.repair`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from ..export import check_output, export_urdf, sidecar_path
from ..physics.repair import repair_nominal
from ._common import reserve_outputs
from ._runtime import (
    robot_from_args,
)


def run(args: argparse.Namespace) -> int:

    parent = Path(args.out).absolute().parent
    if not parent.is_dir():  # as every other output: the folder must exist
        raise InputError(f"the folder of OUT.urdf {args.out} does not exist ({parent})")
    _, side = check_output(args.out, args.force)  # before the work
    if args.json:
        for other, what in ((Path(args.out), "OUT.urdf"), (side, "its sidecar")):
            if Path(args.json).absolute().resolve() == other.absolute().resolve():
                raise InputError(f"--json {args.json} is {what} ({other}); give another path")
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
