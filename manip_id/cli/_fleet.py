"""``manip-id identify --scheduler SPEC / --per-file``: many files, one task each, on Dask.

Each ``--data`` file (and each ``--block`` of one) is read, preprocessed and
accumulated by one task (:func:`manip_id.fleet.identify_files`), on a Dask
cluster with ``--scheduler`` (``local[:N]``, ``tcp://HOST:PORT`` or a
scheduler JSON file) or in this process without it; the client solves from
the summed information. ``--per-file`` adds each file's own estimate and
errors, from the same sums (JSON ``per_file``, and a report figure).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..errors import InputError
from ._common import explicit_workers

FLEET_METHODS = ("ols", "wls")


def add_scheduler_argument(parser, what: str) -> None:
    """``--scheduler SPEC`` (shared by the commands that accumulate on Dask); ``what``
    ends the help: what one task is and where the solve happens."""
    parser.add_argument(
        "--scheduler",
        metavar="SPEC",
        default=None,
        help="accumulate on Dask: local[:N] (a local cluster of N workers on 127.0.0.1, default "
        "2), tcp://HOST:PORT (a running scheduler) or SCHEDULER.json (its scheduler file); " + what,
    )


def check_scheduler(args: argparse.Namespace) -> None:
    """Refuse a malformed ``--scheduler`` before any work (nothing of Dask imported)."""
    if getattr(args, "scheduler", None) is not None:
        from ..execution import parse_scheduler

        parse_scheduler(args.scheduler)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The fleet options of ``manip-id identify``."""
    g = parser.add_argument_group("many files (Dask)")
    add_scheduler_argument(
        g, "each file is one task, the sums are added on the cluster and solved here (ols, wls)"
    )
    g.add_argument(
        "--per-file",
        action="store_true",
        help="also each file's own estimate and errors (JSON per_file, report figure)",
    )
    g.add_argument(
        "--block",
        type=int,
        default=None,
        metavar="SAMPLES",
        help="with --scheduler or --per-file: cut longer files into tasks of SAMPLES samples",
    )


def wanted(args: argparse.Namespace) -> bool:
    """Whether this run goes through :func:`manip_id.fleet.identify_files`."""
    return getattr(args, "scheduler", None) is not None or bool(getattr(args, "per_file", False))


def check(args: argparse.Namespace) -> None:
    """Refuse what the fleet path does not do, before any work."""
    if args.block is not None and not wanted(args):
        raise InputError("--block applies with --scheduler or --per-file")
    if not wanted(args):
        return
    opt = "--scheduler" if args.scheduler is not None else "--per-file"
    if args.simulate:
        raise InputError(f"{opt} works on --data files, not on --simulate")
    if args.method not in FLEET_METHODS:
        raise InputError(
            f"{opt} accumulates ols or wls; {args.method} runs in sample order on one process"
        )
    if args.split is not None:
        raise InputError(f"{opt} identifies whole files: give validation files with --validate")
    if explicit_workers(args) > 1:
        raise InputError("--workers forks local processes; with --scheduler use local:N")
    if args.block is not None and args.block < 1:
        raise InputError(f"--block must be >= 1 samples, got {args.block}")
    check_scheduler(args)


