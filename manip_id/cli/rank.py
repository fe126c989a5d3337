"""``manip-id rank``: base parameters and unidentifiable directions of a robot, or of data."""

from __future__ import annotations

import argparse

import numpy as np

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
    from ..identifiability import analyze_dataset, structural_analysis

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
        path = _write_report(robot, structural, data, dataset, out, args)
    outputs.publish()  # all outputs appear together, once all are complete
    if args.json is not None:
        print(f"\nwrote {args.json}")
    if args.report is not None:
        print(f"\nwrote the report to {path}/index.html")
    return 0


def _individually_identifiable(base) -> np.ndarray:
    """Per standard parameter: a base parameter on its own (independent, nothing regrouped in)."""
    flags = np.zeros(len(base.names), dtype=bool)
    alone = ~np.any(np.abs(base.K) > 0, axis=1) if base.K.size else np.ones(base.n_base, bool)
    flags[base.independent[alone]] = True
    return flags


def _write_report(robot, structural, data, dataset, out: dict, args):
    """Report folder of a rank analysis (see :func:`manip_id.viz.report.write_report`)."""
    from ..errors import InfeasibleTrajectoryError
    from ..viz import figures
    from ..viz.meshcat_scene import RobotScene, link_identifiability
    from ..viz.report import write_report

    figs = {
        "singular_values": lambda path: figures.singular_values(
            path,
            structural.singular_values_scaled,
            tolerance=structural.tolerance,
            rank=structural.rank,
            title=f"structural singular values of {robot.name}: {structural.n_rows} rows from "
            f"random states, rank {structural.rank} of {structural.n_parameters}",
        ),
    }
    notes = list(structural.notes)
    scene = RobotScene(robot, title=f"manip-id rank {robot.name}")
    if data is not None:
        figs["singular_values_data"] = lambda path: figures.singular_values(
            path,
            data.singular_values_scaled,
            tolerance=data.tolerance,
            rank=data.rank,
            title=f"singular values of the data's base regressor: {args.data}, "
            f"{data.n_rows} rows, rank {data.rank}",
        )
        try:
            scene.animate(dataset.t, dataset.q)
        except InfeasibleTrajectoryError as exc:
            notes.append(f"scene not animated: {exc}")
        if data.unexcited:
            notes.append(f"{len(data.unexcited)} identifiable directions the data do not excite")
    scene.add_inertia(robot.nominal_parameters, label="nominal")
    flags = _individually_identifiable(structural.base)
    ident = link_identifiability(robot, identifiable=flags)
    scene.color_by_identifiability(ident)
    notes += list(scene.notes)
    base = structural.base
    dependent = set(int(i) for i in base.dependent)
    rows = [
        {
            "parameter": name,
            "status": "base, alone"
            if flags[i]
            else ("unidentifiable / regrouped" if i in dependent else "base, regrouped"),
        }
        for i, name in enumerate(robot.parameter_names)
    ]
    summary = {
        "robot": robot.name,
        "standard parameters": structural.n_parameters,
        "base parameters (rank)": structural.rank,
        "identifiable on their own": int(flags.sum()),
        "condition number (scaled)": structural.condition_number_scaled,
        "rank tolerance": structural.tolerance,
    }
    if data is not None:
        summary["data"] = str(args.data)
        summary["data rank"] = data.rank
        summary["unexcited directions"] = len(data.unexcited)
    return write_report(
        args.report_claim,
        title=f"manip-id rank {robot.name}",
        summary=summary,
        parameter_table=rows,
        figures=figs,
        scene=scene,
        json_result=out,
        notes=notes,
        force=args.force,
    )


def _load_data(robot, path):
    """The dataset at ``path``, checked against ``robot``, with accelerations."""
    from ..datasets import check_robot, load_dataset

    dataset = load_dataset(path)
    check_robot(dataset, robot)
    if dataset.ddq is None:
        from ..signals import preprocess

        dataset = preprocess(dataset)
    return dataset
