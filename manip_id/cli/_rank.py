"""``manip-id rank`` once it runs: the structural and data rank analyses, printed, saved
and reported (the options are declared in :mod:`.rank`).
"""

from __future__ import annotations

import argparse

from ..datasets import check_robot, load_dataset
from ..identifiability import analyze_dataset, structural_analysis
from ..signals import preprocess
from ..viz.rank_report import write_rank_report
from ._common import reserve_outputs
from ._runtime import robot_from_args


def run(args: argparse.Namespace) -> int:
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
