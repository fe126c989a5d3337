"""``manip-id audit ROBOT --data FILE...``: the log auditor, and its run before every fit.

The command prints the audit (:mod:`manip_id.audit`) of each file against the
nominal model of ROBOT as one compact table and its findings, with the options
they recommend, and writes it as JSON (``--json``: ``{"audit": {"files": [...]}}``).
``identify``, ``payload`` and ``drive-gains`` run the same audit on their files
before the fit (:func:`before_fit`), print the same table and save it in their
JSON as ``audit``. This module also holds the stream options those commands share
(:func:`add_stream_arguments`): ``--delay``, ``--time-unit``, ``--trim-standstill``.
"""

from __future__ import annotations

import argparse

from ..errors import InputError
from ._common import (
    add_file_arguments,
    add_robot_arguments,
    add_stream_arguments,
    column_map,
    input_paths,
    parse_floats,
    profile_from_args,
    reserve_outputs,
    robot_from_args,
    spec_options,
)


def register(sub) -> None:
    p = sub.add_parser(
        "audit",
        help="check log files against the nominal model before a fit",
        description="Audit measurement files against the nominal model of ROBOT: per file and "
        "joint the measured/nominal torque scale and sign (currents, gear ratios, flipped "
        "signs), the delay of the torque stream, the torque offset, the standstill share; per "
        "file the time unit, positions (degrees, offsets, wrap-around), rest at the edges, "
        "static files and bad rows. Prints one table and the options the findings recommend.",
    )
    add_robot_arguments(p)
    p.add_argument(
        "--data",
        metavar="FILE",
        nargs="+",
        action="extend",
        required=True,
        help="one or more measurement files, as for 'manip-id identify' (FILE@START:STOP [s], "
        "FILE@#A:#B [rows])",
    )
    p.add_argument(
        "--column",
        action="append",
        default=[],
        metavar="FIELD=COLUMNS",
        help="CSV column map for other layouts (repeatable), as for 'manip-id identify'",
    )
    p.add_argument(
        "--cutoff",
        type=float,
        default=None,
        help="low-pass cut-off [Hz] for files without ddq [default that of identify]",
    )
    p.add_argument("--json", metavar="OUT", help="write the audit as JSON to OUT")
    add_file_arguments(p)
    add_stream_arguments(p, trim=False)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..audit import AuditOptions, audit_files
    from ..datasets import Window, parse_file_spec
    from ..datasets.stream import torque_scale_vector

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
    colmap = column_map(args.column)
    if colmap is None and profile is not None and profile.columns:
        colmap = dict(profile.columns)
    robot = robot_from_args(args)
    given: object = None
    if args.torque_scale_from is not None:
        from ..payload import load_torque_scale

        given = load_torque_scale(args.torque_scale_from)
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
    if args.json:
        outputs.write_json(args.json, {"audit": audit.to_dict()})
    outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
    return 0
