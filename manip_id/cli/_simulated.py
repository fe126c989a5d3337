"""``manip-id identify --simulate``: identification on a simulated excitation.

A random (or ``--optimize``-d) Fourier excitation of the robot, simulated with torque
noise relative to each joint's RMS torque. Least squares without a report, validation
file or preprocessing runs block by block (:class:`~manip_id.simulation.SimulationStream`,
memory O(N nv)); every other run simulates the whole record, then preprocesses and
identifies it as a log would be.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from ..datasets import check_robot, load_dataset
from ..errors import InputError
from ..execution import resolve_workers
from ..identification import RunOptions, identify
from ..identification.run_context import RunContext, raw_reference
from ..simulation import MeasurementNoise, SimulationStream, check_simulation_memory
from ..trajectories import DEFAULT_WF, DesignOptions, design_excitation, random_trajectory
from ..viz.report_document import ReportSamples
from ._common import (
    SIM_DEFAULTS,
    column_map,
    exports_wanted,
    finish,
    prepare,
    progress,
)
from ._runtime import (
    consistent_options,
    note_exports,
    print_result,
    print_warnings,
    robot_from_args,
    run_document,
    stage_export,
    write_outputs,
)


def excitation(robot, seed: int, *, optimize: bool = False):
    """The excitation of the simulating commands: a random (or D-optimal, rest-to-rest,
    :func:`~manip_id.trajectories.design_excitation`) Fourier trajectory of ``seed``,
    designed by the robot's profile (robots/NAME.toml ``[excitation]``), else with 5
    harmonics and a 10 s period."""
    design = {"harmonics": 5, **(robot.profile.excitation.design_kwargs() if robot.profile else {})}
    if optimize:
        period = 2 * math.pi / design.get("wf", DEFAULT_WF)  # [s]
        options = DesignOptions(
            harmonics=max(2, design["harmonics"]),
            margin=design.get("margin", 0.05),
            acceleration_limit=design.get("acceleration_limit"),
            seed=seed,
            starts=4,
            refine=1,
        )
        return design_excitation(robot, period, options=options).trajectory
    return random_trajectory(robot, seed=seed, **design)


def simulation_stream(robot, args: argparse.Namespace):
    """The simulated record of the ``--simulate`` options, as a block-wise stream, and
    the simulation's settings (duration, rate, noise, seed, period)."""
    opts = {
        k: (SIM_DEFAULTS[k] if getattr(args, k) is None else getattr(args, k)) for k in SIM_DEFAULTS
    }
    seed = int(opts["seed"])  # --seed is parsed as an int, its default is 0
    traj = excitation(robot, seed, optimize=args.optimize)
    opts["period"] = float(traj.period)  # [s] the excitation repeats after it
    stream = SimulationStream(
        robot,
        traj,
        duration=opts["duration"],
        rate=opts["rate"],
        noise=MeasurementNoise(tau=opts["noise"]),
        seed=seed,
    )
    return stream, opts


def simulate_record(robot, args: argparse.Namespace):
    """The simulated record of the ``--simulate`` options, whole (:class:`SimulatedData`)."""
    stream, opts = simulation_stream(robot, args)
    check_simulation_memory(robot, stream.n_samples)
    return stream.simulated_data(), opts


def _streams(args: argparse.Namespace) -> bool:
    """Whether ``--simulate`` runs block by block: least squares, nothing needing whole arrays."""
    return (
        args.method in ("ols", "wls")
        and args.report is None
        and args.validate is None
        and args.cutoff is None
        and args.trim is None
        and args.decimate == 1
    )


