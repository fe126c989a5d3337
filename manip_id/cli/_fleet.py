"""``manip-id identify --scheduler SPEC / --per-file``: many files, one task each, on Dask.

Each ``--data`` file (and each ``--block`` of one) is read, preprocessed and
accumulated by one task (:func:`manip_id.identification.fleet.identify_files`), on a Dask
cluster with ``--scheduler`` (``local[:N]``, ``tcp://HOST:PORT`` or a
scheduler JSON file) or in this process without it; the client solves from
the summed information. ``--per-file`` adds each file's own estimate and
errors, from the same sums (JSON ``per_file``, and a report figure).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

from ..identification import ModelOptions, PartitionOptions, RunOptions
from ..identification.fleet import identify_files
from ..identification.temperature import reference_from_files
from ..signals import DEFAULT_CUTOFF
from ..viz.report_document import RunContext, add_file_info, result_document
from ._common import (
    data_column_map,
    exports_wanted,
    file_specs,
    finish,
    identify_report,
    note_window,
    profile_from_args,
)
from ._runtime import (
    consistent_kwargs,
    note_exports,
    preprocess_options,
    print_result,
    print_warnings,
    report_options,
    robot_from_args,
    stage_export,
)


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


def _identify(args: argparse.Namespace):
    """The robot, the specs, the options and the pooled result of the files."""
    profile = profile_from_args(args)
    colmap = data_column_map(args, profile)
    specs = file_specs(args.data, args, colmap)
    vspecs = file_specs(args.validate, args, colmap) if args.validate is not None else None
    robot = robot_from_args(args)
    options = preprocess_options(args, robot.nv, None if profile is None else profile.torque_scale)
    model = getattr(args, "model", "dynamic")
    if model != "dynamic" and options.cutoff is None:  # as the local path: q, dq filtered
        options = replace(options, cutoff=DEFAULT_CUTOFF)
    robot, _, made = reference_from_files(robot, specs, vspecs, options)  # the law's T0
    for scan in made:
        scan.discard()
    result = identify_files(
        robot,
        specs,
        method=args.method,
        options=options,
        validation=vspecs,
        run=RunOptions(scheduler=args.scheduler, chunk=args.chunk),
        partition=PartitionOptions(block=args.block, per_file=args.per_file),
        model=ModelOptions(model, window_length=getattr(args, "window_length", None)),
        uncertainty=args.uncertainty,
        **consistent_kwargs(args),
    )
    return SimpleNamespace(robot=robot, specs=specs, vspecs=vspecs, options=options), result


def run(args: argparse.Namespace, outputs, t_start: float) -> int:
    """The fleet branch of ``manip-id identify`` (after the outputs were reserved).

    The options, file specs and JSON file information are those of the multi-file
    path; the files are scanned and accumulated by the tasks (not here), and their
    quality summaries come back with the sums.
    """
    run_, result = _identify(args)
    robot, specs, vspecs = run_.robot, run_.specs, run_.vspecs
    files: dict = result.files or {"train": [], "validation": None}
    for info in files["train"]:
        print(info.quality.text())
    for info in files["validation"] or []:
        print("validation " + info.quality.text())
    timings = {k: float(v) for k, v in result.timings.items()}
    timings["total"] = time.perf_counter() - t_start
    n_valid = 0 if vspecs is None else sum(f.n_samples for f in files["validation"])
    source = {"data": [s.label for s in specs], "scheduler": args.scheduler or "this process"}
    if vspecs is not None:
        source["validate"] = [s.label for s in vspecs]
    ctx = RunContext(
        method=args.method,
        source=source,
        n_validation=n_valid,
        settings=files["train"][0].settings,
        timings=timings,
        poorly_identified=getattr(args, "poorly_identified", None),
        condition_limit=getattr(args, "condition_limit", None),
    )
    report = result_document(robot, result, ctx)
    infos = files["train"] + (files["validation"] or [])
    scans = {f.spec: SimpleNamespace(quality=f.quality) for f in infos}
    add_file_info(report, robot, specs, vspecs, scans, files, run_.options, result)
    if args.per_file:
        report["per_file"] = [f.to_dict() for f in result.per_file or []]
    model = getattr(args, "model", "dynamic")
    if model != "dynamic":  # as the local energy / momentum path reports them
        report["model"] = model
        note_window(report, result, args.window_length)
        report["outputs"] = list(result.output_names)
    print_result(report, args)
    if args.per_file:
        print(_per_file_table(result))
    print_warnings(report)
    note_exports(args, report)
    if args.json:
        outputs.write_json(args.json, report)
    path = None
    if args.report is not None:
        options = report_options(args, f"{len(specs)} files")
        path = identify_report("write_fleet_report")(
            args.report_claim, robot, result, report, options=options, per_file=args.per_file
        )
    if exports_wanted(args):
        stage_export(robot, result, args, outputs)
    return finish(args, outputs, path)
