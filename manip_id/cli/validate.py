"""``manip-id validate ROBOT --model RESULT.json --data FILE...``: rollout validation.

From many start points of each file the identified model (and the nominal one) is
integrated forward from the measured torques over ``--horizon`` seconds and compared
with the logged positions and velocities (:mod:`manip_id.identification.rollout`).
"""

from __future__ import annotations

from ._common import add_robot_arguments, command


def register(sub) -> None:
    p = sub.add_parser(
        "validate",
        help="roll the identified and the nominal model forward from the measured torques",
        description="Rollout validation: from each of many start points of the data, integrate "
        "the identified model (RESULT.json) and the nominal one forward from the measured "
        "torques over --horizon seconds (semi-implicit Euler at the log step, Coulomb friction "
        "regularized as tanh(dq/eps)) and report per joint the RMS position and velocity "
        "errors at the horizon and the share of start points within --tolerance.",
    )
    add_robot_arguments(p)
    p.add_argument(
        "--model", metavar="RESULT.json", required=True, help="the identified model to roll out"
    )
    p.add_argument(
        "--data",
        metavar="FILE",
        nargs="+",
        action="extend",
        required=True,
        help="measurement files (formats and FILE@START:STOP windows as identify --data)",
    )
    p.add_argument("--horizon", type=float, default=0.25, help="seconds integrated [default 0.25]")
    p.add_argument(
        "--starts", type=int, default=200, help="most start points per file [default 200]"
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=0.01,
        help="position error [rad] within which a horizon counts as followed [default 0.01]",
    )
    p.add_argument(
        "--eps",
        type=float,
        default=0.01,
        help="smallest width of the Coulomb regularization tanh(dq/eps) [rad/s] "
        "[default 0.01; widened per joint where one step would overshoot]",
    )
    p.add_argument("--cutoff", type=float, default=None, help="low-pass cut-off [Hz] [default 3]")
    p.add_argument("--order", type=int, default=4, help="Butterworth order [default 4]")
    p.add_argument(
        "--trim",
        type=float,
        default=None,
        help="seconds dropped at each end [default: the filter's edge transient]",
    )
    p.add_argument("--json", metavar="OUT", help="write the rollout errors as JSON to OUT")
    p.add_argument(
        "--figure", metavar="OUT.png", help="measured vs simulated positions for 3 start points"
    )
    p.set_defaults(func=command("manip_id.cli._validate"))