def _run_stream(robot, args, outputs, timings: dict, t_start: float) -> int:
    """``--simulate`` with least squares, the record simulated and accumulated in blocks.

    Memory O(N nv) for the noise-free torques (:class:`~manip_id.simulation.SimulationStream`)
    plus one block, instead of the whole record's arrays; same samples, same split
    (:meth:`~manip_id.datasets.Dataset.split`) and same estimate as the whole-array path.
    """
    t0 = time.perf_counter()
    stream, opts = simulation_stream(robot, args)
    stream.tau_true  # noqa: B018 (the noise-free torques, computed once)
    timings["simulate"] = time.perf_counter() - t0
    source: dict = {"simulated": opts}
    n = k = stream.n_samples
    if args.split is not None:  # as Dataset.split
        k = min(max(int(round(args.split * n)), 2), n - 2)
        source["split"] = args.split
    report_progress = progress(args, n)
    workers = resolve_workers(args.workers, k)

    def on_progress(done: int, total: int) -> None:  # serial: samples of k; workers: parts
        if report_progress is not None:
            report_progress(done, total if workers > 1 else k)

    train = stream.parts(workers, 0, k) if workers > 1 else stream.blocks(0, k)
    result = identify(
        robot,
        train,
        method=args.method,
        validation=stream.blocks(k, n) if k < n else None,
        run=RunOptions(chunk=args.chunk, workers=workers, progress=on_progress),
        uncertainty=args.uncertainty,
        consistent=consistent_options(args),
    )
    timings.update({name: float(v) for name, v in dict(result.timings).items()})
    timings["total"] = time.perf_counter() - t_start
    theta_true = np.asarray(stream.theta_true, dtype=float)
    ctx = RunContext(source, n_validation=n - k, theta_true=theta_true)
    result, report = run_document(robot, result, args, ctx, timings)
    print_result(report, args)
    print_warnings(report)
    note_exports(args, report)
    if args.json:
        outputs.write_json(args.json, report)
    if exports_wanted(args):
        stage_export(robot, result, args, outputs)
    return finish(args, outputs)


def run(args: argparse.Namespace, outputs, t_start: float) -> int:
    """``manip-id identify --simulate`` (after the outputs were reserved)."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    validation = None
    if args.validate is not None:  # read the file first: bad data fail before the robot loads
        if len(args.validate) > 1:
            raise InputError("--simulate takes one --validate file")
        validation = load_dataset(args.validate[0], columns=column_map(args.column))
    timings["load"] = time.perf_counter() - t0
    robot = robot_from_args(args)
    if robot.layout.needs_temperature:
        raise InputError(
            "--simulate simulates no temperature, which the temperature friction law needs: "
            "identify logs with a temp field (--data), or simulate with "
            "manip_id.simulation.simulate(..., thermal=ThermalOptions(...))"
        )
    if _streams(args):  # simulated least squares: block by block, bounded memory
        return _run_stream(robot, args, outputs, timings, t_start)
    t0 = time.perf_counter()
    sim, opts = simulate_record(robot, args)
    data, theta_true = sim.dataset, np.asarray(sim.theta_true, dtype=float)
    source: dict = {"simulated": opts}
    timings["simulate"] = time.perf_counter() - t0
    if validation is not None:
        check_robot(validation, robot)
        source["validate"] = str(args.validate)
    full = data
    if validation is None and args.split is not None:
        data, validation = data.split(args.split)
        source["split"] = args.split
    t0 = time.perf_counter()
    train = prepare(data, args, "training data")
    valid = None if validation is None else prepare(validation, args, "validation data")
    timings["preprocess"] = time.perf_counter() - t0
    result = identify(
        robot,
        (train.q, train.dq, train.ddq, train.tau),
        method=args.method,
        validation=None if valid is None else (valid.q, valid.dq, valid.ddq, valid.tau),
        run=RunOptions(
            chunk=args.chunk,
            workers=args.workers,
            progress=progress(args, train.n_samples + (0 if valid is None else valid.n_samples)),
        ),
        uncertainty=args.uncertainty,
        consistent=consistent_options(args),
    )
    timings.update({k: float(v) for k, v in dict(result.timings).items()})
    timings["total"] = time.perf_counter() - t_start
    n_valid = 0 if valid is None else int(valid.n_samples)
    settings = train.meta.get("preprocess")
    ctx = RunContext(source, n_validation=n_valid, settings=settings, theta_true=theta_true)
    result, _ = run_document(robot, result, args, ctx, timings)
    parts = [("train", train, data.t, data.tau)]
    if valid is not None and validation is not None:  # valid is validation preprocessed
        parts.append(("validation", valid, validation.t, validation.tau))
    raw = raw_reference(robot, result, parts, args.chunk)
    result, report = run_document(robot, result, args, ctx, timings, raw)
    print_result(report, args)
    return write_outputs(args, outputs, robot, result, report, ReportSamples(train, valid, full))
