"""``manip-id export`` once it runs (the options are declared in :mod:`.export`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from ..export import check_output, saved_parameters, sidecar_path
from ..identification import load_result
from ._common import finish, reserve_outputs
from ._runtime import robot_from_args, stage_export


def run(args: argparse.Namespace) -> int:
    if not (args.export_urdf or args.export_mjcf):
        raise InputError("give what to write: --export-urdf OUT.urdf and/or --export-mjcf OUT.xml")
    if args.export_urdf:
        check_output(args.export_urdf, force=args.force)
    if args.export_mjcf:
        check_output(args.export_mjcf, force=args.force, suffixes=(".xml",))
    outputs = reserve_outputs(args)  # checked against each other and the inputs first
    if args.export_urdf:
        outputs.file(sidecar_path(args.export_urdf), "--export-urdf sidecar")
    if args.export_mjcf:
        outputs.file(args.export_mjcf, "--export-mjcf")
        outputs.file(sidecar_path(args.export_mjcf), "--export-mjcf sidecar")
    path = Path(args.model)
    result = load_result(path / "result.json" if path.is_dir() else path)
    robot = robot_from_args(args, args.model)  # the result's joint terms and joints
    theta = saved_parameters(robot, result, source=str(args.model))
    stage_export(robot, result, args, outputs, theta=theta, command="manip-id export")
    return finish(args, outputs)
