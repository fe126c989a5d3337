"""``manip-id identify --model energy|momentum``: identification without accelerations.

One file or a simulation, whole: q and dq resampled and filtered, tau left raw (the
models integrate it: the energy model over intervals of ``--window-length`` seconds, the
momentum model through a first-order filter of bandwidth ``3 / --window-length`` rad/s).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from ..datasets import check_robot, load_dataset
from ..errors import InputError
from ..identification import ModelOptions, RunOptions, identify
from ..identification.run_context import RunContext
from ..signals import DEFAULT_CUTOFF, preprocess
from ..viz.report_document import ReportSamples
from ._common import column_map, explicit_workers, fleet_wanted, note_window, prepare
from ._runtime import (
    consistent_options,
    print_result,
    robot_from_args,
    run_document,
    write_outputs,
)
from ._simulated import simulate_record


def _check(args: argparse.Namespace) -> None:
    if explicit_workers(args) > 1 or fleet_wanted(args):
        raise InputError(f"--model {args.model} runs in one process (no --workers, --scheduler)")
    if args.data is not None and len(args.data) > 1:
        raise InputError(f"--model {args.model} takes one --data file, got {len(args.data)}")
    if args.validate is not None and len(args.validate) > 1:
        raise InputError(f"--model {args.model} takes one --validate file")
    if args.window_length is not None and not (
        math.isfinite(args.window_length) and args.window_length > 0
    ):
        raise InputError(f"--window-length must be a positive time [s], got {args.window_length}")


def _load(args: argparse.Namespace, timings: dict):
    """The robot, the record, its validation part, the source and a simulation's truth."""
    t0 = time.perf_counter()
    columns = column_map(args.column)
    data = None if args.simulate else load_dataset(args.data[0], columns=columns)
    validation = None if args.validate is None else load_dataset(args.validate[0], columns=columns)
    timings["load"] = time.perf_counter() - t0
    robot = robot_from_args(args)
    theta_true = None
    if data is None:  # --simulate
        sim, opts = simulate_record(robot, args)
        data, theta_true = sim.dataset, np.asarray(sim.theta_true, dtype=float)
        source: dict = {"simulated": opts}
    else:
        check_robot(data, robot)
        source = {"data": str(args.data[0])}
    if validation is not None:
        check_robot(validation, robot)
        source["validate"] = str(args.validate[0])
    return robot, data, validation, source, theta_true


def _prepare_train(data, args: argparse.Namespace):
    """Training samples: resampled, q and dq filtered; tau left raw (the models integrate it)."""
    if args.simulate and args.cutoff is None and args.decimate == 1 and args.trim is None:
        return data  # uniform and noise on tau only: nothing to filter
    cutoff = DEFAULT_CUTOFF if args.cutoff is None else args.cutoff
    try:
        return preprocess(
            data,
            cutoff=cutoff,
            order=args.order,
            decimate=args.decimate,
            trim=args.trim,
            filter_torque=False,
        )
    except InputError as exc:
        raise InputError(f"training data: {exc}") from exc


def _uniform_step(t, model: str) -> float:
    """The sampling step [s] of uniform samples (the models need them)."""
    steps = np.diff(t)
    dt = float(np.mean(steps))
    if np.ptp(steps) > 1e-6 * dt:
        raise InputError(
            f"--model {model} needs uniform samples; steps range over "
            f"[{steps.min():g}, {steps.max():g}] s (give --cutoff to resample)"
        )
    return dt


def run(args: argparse.Namespace, outputs, t_start: float) -> int:
    """``manip-id identify --model energy|momentum`` (after the outputs were reserved)."""
    _check(args)
    timings: dict[str, float] = {}
    robot, data, validation, source, theta_true = _load(args, timings)
    full = data
    if validation is None and args.split is not None:
        data, validation = data.split(args.split)
        source["split"] = args.split
    t0 = time.perf_counter()
    train = _prepare_train(data, args)
    valid = None if validation is None else prepare(validation, args, "validation data")
    timings["preprocess"] = time.perf_counter() - t0
    result = identify(
        robot,
        (train.q, train.dq, None, train.tau),
        method=args.method,
        validation=None if valid is None else (valid.q, valid.dq, valid.ddq, valid.tau),
        run=RunOptions(chunk=args.chunk),
        model=ModelOptions(
            args.model, window_length=args.window_length, dt=_uniform_step(train.t, args.model)
        ),
        uncertainty=args.uncertainty,
        consistent=consistent_options(args),
    )
    timings.update({k: float(v) for k, v in dict(result.timings).items()})
    timings["total"] = time.perf_counter() - t_start
    ctx = RunContext(
        source=source,
        n_validation=0 if valid is None else int(valid.n_samples),
        settings=train.meta.get("preprocess"),
        theta_true=theta_true,
    )
    result, report = run_document(robot, result, args, ctx, timings)
    report["model"] = args.model
    note_window(report, result, args.window_length)
    report["outputs"] = list(result.output_names)
    print_result(report, args)
    return write_outputs(args, outputs, robot, result, report, ReportSamples(train, valid, full))
