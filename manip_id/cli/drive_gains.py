"""``manip-id drive-gains``: motor current to joint torque gains from a known payload.

The files hold motor currents [A] in the torque columns. With unloaded and loaded
runs and the payload's known mass (and, when known, its centre of mass and inertia),
:func:`manip_id.payload.identify_drive_gains` estimates one gain per joint
(``tau_j = g_j i_j`` [N m / A]), the robot's base parameters and the payload
parameters not given (Gautier & Briot), by maximum likelihood in current units
(default), OLS, WLS or total least squares (``--method``). A warning names any
joint whose gain the data do not determine.
The JSON's ``drive_gains`` feed ``manip-id identify --torque-scale-from RESULT.json``.
"""

from __future__ import annotations

import argparse
import math
import time

from ..errors import InputError
from ._common import (
    add_robot_arguments,
    check_frame,
    parse_floats,
    print_warnings,
    robot_from_args,
)
from .payload import (
    add_run_arguments,
    check_run_args,
    input_paths,
    preprocess_settings,
    publish_json,
    read_runs,
    reserve_json,
)


def register(sub) -> None:
    p = sub.add_parser(
        "drive-gains",
        help="identify drive gains (current to torque) with a known payload",
        description="Estimate the drive gain of each joint (torque = gain * current) from runs "
        "whose torque columns hold motor currents, without (--unloaded) and with (--loaded) a "
        "payload of known mass fixed to FRAME, together with the base parameters and the "
        "payload parameters that are not given.",
    )
    add_robot_arguments(p)
    add_run_arguments(p, unloaded_required=True)
    p.add_argument(
        "--payload-mass", type=float, required=True, metavar="KG", help="payload mass [kg]"
    )
    p.add_argument(
        "--payload-com",
        default=None,
        metavar="X,Y,Z",
        help="payload centre of mass in FRAME [m], when known",
    )
    p.add_argument(
        "--payload-inertia",
        default=None,
        metavar="IXX,IXY,IYY,IXZ,IYZ,IZZ",
        help="payload inertia about its centre of mass, FRAME axes [kg m^2], when known "
        "(needs --payload-com)",
    )
    p.add_argument(
        "--method",
        choices=("ml", "ols", "wls", "tls"),
        default="ml",
        help="ml: maximum likelihood in current units, started from OLS (default); ols: known "
        "payload columns on the right-hand side (Gautier & Briot); wls: the same weighted per "
        "joint; tls: total least squares. ols/wls/tls shrink the gain of a joint whose current "
        "is small against its noise",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
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
    reserve_json(args, input_paths(args))
    from ..payload import identify_drive_gains  # pinocchio: heavy, not for --help

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
    publish_json(args, doc)
    return 0
