"""``manip-id drive-gains`` once it runs: drive gains from runs with and without a known
payload, printed and saved (the options are declared in :mod:`.drive_gains`).
"""

from __future__ import annotations

import argparse
import math
import time

from ..errors import InputError
from ..payload import check_known_payload, identify_drive_gains
from ..viz.payload_report import write_drive_gain_report
from ._common import parse_floats, quiet_stdout
from ._payload import (
    check_run_args,
    input_paths,
    preprocess_settings,
    publish_outputs,
    read_runs,
    reserve_json,
    reserve_report,
)
from ._runtime import check_frame, print_warnings, robot_from_args


def run(args: argparse.Namespace) -> int:
    """``manip-id drive-gains`` (``--quiet``: nothing on stdout)."""
    with quiet_stdout(args):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    check_run_args(args)
    if not (math.isfinite(args.payload_mass) and args.payload_mass > 0):
        raise InputError(f"--payload-mass must be > 0 [kg], got {args.payload_mass}")
    com = None if args.payload_com is None else parse_floats(args.payload_com, "--payload-com", 3)
    inertia = (
        None
        if args.payload_inertia is None
        else parse_floats(args.payload_inertia, "--payload-inertia", 6)
    )
    if inertia is not None and com is None:
        raise InputError("--payload-inertia (about the centre of mass) needs --payload-com")
    check_known_payload(args.payload_mass, com, inertia)  # physical, before any file is read
    args.report_claim = reserve_report(args, input_paths(args))
    reserve_json(args, input_paths(args))
    robot = robot_from_args(args)
    check_frame(robot, args.frame)
    unloaded, loaded, source = read_runs(args, robot)
    result = identify_drive_gains(
        robot,
        unloaded,
        loaded,
        args.frame,
        args.payload_mass,
        payload_com=com,
        payload_inertia=inertia,
        method=args.method,
        velocity_deadband=args.velocity_deadband,
        chunk=args.chunk,
    )
    doc = result.to_dict()
    doc["audit"] = source.pop("audit")
    doc["data_quality"] = source.pop("data_quality")
    doc["source"] = source
    doc["preprocess"] = preprocess_settings(unloaded + loaded)
    doc["timings"]["command_total"] = round(time.perf_counter() - t_start, 6)
    print(result.table())
    print_warnings(doc)
    publish_outputs(
        args, doc, lambda claim: write_drive_gain_report(claim, robot, doc, force=args.force)
    )
    return 0
