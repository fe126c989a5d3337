"""In-memory data -> a problem: arrays, datasets, blocks and parts (the rows of :func:`solve`).

For N samples ``(q, dq, ddq, tau)`` (or blocks of them) the base-regressor rows are
accumulated (:mod:`~manip_id.identification.problem`: serially, in forked parts, or
as Dask tasks), or one pass of an online law runs over them in order; the energy and
momentum models (:mod:`manip_id.models`) replace ``ddq`` by integrals of the data.
Every path ends in the same :func:`~manip_id.identification.solve`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..estimators import GradientEstimator, RLSEstimator
from ..estimators.consistent.terms import missing_term_warnings
from ..execution import AUTO, available_cores, open_backend, portable_robot, reduce_tree
from ..identifiability import BaseParameters
from ..models import (
    WindowChoice,
    accumulate_energy,
    accumulate_momentum,
    choose_window,
    window_samples,
)
from ..robot.compiled_regressor import planned_samples
from ..robot.model import Robot
from ..robot.regressor import check_states, check_temperature, iter_regressor
from .data_sources import Blocks, Parts, Samples
from .options import (
    ONLINE,
    ModelOptions,
    OnlineOptions,
    RunOptions,
    SolveSettings,
    UncertaintyOptions,
    check_least_squares,
    check_method,
)
from .problem import (
    OnlineRun,
    Problem,
    accumulate_arrays,
    accumulate_blocks,
    accumulate_forked,
    array_part,
    check_equations,
    check_samples,
    check_tau,
    resolve_base,
    validation_blocks,
)
from .result import IdentificationResult
from .tasks import PartSums, blocks_sums
from .temperature import note_reference, reference_from_arrays


def online_estimator(method: str, r: int, options: OnlineOptions, n: int):
    """The online law of ``method`` over ``n`` samples, and a text naming it."""
    options.check_method(method)
    theta0 = np.zeros(r) if options.theta0 is None else options.theta0
    record = max(1, n // 1000) if options.record_every is None else options.record_every
    common = dict(bounds=options.bounds, record_every=record, t0=options.t0)
    if method == "rls":
        P0 = 1e6 if options.P0 is None else options.P0
        forgetting = 1.0 if options.forgetting is None else options.forgetting
        est = RLSEstimator(
            theta0, P0, forgetting=forgetting, p_min=options.p_min, p_max=options.p_max, **common
        )
        what = f"RLS (P0={P0 if np.ndim(P0) == 0 else 'given'}, forgetting {est.forgetting:g})"
    else:
        gamma = 1.0 if options.gamma is None else options.gamma
        normalized = True if options.normalized is None else options.normalized
        est = GradientEstimator(theta0, gamma, normalized=normalized, **common)
        what = ("normalized " if normalized else "") + "gradient law"
    return est, what


def samples_problem(
    robot: Robot,
    samples: Samples,
    validation,
    base: BaseParameters | None,
    settings: SolveSettings,
    opts: CallOptions,
) -> Problem:
    """The problem of N samples in memory (``validation``: a tuple ``(q, dq, ddq, tau[,
    temp])`` or None). ``samples.temp``: the measured temperature of the ``temperature``
    law, (N, nv) or (N, 1), or None: when the robot's reference ``T0`` is unset it becomes
    the mean of ``temp`` per joint (:mod:`~manip_id.identification.temperature`, recorded
    in ``context["friction_shapes"]`` by a post-step)."""
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    method = settings.method
    check_method(method)
    if opts.model.name != "dynamic":
        return _free_problem(robot, samples, validation, base, settings, opts)
    if samples.ddq is None:
        raise InputError(
            "the data have no accelerations (ddq): estimate them first (manip_id.signals) "
            "or use the energy or momentum model"
        )
    q, dq, ddq, tau = check_samples(robot, samples.q, samples.dq, samples.ddq, samples.tau)
    robot = reference_from_arrays(robot, samples.temp)  # the temperature law's T0
    temp = check_temperature(robot, samples.temp, dq) if robot.layout.needs_temperature else None
    n = q.shape[0]
    blocks = validation_blocks(robot, validation)
    timings["checks"] = time.perf_counter() - t_start
    base = resolve_base(robot, base, timings)
    ind, r = base.independent, base.n_base
    check_equations(n * robot.nv, r, f"{n} samples")
    run_o, online_options = opts.run, opts.online
    dt = 1.0 if online_options.dt is None else float(online_options.dt)
    online_run = None
    if method in ONLINE:
        est, what = online_estimator(method, r, online_options, n)
        states = (q, dq, ddq, tau, temp)
        acc, times = accumulate_online(
            robot, states, ind, est, dt, run=run_o, uncertainty=settings.uncertainty
        )
        online_run = OnlineRun(est, what)
    else:
        acc, times = accumulate_arrays(
            robot, q, dq, ddq, tau, ind, run=run_o, uncertainty=settings.uncertainty, temp=temp
        )
    timings.update(times)
    problem = Problem(
        robot,
        base,
        acc,
        n,
        timings,
        t_start,
        validation_blocks=blocks,
        online=online_run,
        chunk=run_o.chunk,
        settings=settings,
    )
    train = next(array_part(q, dq, ddq, tau, 0, n, temp))

    def terms(result: IdentificationResult) -> IdentificationResult:
        # an implausible consistent fit: would a joint term the model lacks lower the error?
        result.warnings.extend(
            missing_term_warnings(robot, result.standard, [train], blocks, ind, run_o.chunk)
        )
        return note_reference(result, robot)  # the T0 the coefficients fvt, fct refer to

    problem.post.append(terms)
    return problem


def accumulate_online(
    robot: Robot,
    states: tuple,
    ind,
    est,
    dt: float,
    *,
    run: RunOptions,
    uncertainty: UncertaintyOptions | None = None,
):
    """One pass of the online law ``est`` over the samples ``states = (q, dq, ddq, tau,
    temp)`` in order (Euler step ``dt`` [s]; ``temp`` the temperature (N, nv) or None),
    with the information accumulated in the same pass (for the covariance and the errors,
    with the per-block sums of ``uncertainty``); ``run.chunk``, ``run.progress(done,
    total)``."""
    q, dq, ddq, tau, temp = states
    n, nv, chunk, progress = q.shape[0], robot.nv, run.chunk, run.progress
    acc = UncertaintyOptions.from_value(uncertainty).accumulator(len(ind), nv)
    t_reg = t_acc = t_onl = 0.0
    t0 = time.perf_counter()
    for c in iter_regressor(robot, q, dq, ddq, chunk=chunk, temp=temp):
        t1 = time.perf_counter()
        t_reg += t1 - t0
        Yb = np.ascontiguousarray(c.Y[:, :, ind])
        acc.add(Yb, tau[c.start : c.stop], check=False)
        t2 = time.perf_counter()
        t_acc += t2 - t1
        step = est.step
        for i in range(c.stop - c.start):
            step(Yb[i], tau[c.start + i], dt)
        t_onl += time.perf_counter() - t2
        if progress is not None:
            progress(c.stop, n)
        t0 = time.perf_counter()
    return acc, {"regressor": t_reg, "accumulate": t_acc, "online": t_onl}


@dataclass(frozen=True)
class CallOptions:
    """The option objects of one call that shape the problem (not the solve's).

    Attributes
    ----------
    model : ModelOptions
        "dynamic", "energy" or "momentum".
    online : OnlineOptions
        The online law's options (``rls``, ``gradient``).
    run : RunOptions
        Chunk, workers, scheduler, progress.
    """

    model: ModelOptions = field(default_factory=ModelOptions)
    online: OnlineOptions = field(default_factory=OnlineOptions)
    run: RunOptions = field(default_factory=RunOptions)


def _free_problem(
    robot: Robot, samples: Samples, validation, base, settings: SolveSettings, opts: CallOptions
) -> Problem:
    """The energy / momentum problem: their rows (``dt`` the model's, else the data's mean
    sample time, else 1 s), the usual solve."""
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    model = opts.model
    check_least_squares(settings.method, f"the {model.name} model is solved by")
    q, dq, tau = samples.q, samples.dq, samples.tau
    batched, (q, dq) = check_states(robot, q=q, dq=dq)
    if not batched:
        raise InputError(f"identification takes N samples (2-D arrays), got q.shape={q.shape}")
    tau = check_tau(robot, tau, q.shape[0])
    blocks = validation_blocks(robot, validation)
    timings["checks"] = time.perf_counter() - t_start
    base = resolve_base(robot, base, timings)
    t0 = time.perf_counter()
    accumulate = accumulate_energy if model.name == "energy" else accumulate_momentum
    dt = float(model.dt if model.dt is not None else samples.dt or 1.0)
    nv_rows = 1 if model.name == "energy" else robot.nv
    unc = settings.uncertainty or UncertaintyOptions()
    rows_unc = replace(unc, block_length=1)  # rows span windows: start at one
    window = model_window(model, q.shape[0], dt, base.n_base, robot.nv)
    with planned_samples(q.shape[0]):  # one regressor path for the run, as for files
        acc = accumulate(
            robot,
            q,
            dq,
            tau,
            dt=dt,
            window_length=window.length,
            columns=base.independent,
            blocks=rows_unc.blocks(base.n_base, nv_rows),
        )
    timings["accumulate"] = time.perf_counter() - t0
    if acc.n_rows <= base.n_base:
        raise InputError(
            f"{acc.n} {model.name}-model rows ({acc.n_rows} equations) for {base.n_base} base "
            "parameters: give more samples or a shorter window_length"
        )
    problem = Problem(
        robot,
        base,
        acc,
        q.shape[0],
        timings,
        t_start,
        validation_blocks=blocks,
        model=model.name,
        chunk=opts.run.chunk,
        settings=settings,
        context={"window": window.to_dict()},
    )
    return problem


def accumulate_parts(
    robot: Robot,
    parts,
    columns,
    run: RunOptions,
    split_every: int = 8,
    *,
    uncertainty: UncertaintyOptions | None = None,
):
    """Parts ``(func, args)`` (``func(*args)`` yielding blocks ``(q, dq, ddq, tau)``), each one
    task on the run's back-end (:func:`manip_id.execution.open_backend`), the sums added in a
    tree. ``func`` must be importable on Dask workers and ``args`` picklable. Each part is a
    record of its own for the per-block sums of ``uncertainty``. Returns the sums and the
    task times summed."""
    parts = list(parts)
    if not parts:
        raise InputError("no parts to accumulate")
    unc = UncertaintyOptions.from_value(uncertainty)
    if run.scheduler is None:
        workers = available_cores() if run.workers == AUTO else int(run.workers)
        r, nv = len(columns), robot.nv
        records = [unc.blocks(r, nv, stream=k) for k in range(len(parts))]
        return accumulate_forked(
            robot, parts, columns, run.chunk, workers, run.progress, records=records
        )
    light = portable_robot(robot)
    with open_backend(scheduler=run.scheduler) as backend:
        leaves = backend.map(
            blocks_sums,
            [
                (light, func, tuple(args), columns, run.chunk, unc, k)
                for k, (func, args) in enumerate(parts)
            ],
        )
        (total,) = backend.gather([reduce_tree(backend, leaves, split_every)])
    assert isinstance(total, PartSums)
    return total.acc, dict(total.timings)


def blocks_problem(
    robot: Robot,
    source: Blocks | Parts,
    validation,
    base: BaseParameters | None,
    settings: SolveSettings,
    run: RunOptions,
) -> Problem:
    """The problem of data that arrive in blocks (files, logs, streams).

    :class:`Blocks` (an iterable of blocks ``(q, dq, ddq, tau)``) are accumulated in this
    process, in order; :class:`Parts` (``(func, args)``, ``func(*args)`` yielding blocks)
    each in its own forked process or Dask task, the accumulators merged by addition.
    Memory stays O(chunk nv p + nv r^2) per process however many samples flow through.
    ``validation`` is an iterable of blocks too. Least squares only (the online laws need
    the samples in order: give arrays); for the covariance's per-block sums the blocks of
    one iterable follow each other, each part is a record of its own.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    check_least_squares(settings.method, "data in blocks or parts are solved by")
    unc = settings.uncertainty or UncertaintyOptions()
    base = resolve_base(robot, base, timings)
    ind = base.independent
    t0 = time.perf_counter()
    if isinstance(source, Blocks) and (run.scheduler is not None or run.workers_for(None) > 1):
        raise InputError(
            "with workers > 1 or a scheduler, data in blocks must be parts (func, args), "
            f"got {type(source.blocks).__name__} of blocks"
        )
    if isinstance(source, Parts):
        acc, times = accumulate_parts(robot, source.parts, ind, run, uncertainty=unc)
        timings["accumulate_wall"] = time.perf_counter() - t0
    else:
        record = unc.blocks(len(ind), robot.nv)
        acc, times = accumulate_blocks(
            robot, source.blocks, ind, run.chunk, progress=run.progress, record=record
        )
    timings.update(times)
    check_equations(acc.n * robot.nv, base.n_base, f"{acc.n} samples")
    return Problem(
        robot,
        base,
        acc,
        acc.n,
        timings,
        t_start,
        validation_blocks=validation,
        chunk=run.chunk,
        settings=settings,
    )


def model_window(model: ModelOptions, n_samples: int, dt: float, n_base: int, nv: int):
    """The energy / momentum window: the given ``model.window_length``, or one chosen from
    the data (:func:`~manip_id.models.choose_window`), as a
    :class:`~manip_id.models.WindowChoice`."""
    energy = model.name == "energy"
    if model.window_length is None:
        return choose_window(
            n_samples, dt, n_base, rows_per_window=1 if energy else nv, even=energy
        )
    w = window_samples(model.window_length, dt, even=energy)
    rows = (max(n_samples - 1, 0) // w) * (1 if energy else nv)
    return WindowChoice(w * dt, w, rows, False, "given")


__all__ = [
    "CallOptions",
    "accumulate_parts",
    "blocks_problem",
    "model_window",
    "online_estimator",
    "samples_problem",
]
