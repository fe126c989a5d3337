"""``manip-id identify --data FILE...``: log files through the library's one door.

The options become the library's option objects once (:func:`files_call`), one call of
:func:`manip_id.identification.identify` runs the file pipeline (pre-fit audit, scans,
temperature reference, ``--friction auto``, accumulation here, forked or on Dask,
per-file estimates; :mod:`manip_id.identification.file_run`), and the result is
rendered: its ``to_dict()`` is the JSON.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..identification import (
    FileOptions,
    ModelOptions,
    PartitionOptions,
    RunOptions,
    build_problem,
    solve,
)
from ..identification.file_run import collect
from ..identification.selection import SelectionOptions
from ..signals import DEFAULT_CUTOFF
from ..viz.report_document import ReportSamples
from . import _rollout
from ._common import (
    data_column_map,
    exports_wanted,
    file_specs,
    finish,
    fleet_wanted,
    identify_report,
    note_window,
    profile_from_args,
    progress,
)
from ._runtime import (
    consistent_options,
    note_exports,
    preprocess_options,
    print_result,
    print_warnings,
    report_options,
    robot_from_args,
    stage_export,
    write_outputs,
)


def files_call(args: argparse.Namespace):
    """The robot, the file specs and the keywords of
    :func:`~manip_id.identification.identify` for these options."""
    profile = profile_from_args(args)  # robots/ROBOT.toml [data]: defaults of the options
    colmap = data_column_map(args, profile)
    specs = file_specs(args.data, args, colmap)  # bad specs fail before the robot loads
    vspecs = file_specs(args.validate, args, colmap) if args.validate is not None else None
    robot = robot_from_args(args)
    options = preprocess_options(args, robot, None if profile is None else profile.torque_scale)
    fleet = fleet_wanted(args)
    if args.model != "dynamic" and options.cutoff is None:  # as the local path: q, dq filtered
        options = replace(options, cutoff=DEFAULT_CUTOFF)
    files = FileOptions(
        preprocess=options,
        audit=not fleet,
        trim_standstill=bool(getattr(args, "trim_standstill", False)),
        split=args.split,
        partition=PartitionOptions(block=args.block, per_file=args.per_file) if fleet else None,
        select_friction=SelectionOptions() if args.friction == "auto" else None,
        **_rollout.forward_options(args),
        **_rollout.closed_loop_options(args, robot.nv),
    )
    kwargs = dict(
        validation=vspecs,
        method="ols" if args.method in _rollout.CLOSED_LOOP else args.method,  # their start
        consistent=consistent_options(args),
        model=ModelOptions(args.model, window_length=args.window_length),
        run=RunOptions(
            chunk=args.chunk,
            workers=1 if fleet else args.workers,
            scheduler=args.scheduler,
            progress=progress(args),
            echo=print,
            verbose=bool(getattr(args, "verbose", False)),
        ),
        uncertainty=args.uncertainty,
        files=files,
    )
    return robot, specs, kwargs


def _per_file_table(result) -> str:
    lines = ["per file: samples, relative torque error (train), condition number"]
    w = max(len(Path(f.path).name) for f in result.per_file)
    for f in result.per_file:
        name = Path(f.path).name
        if f.result is None:
            lines.append(f"  {name:<{w}}  {f.n_samples:>9}  not solvable alone: {f.error}")
        else:
            r = f.result
            lines.append(
                f"  {name:<{w}}  {f.n_samples:>9}  {100 * r.relative_error.train:8.3f} %  "
                f"{r.condition_number:10.4g}"
            )
    return "\n".join(lines)


def _print_files(report: dict) -> None:
    """The deadband's left-out rows and the validation error per file, when there are any."""
    band = report.get("velocity_deadband")
    if band is not None:
        left = band["excluded_rows"]
        print(
            f"velocity deadband {band['eps']:g} rad/s: rows left out per joint: "
            + ", ".join(f"{j} {n}" for j, n in left.items())
        )
    per_file = report["relative_error"].get("validation_per_file")
    if per_file and len(per_file) > 1:
        print(
            "validation per file: "
            + ", ".join(f"{e['file']} {100 * (e['error'] or np.nan):.3f} %" for e in per_file)
        )


def run(args: argparse.Namespace, outputs, t_start: float) -> int:
    """``manip-id identify --data ...`` (after the outputs were reserved)."""
    robot, specs, kwargs = files_call(args)
    problem = build_problem(robot, specs, **kwargs)  # identify = build_problem + solve
    result = solve(problem)
    robot = problem.robot  # with the temperature reference and the chosen friction laws
    report = result.to_dict(
        poorly_identified=args.poorly_identified, condition_limit=args.condition_limit
    )
    if args.model != "dynamic":
        note_window(report, result, args.window_length)
    print_result(report, args)
    if fleet_wanted(args):
        return _finish_fleet(args, outputs, robot, result, report, len(specs))
    _print_files(report)
    samples = None
    if args.report is not None:  # the report draws the samples
        files = result.files or {}
        options = kwargs["files"].preprocess
        train_specs = [r.spec for r in files["train"]]
        vspecs = None if files.get("validation") is None else [r.spec for r in files["validation"]]
        train = collect(robot, train_specs, options, {})
        valid = None if vspecs is None else collect(robot, vspecs, options, {})
        samples = ReportSamples(train, valid, train)
    return write_outputs(args, outputs, robot, result, report, samples)


def _finish_fleet(args, outputs, robot, result, report: dict, n_files: int) -> int:
    """Per-file table, warnings, JSON, fleet report, exports."""
    if args.per_file:
        print(_per_file_table(result))
    print_warnings(report)
    note_exports(args, report)
    if args.json:
        outputs.write_json(args.json, report)
    path = None
    if args.report is not None:
        options = report_options(args, f"{n_files} files")
        path = identify_report("write_fleet_report")(
            args.report_claim, robot, result, report, options=options, per_file=args.per_file
        )
    if exports_wanted(args):
        stage_export(robot, result, args, outputs)
    return finish(args, outputs, path)
