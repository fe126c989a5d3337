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

FLEET_METHODS = ("ols", "wls")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The fleet options of ``manip-id identify``."""
    g = parser.add_argument_group("many files (Dask)")
    g.add_argument(
        "--scheduler",
        metavar="SPEC",
        default=None,
        help="accumulate on Dask: local[:N] (a local cluster of N workers on 127.0.0.1, default "
        "2), tcp://HOST:PORT (a running scheduler) or SCHEDULER.json (its scheduler file); each "
        "file is one task, the sums are added on the cluster and solved here (ols, wls)",
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
    if args.workers > 1:
        raise InputError("--workers forks local processes; with --scheduler use local:N")
    if args.block is not None and args.block < 1:
        raise InputError(f"--block must be >= 1 samples, got {args.block}")
    if args.scheduler is not None:
        from ..fleet import parse_scheduler

        parse_scheduler(args.scheduler)


def _files(value) -> list[str] | None:
    if value is None:
        return None
    return [str(v) for v in value] if isinstance(value, (list, tuple)) else [str(value)]


def _options(args):
    """The :class:`~manip_id.pipeline.PreprocessOptions` of the command's options.

    Files without ddq are preprocessed (default cut-off), the others used as
    they are unless a filtering option was given; the real-log options
    (torque scale, velocity deadband, bad rows) are taken when the command has them.
    """
    from ..pipeline import PreprocessOptions

    extra = {}
    for name in ("velocity_deadband", "drop_bad_rows"):
        value = getattr(args, name, None)
        if value is not None:
            extra[name] = value
    scale = getattr(args, "torque_scale", None)
    if isinstance(scale, str):
        try:
            scale = tuple(float(g) for g in scale.split(","))
        except ValueError as exc:
            raise InputError(f"--torque-scale expects G or G1,...,Gn, got {scale!r}") from exc
    if scale is not None:
        extra["torque_scale"] = scale[0] if len(scale) == 1 else scale
    return PreprocessOptions(
        cutoff=args.cutoff, order=args.order, trim=args.trim, decimate=args.decimate, **extra
    )


def _specs(args, files):
    """File specs of ``files`` with the command's window, CSV column map and bag topic."""
    from ..datasets import parse_file_spec
    from . import identify as cmd

    if files is None:
        return None
    kwargs = {"columns": cmd._column_map(args.column)}
    if getattr(args, "topic", None) is not None:
        kwargs["topic"] = args.topic
    return [parse_file_spec(f, window=getattr(args, "window", None), **kwargs) for f in files]


class _Count:
    def __init__(self, n: int):
        self.n_samples = n


def run(args: argparse.Namespace, outputs, t_start: float) -> int:
    """The fleet branch of ``manip-id identify`` (after the outputs were reserved)."""
    from ..fleet import identify_files
    from . import identify as cmd
    from ._common import robot_from_args

    files, vfiles = _specs(args, _files(args.data)), _specs(args, _files(args.validate))
    opts = _options(args)
    robot = robot_from_args(args)
    result = identify_files(
        robot,
        files,
        scheduler=args.scheduler,
        method=args.method,
        per_file=True,  # the file summaries; the estimates are shown with --per-file
        block=args.block,
        options=opts,
        validation=vfiles,
        chunk=args.chunk,
    )
    timings = {k: float(v) for k, v in result.timings.items()}
    timings["total"] = time.perf_counter() - t_start
    per_vfile = result.relative_error.validation_per_file
    valid = None if per_vfile is None else _Count(sum(e["n_samples"] for e in per_vfile))
    source = {"data": [f.label for f in files], "scheduler": args.scheduler or "this process"}
    if vfiles is not None:
        source["validate"] = [f.label for f in vfiles]
    report = cmd._report(robot, result, None, valid, None, timings, args, source, None)
    report["preprocess"] = opts.to_dict()
    if per_vfile is not None:
        report["relative_error"]["validation_per_file"] = per_vfile
    report["files"] = [f.summary for f in result.per_file]
    if args.per_file:
        report["per_file"] = [f.to_dict() for f in result.per_file]
    print(result.table())
    print(cmd._summary(robot, report))
    if args.per_file:
        print(_per_file_table(result))
    if args.json:
        outputs.write_json(args.json, report)
    path = None
    if args.report is not None:
        path = _write_report(robot, result, report, args)
    outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
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
    rel = report["relative_error"]
    summary = {
        "robot": robot.name,
        "method": args.method,
        "files": len(files),
        "scheduler": report["source"]["scheduler"],
        "training samples": report["n_samples"],
        "validation samples": report["n_validation_samples"],
        "base parameters": f"{report['n_base']} of {report['n_parameters']}",
        "condition number": report["condition_number"],
        "relative torque error (train)": rel["train"],
        "relative torque error (validation)": rel["validation"],
    }
    rows = [
        {
            "name": p["name"],
            "expression": p["expression"],
            "value": p["value"],
            "std": p["std"],
            "std [%]": p["std_percent"],
        }
        for p in report["base_parameters"]
    ]
    notes = [
        f"{f.path}: not solvable alone ({f.error})"
        for f in (result.per_file or [])
        if f.result is None
    ]
    return write_report(
        args.report_claim,
        title=f"manip-id identify: {run_name}",
        summary=summary,
        parameter_table=rows,
        figures=figs,
        json_result=report,
        notes=notes,
        force=args.force,
    )
