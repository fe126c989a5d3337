"""``manip-id rank``: base parameters and unidentifiable directions of a robot, or of data."""

from __future__ import annotations

from ._common import add_robot_arguments, command


def register(sub) -> None:
    p = sub.add_parser(
        "rank",
        help="rank analysis: base parameters and unidentifiable directions",
        description="Structural rank analysis of a robot's regressor (random states within the "
        "joint limits): rank, condition number, base parameters as expressions in "
        "parameter names, and the directions no data can identify. With --data, "
        "also what a dataset excites.",
    )
    add_robot_arguments(p)
    p.add_argument(
        "--data",
        default=None,
        metavar="FILE",
        help="dataset (.npz, .csv or the Panda log folder): analyse what it excites "
        "(accelerations are estimated by filtering when the file has no ddq)",
    )
    p.add_argument("--json", default=None, metavar="OUT", help="write the analysis as JSON")
    p.add_argument(
        "--report",
        default=None,
        metavar="DIR",
        help="write a report folder: result.json, the singular-value spectrum, the robot scene "
        "colored by identifiability (scene.html) and index.html",
    )
    p.add_argument("--force", action="store_true", help="replace a non-empty --report folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the random states (default 0)")
    p.add_argument(
        "--samples",
        type=int,
        default=None,
        help="number of random states (default: 20 rows per parameter, at least 100)",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=None,
        help="relative rank tolerance on the column-scaled singular values "
        "(default max(max(M, p) * eps, 1e-8))",
    )
    p.set_defaults(func=command("manip_id.cli._rank"))
