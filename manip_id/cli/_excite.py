"""``manip-id excite`` once it runs (the options are declared in :mod:`.excite`)."""

from __future__ import annotations

import argparse
import importlib
import os

import numpy as np

from .._io import OutputSet
from ..errors import InputError, OutputError
from ..identification import load_result
from ..robot.model import available_robots
from ..trajectories import (
    DesignOptions,
    PriorInformation,
    World,
    design_excitation,
    format_of,
    write_trajectory,
)
from ._common import parse_floats, reserve_outputs
from ._runtime import robot_from_args


def run(args: argparse.Namespace) -> int:
    if args.sigma is not None and args.previous is None:
        raise InputError(
            "--sigma applies with --from RESULT.json (the identified model's torques plus K "
            "standard deviations); without --from the torque limits hold for the nominal model"
        )
    fmt = format_of(args.out, args.format)
    for path in (args.out, args.json):
        if path is not None and os.path.exists(path) and not args.force:
            raise OutputError(f"{path} exists; give --force to replace it")
    args.outputs = OutputSet(inputs=[p for p in (args.world, args.previous) if p])
    outputs = reserve_outputs(args)
    outputs.file(args.out, "--out")
    robot = robot_from_args(args)
    world = World.load(args.world) if args.world else None
    prior = None
    if args.previous is not None:
        result = load_result(args.previous)
        if result.robot_name != robot.name and {result.robot_name, robot.name} <= set(
            available_robots()
        ):
            raise InputError(
                f"{args.previous} is a result of robot {result.robot_name!r}, not of {robot.name!r}"
            )
        if list(result.base.names) != list(robot.parameter_names):
            raise InputError(
                f"{args.previous} was identified with other parameters than {robot.name!r} has "
                "with these options: give the same --friction/--armature/--joints as identify"
            )
        prior = PriorInformation.from_result(result)
    options = DesignOptions(
        harmonics=args.harmonics,
        base_frequency=args.base_frequency,
        start=None
        if args.start is None
        else np.array(parse_floats(args.start, "--start", robot.nv)),
        criterion=args.criterion,
        margin=args.margin,
        acceleration_limit=_acceleration(args, robot.nv),
        torque=not args.no_torque_limits,
        sigma=DesignOptions.sigma if args.sigma is None else args.sigma,
        clearance=args.clearance,
        self_collision=not args.no_self_collision,
        noise=args.noise,
        rate=args.rate,
        starts=args.starts,
        maxiter=args.maxiter,
        seed=args.seed,
    )
    design = design_excitation(robot, args.duration, options=options, world=world, prior=prior)
    t, q, dq, ddq = design.samples()
    tau = design.torques(robot)
    outputs.write(
        args.out, lambda tmp: write_trajectory(tmp, fmt, t, q, dq, ddq, tau, robot.dof_names)
    )
    doc = {"robot": robot.name, "excitation": design.to_dict()}
    if args.json is not None:
        outputs.write_json(args.json, doc)
    if args.report is not None:
        # matplotlib and meshcat are loaded only when a report is written
        viz = importlib.import_module("manip_id.viz.excite_report")
        viz.write_excite_report(
            args.report_claim, robot, design, doc, source=args.previous, force=args.force
        )
    print("\n".join(design.summary()))
    outputs.publish()
    print(f"wrote {args.out}" + (f" and {args.json}" if args.json else ""))
    if args.report is not None:
        print(f"wrote the report to {args.report}/index.html")
    return 0


def _acceleration(args: argparse.Namespace, nv: int):
    if args.acceleration_limit is None:
        return None
    values = parse_floats(args.acceleration_limit, "--acceleration-limit")
    if len(values) not in (1, nv):
        raise InputError(f"--acceleration-limit: expected 1 or {nv} values, got {len(values)}")
    return np.array(values) if len(values) > 1 else values[0]
