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

from ._common import add_quiet_verbose, add_robot_arguments, command
from .payload import (
    add_run_arguments,
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
    p.add_argument(
        "--force",
        action="store_true",
        help="replace a --report folder manip-id wrote [default: refuse]",
    )
    add_quiet_verbose(
        p,
        "also print each file's data quality and the pre-fit audit's table "
        "[default: the audit in one line; the data quality is in --json]",
    )
    p.set_defaults(func=command("manip_id.cli._drive_gains"))
