"""``manip-id rank``: base parameters and unidentifiable directions of a robot, or of data."""

from __future__ import annotations

import argparse

from ..datasets import check_robot, load_dataset
from ..signals import preprocess
from ._common import add_robot_arguments, reserve_outputs, robot_from_args


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
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..identifiability import analyze_dataset, structural_analysis  # pinocchio: heavy

    outputs = reserve_outputs(args)  # every output checked (and the report claimed) first
    robot = robot_from_args(args)
    dataset = _load_data(robot, args.data) if args.data is not None else None
    structural = structural_analysis(
        robot, seed=args.seed, n_samples=args.samples, tolerance=args.tolerance
    )
    print(structural.report())
    out = {"robot": robot.name, **structural.to_dict()}
    data = None
    if dataset is not None:
        data = analyze_dataset(robot, dataset, structural=structural, tolerance=args.tolerance)
        print()
        print(data.report(details=False))
        out["data"] = {"file": str(args.data), **data.to_dict()}
    if args.json is not None:
        outputs.write_json(args.json, out)
    if args.report is not None:
        from ..viz.rank_report import write_rank_report  # matplotlib, meshcat: heavy

        path = write_rank_report(
            args.report_claim, robot, structural, out, data=data, dataset=dataset, force=args.force
        )
    outputs.publish()  # all outputs appear together, once all are complete
    if args.json is not None:
        print(f"\nwrote {args.json}")
    if args.report is not None:
        print(f"\nwrote the report to {path}/index.html")
    return 0


def _load_data(robot, path):
    """The dataset at ``path``, checked against ``robot``, with accelerations."""
    dataset = load_dataset(path)
    check_robot(dataset, robot)
    if dataset.ddq is None:
        dataset = preprocess(dataset)
    return dataset
