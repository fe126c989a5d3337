"""``manip-id audit`` once it runs (the options are declared in :mod:`.audit`)."""

from __future__ import annotations

import argparse

from ..audit import AuditOptions, audit_files
from ..datasets import Window, parse_file_spec
from ..datasets.stream import torque_scale_vector
from ..errors import InputError
from ..payload import load_torque_scale
from ..viz.audit_report import write_audit_report
from ._common import (
    data_column_map,
    input_paths,
    parse_floats,
    profile_from_args,
    reserve_outputs,
    spec_options,
)
from ._runtime import (
    robot_from_args,
)


def run(args: argparse.Namespace) -> int:

    if args.torque_scale is not None and args.torque_scale_from is not None:
        raise InputError("give --torque-scale or --torque-scale-from, not both")
    eps = args.velocity_deadband
    if eps is not None and not eps > 0:
        raise InputError(f"--velocity-deadband must be positive [rad/s], got {eps}")
    if args.cutoff is not None and not args.cutoff > 0:
        raise InputError(f"--cutoff must be a positive frequency [Hz], got {args.cutoff}")
    if args.window is not None:
        Window.parse(args.window, "--window")
    outputs = reserve_outputs(args)
    outputs.add_inputs(input_paths(args))
    profile = profile_from_args(args)
    colmap = data_column_map(args, profile)
    robot = robot_from_args(args)
    given: object = None
    if args.torque_scale_from is not None:
        given = load_torque_scale(args.torque_scale_from, robot)
    elif args.torque_scale is not None:
        given = parse_floats(args.torque_scale, "--torque-scale")
    elif profile is not None and profile.torque_scale is not None:
        given = profile.torque_scale
    vector = torque_scale_vector(given, robot.nv, "--torque-scale")
    scale = None if vector is None else tuple(vector.tolist())
    extra = spec_options(args)
    specs = [
        parse_file_spec(v, window=args.window, columns=colmap, topic=args.topic, **extra)
        for v in args.data
    ]
    options = AuditOptions(
        torque_scale=scale,
        drop_bad_rows=args.drop_bad_rows,
        standstill=args.velocity_deadband,
        cutoff=args.cutoff,
    )
    audit = audit_files(robot, specs, options)
    print(audit.table())
    audit.check()  # every file audited first; then one error naming each unreadable one
    if args.json:
        outputs.write_json(args.json, {"audit": audit.to_dict()})
    if args.report_claim is not None:
        write_audit_report(args.report_claim, audit.to_dict(), force=args.force)
    outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
    if args.report_claim is not None:
        print(f"wrote the report to {args.report}/index.html")
    return 0
