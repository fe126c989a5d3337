"""``manip-id monitor`` once it runs (the options are declared in :mod:`.monitor`)."""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from .._io import OutputSet
from .._native import native_stderr_captured
from ..errors import InputError
from ..monitor import (  # the package loads with the command, not with --help
    DEFAULT_FILTER_GAIN,
    DEFAULT_GAIN,
    CollisionMonitor,
    ReadOptions,
    as_logs,
    calibrate_thresholds,
    check_temperatures,
    load_model,
    load_thresholds,
    model_from_robot,
)
from ..robot.model import load_robot
from ..viz.monitor_report import write_monitor_report
from ._common import (
    reserve_outputs,
)
from ._runtime import (
    robot_from_args,
)


def _floats(text, what: str, *, none: bool = False):
    if text is None:
        return None
    if none and str(text).strip().lower() == "none":
        return "none"
    try:
        vals = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{what} expects numbers separated by commas, got {text!r}") from None
    if not vals:
        raise InputError(f"{what} expects at least one number, got {text!r}")
    return vals[0] if len(vals) == 1 else np.asarray(vals)


def _columns(items: list[str]):
    """``["t=stamp", "q=pos*", "tau=3,4,5"]`` -> a column map, as ``identify --column`` reads
    it (a copy of its private helper: the cli package has no public one yet)."""
    if not items:
        return None
    out: dict = {}
    for spec in items:
        field, sep, cols = spec.partition("=")
        if not sep or not field.strip() or not cols.strip():
            raise InputError(f"--column expects FIELD=COLUMNS, e.g. q='pos*', got {spec!r}")
        names = [c.strip() for c in cols.split(",") if c.strip()]
        vals: list[int | str] = [int(c) if c.lstrip("-").isdigit() else c for c in names]
        field = field.strip()
        out[field] = vals if field == "joint_names" or len(vals) > 1 else vals[0]
    return out


def _reserve(args):
    """The outputs, checked against every input (the --calibrate and --model files too)."""
    if getattr(args, "outputs", None) is None:
        args.outputs = OutputSet()
    files = [*(args.calibrate or []), *args.data, args.model, args.thresholds]
    args.outputs.add_inputs(
        f if os.path.exists(f) or "@" not in f else f.rsplit("@", 1)[0] for f in files if f
    )
    return reserve_outputs(args)


def _robot(args):
    if not args.identified:
        return robot_from_args(args, args.model)

    with native_stderr_captured("urdfdom"):
        return load_robot(args.robot, identified=True, package_dirs=args.package_dir)


def run(args: argparse.Namespace) -> int:

    t_start = time.perf_counter()
    gain = _floats(args.gain, "--gain")
    fgain = _floats(args.filter_gain, "--filter-gain", none=True)
    if args.thresholds is not None and (gain is not None or fgain is not None):
        raise InputError("--thresholds carry the observer gains they hold for: no --gain then")
    gain = DEFAULT_GAIN if gain is None else gain
    fgain = DEFAULT_FILTER_GAIN if fgain is None else (None if fgain == "none" else fgain)
    scale = _floats(args.torque_scale, "--torque-scale")
    options = ReadOptions(
        torque_scale=None if scale is None else tuple(np.atleast_1d(scale).tolist()),
        drop_bad_rows=args.drop_bad_rows,
        window=args.window,
        columns=_columns(args.column),
        topic=args.topic,
    )
    outputs = _reserve(args)
    robot = _robot(args)
    if args.model is None and not args.identified:
        raise InputError(
            "give the identified model: --model RESULT.json, or an exported URDF as ROBOT "
            "with --identified"
        )
    model = load_model(robot, args.model) if args.model else model_from_robot(robot)
    saved = None if args.thresholds is None else load_thresholds(args.thresholds)  # small: first
    calib = None if saved is not None else as_logs(robot, args.calibrate, options)
    logs = as_logs(robot, args.data, options)
    check_temperatures([*(calib or []), *logs], robot.layout.needs_temperature)  # before work
    if saved is not None:
        th = saved
        gain, fgain = th.gain, th.filter_gain
    else:
        th = calibrate_thresholds(
            robot, model, calib, false_alarm=args.false_alarm, gain=gain, filter_gain=fgain
        )
    mon = CollisionMonitor(robot, model, th, gain=gain, filter_gain=fgain)
    runs = [mon.run(lg.t, lg.q, lg.dq, lg.tau, file=lg.file, temp=lg.temp) for lg in logs]
    detections = [d for run in runs for d in run.detections()]
    doc = {
        "robot": robot.name,
        "model": model.source,
        "thresholds": th.to_dict(),
        "detections": [d.to_dict() for d in detections],
        "files": [_file_summary(run) for run in runs],
        "timings": {"total": time.perf_counter() - t_start},
    }
    print(_summary(th, runs, detections))
    if args.json is not None:
        outputs.write_json(args.json, doc)
    if args.report is not None:
        write_monitor_report(args.report_claim, robot, th, runs, detections, doc, force=args.force)
    outputs.publish()
    if args.json is not None:
        print(f"wrote {args.json}")
    if args.report is not None:
        print(f"wrote the report to {args.report}/index.html")
    return 0


def _file_summary(run) -> dict:
    """The JSON ``files[i]`` of one monitored run: samples, alarm rates, detections, peaks."""
    return {
        "file": run.file,
        "n_samples": int(run.t.size),
        "alarm_rate": run.alarm_rate,
        "alarm_rate_per_joint": dict(
            zip(run.dof_names, run.alarm_rate_per_joint.tolist(), strict=True)
        ),
        "n_detections": len(run.detections()),
        "max_residual": dict(
            zip(run.dof_names, np.abs(run.residual).max(axis=0).tolist(), strict=True)
        ),
    }


def _summary(th, runs, detections) -> str:
    lines = [
        f"bounds at a false-alarm rate {th.false_alarm:g} per sample ({th.n_samples} "
        f"calibration samples, measured rate there {th.rate:.3g}):",
        "  "
        + ", ".join(
            f"{n} {b:.3g} N m" for n, b in zip(th.dof_names, th.bound.tolist(), strict=True)
        ),
    ]
    for run in runs:
        n = sum(1 for d in detections if d.file == run.file)
        lines.append(f"{run.file}: {n} detection(s), alarm rate {run.alarm_rate:.3g}")
    for d in detections:
        lines.append(
            f"  {d.start:.4f} .. {d.stop:.4f} s: {', '.join(d.joints)} "
            f"(peak {d.peak:.3g} N m on {d.peak_joint})"
        )
    return "\n".join(lines)