def run(args: argparse.Namespace, outputs, t_start: float) -> int:
    """The fleet branch of ``manip-id identify`` (after the outputs were reserved).

    The options, file specs and JSON file information are those of the
    multi-file path (:mod:`manip_id.cli._files`); the files are scanned and
    accumulated by the tasks (not here), and their quality summaries come back
    with the sums.
    """
    from types import SimpleNamespace

    from ..fleet import identify_files
    from ..identification import ModelOptions, PartitionOptions, RunOptions
    from . import _files
    from . import identify as cmd
    from ._common import profile_from_args, robot_from_args

    profile = profile_from_args(args)
    colmap = cmd._column_map(args.column)
    if colmap is None and profile is not None and profile.columns:
        colmap = dict(profile.columns)
    specs = _files._specs(args.data, args, colmap)
    vspecs = _files._specs(args.validate, args, colmap) if args.validate is not None else None
    robot = robot_from_args(args)
    options = _files._options(args, robot.nv, None if profile is None else profile.torque_scale)
    model = getattr(args, "model", "dynamic")
    if model != "dynamic" and options.cutoff is None:  # as the local path: q, dq filtered
        from dataclasses import replace

        from ..signals import DEFAULT_CUTOFF

        options = replace(options, cutoff=DEFAULT_CUTOFF)
    result = identify_files(
        robot,
        specs,
        method=args.method,
        options=options,
        validation=vspecs,
        run=RunOptions(scheduler=args.scheduler, chunk=args.chunk),
        partition=PartitionOptions(block=args.block, per_file=args.per_file),
        model=ModelOptions(model, window_length=getattr(args, "window_length", None)),
        **cmd._consistent_kwargs(args),
    )
    files: dict = result.files or {"train": [], "validation": None}
    for info in files["train"]:
        print(info.quality.text())
    for info in files["validation"] or []:
        print("validation " + info.quality.text())
    timings = {k: float(v) for k, v in result.timings.items()}
    timings["total"] = time.perf_counter() - t_start
    n_valid = None if vspecs is None else sum(f.n_samples for f in files["validation"])
    source = {"data": [s.label for s in specs], "scheduler": args.scheduler or "this process"}
    if vspecs is not None:
        source["validate"] = [s.label for s in vspecs]
    report = cmd._result_document(
        robot,
        result,
        SimpleNamespace(n_samples=result.n_samples),
        None if n_valid is None else SimpleNamespace(n_samples=n_valid),
        None,
        timings,
        args,
        source,
        files["train"][0].settings,
    )
    infos = files["train"] + (files["validation"] or [])
    scans = {f.spec: SimpleNamespace(quality=f.quality) for f in infos}
    _files._add_file_info(report, robot, specs, vspecs, scans, files, options, result)
    if args.per_file:
        report["per_file"] = [f.to_dict() for f in result.per_file or []]
    print(result.table())
    if model == "dynamic":
        print(cmd._summary(robot, report))
    else:  # as the local energy / momentum path reports them
        report.update(model=model, window_length=args.window_length)
        report["outputs"] = list(result.output_names)
        rel = report["relative_error"]
        shown = report if rel["per_joint_validation"] else {**report, "joints": report["outputs"]}
        text = cmd._summary(robot, shown)
        print(text.replace("relative torque error: train", "relative error: train"))
    if args.per_file:
        print(_per_file_table(result))
    if args.json:
        outputs.write_json(args.json, report)
    path = None
    if args.report is not None:
        path = _write_report(robot, result, report, args)
    if getattr(args, "export_urdf", None) or getattr(args, "export_mjcf", None):
        cmd._export(robot, result, args, outputs)
    outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
    cmd._exports_written(args)
    if path is not None:
        print(f"wrote the report to {path}/index.html")
    return 0


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


def _write_report(robot, result, report: dict, args):
    """Summary, parameter table, singular values and (``--per-file``) the per-file figure."""
    import numpy as np

    from ..viz import figures
    from ..viz.report import write_report

    files = report["source"]["data"]
    run_name = f"{robot.name}, {args.method}, {len(files)} files, {result.n_samples} samples"
    ra = result.rank_analysis
    figs = {
        "singular_values": lambda path: figures.singular_values(
            path,
            ra.singular_values_scaled,
            tolerance=ra.tolerance,
            rank=ra.rank,
            title=f"singular values of the pooled base regressor: {run_name}",
        )
    }
    solved = [f for f in (result.per_file or []) if f.result is not None and args.per_file]
    if solved:
        est = np.array([f.result.estimate for f in solved])
        std = np.array([f.result.std for f in solved])
        figs["per_file_parameters"] = lambda path: figures.per_file_parameters(
            path,
            est,
            std,
            pooled=result.estimate,
            names=result.names,
            files=[Path(f.path).name for f in solved],
            title=f"per-file parameters (+-1 std) relative to the pooled fit: {run_name}",
        )
    from .identify import report_parameter_rows, report_quality_rows, report_summary

    summary = {
        **report_summary(report, f"{len(files)} files"),
        "scheduler": report["source"]["scheduler"],
    }
    rows = report_parameter_rows(report)
    notes = list(report["warnings"]) + [
        f"{f.path}: not solvable alone ({f.error})"
        for f in (result.per_file or [])
        if f.result is None
    ]
    quality = report_quality_rows(report)
    return write_report(
        args.report_claim,
        title=f"manip-id identify: {run_name}",
        summary=summary,
        parameter_table=rows,
        figures=figs,
        json_result=report,
        notes=notes,
        force=args.force,
        tables={"Data quality": quality} if quality else None,
    )
