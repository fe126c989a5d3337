"""``manip-id validate`` once it runs (the options are declared in :mod:`.validate`)."""

from __future__ import annotations

import argparse
import time

from ..errors import InputError
from ..identification import PreprocessOptions, load_result
from ..identification.rollout import RolloutOptions, read_logs, rollout_validation
from ..viz.rollout_figure import rollout_traces
from ._common import reserve_outputs
from ._runtime import robot_from_args

#: Joint terms a result names -> the friction law that enables them.
_LAWS = {"fv": "viscous", "fc": "coulomb", "fo": "offset"}


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    options = RolloutOptions(
        horizon=args.horizon, starts=args.starts, tolerance=args.tolerance, eps=args.eps
    )
    if args.figure is not None and not str(args.figure).lower().endswith(".png"):
        raise InputError(
            f"--figure writes a PNG: expected a name ending in .png, got {args.figure}"
        )
    outputs = reserve_outputs(args)
    if args.figure is not None:
        outputs.file(args.figure, "--figure")
    result = load_result(args.model)
    robot = robot_from_args(args, args.model)
    logs = read_logs(
        robot, args.data, PreprocessOptions(cutoff=args.cutoff, order=args.order, trim=args.trim)
    )
    report = rollout_validation(robot, result, logs, options=options)
    print(report.table())
    doc = {
        "robot": robot.name,
        "model": str(args.model),
        "data": list(args.data),
        "rollout": report.to_dict(),
        "timings": {"total": time.perf_counter() - t0},
    }
    if args.json is not None:
        outputs.write_json(args.json, doc)
    if args.figure is not None:
        title = f"rollout over {report.horizon:g} s: measured, identified, nominal"
        outputs.write(
            args.figure, lambda tmp: rollout_traces(tmp, report.traces, report.joints, title=title)
        )
    outputs.publish()
    for value in (args.json, args.figure):
        if value is not None:
            print(f"wrote {value}")
    return 0
