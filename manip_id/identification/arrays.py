"""In-memory entry points: arrays, blocks and datasets -> a problem -> :func:`solve`.

For N samples ``(q, dq, ddq, tau)`` (or blocks of them) the base-regressor rows are
accumulated (:mod:`~manip_id.identification.problem`: serially, in forked parts, or
as Dask tasks), or one pass of an online law runs over them in order; the energy and
momentum models (:mod:`manip_id.models`) replace ``ddq`` by integrals of the data.
Every path ends in the same :func:`~manip_id.identification.solve`.
"""

from __future__ import annotations

import time
from dataclasses import replace

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
from .options import (
    ONLINE,
    ConsistentOptions,
    ModelOptions,
    OnlineOptions,
    RankOptions,
    RunOptions,
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
from .solve import solve
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


def identify(
    robot: Robot,
    q,
    dq,
    ddq,
    tau,
    *,
    method: str = "wls",
    validation: tuple | None = None,
    base: BaseParameters | None = None,
    consistent: ConsistentOptions | bool | dict | None = None,
    online: OnlineOptions | dict | None = None,
    model: ModelOptions | str | dict | None = None,
    rank: RankOptions | dict | None = None,
    run: RunOptions | dict | None = None,
    uncertainty: UncertaintyOptions | str | dict | None = None,
) -> IdentificationResult:
    """Identify the base parameters of ``robot`` from N samples, streamed.

    Parameters
    ----------
    robot : Robot
        The robot (its joint terms decide the columns).
    q, dq, ddq, tau : array_like
        Positions [rad or m], shape (N, nq); velocities [rad/s], accelerations
        [rad/s^2] and torques [N m], shape (N, nv). ``ddq`` may be None for the
        energy and momentum models.
    method : str
        "wls" (default: weighted by per-joint noise variances from the OLS residuals,
        re-estimated from the weighted ones), "ols" (ordinary least squares), "rls" (one
        pass of recursive least squares), "gradient" (one pass of the normalized gradient
        law); see :data:`METHODS`.
    validation : tuple or None
        ``(q, dq, ddq, tau)`` for the validation error (``(q, dq, ddq, tau, temp)`` with
        the temperature law).
    base : BaseParameters or None
        Base parametrization; default the structural one of ``analyze(robot)``.
    consistent : ConsistentOptions, bool or None
        Physically consistent standard parameters ("ols"/"wls"); True: the defaults.
    online : OnlineOptions or dict or None
        Options of the online law (an unknown key is an :class:`InputError`).
    model : ModelOptions, str or None
        "dynamic" (default, needs ``ddq``), "energy" or "momentum", with the window
        length and the sample time ``dt`` [s] (default 1).
    rank : RankOptions or None
        ``minimum_norm=True`` solves rank-deficient data instead of raising.
    run : RunOptions or None
        ``chunk``, ``workers`` (forked contiguous parts for "ols"/"wls", equal to the
        serial result to round-off) and ``progress(done, total)``.
    uncertainty : UncertaintyOptions, str, dict or None
        The covariance behind ``std``: "auto" (default: autocorrelation-consistent,
        from per-block sums of the accumulation, when the data give at least 16
        blocks; else white), "white" (``sigma^2 (Y^T Y)^-1``) or "hac"; see
        :mod:`manip_id.estimators.uncertainty`. ``std_white`` keeps the white one.

    Returns
    -------
    IdentificationResult
        The robot's ``temperature`` friction law needs the measured temperature: give a
        :class:`~manip_id.datasets.Dataset` with ``temp`` to :func:`identify_dataset`.
    """
    opts = _Opts(consistent, model, rank, run, uncertainty, online)
    return _identify(robot, (q, dq, ddq, tau, None), method, validation, base, opts)


def _identify(robot: Robot, samples: tuple, method: str, validation, base, opts: _Opts):
    """The body of :func:`identify` on ``samples = (q, dq, ddq, tau, temp)`` (``temp``
    the measured temperature of the ``temperature`` law, (N, nv) or (N, 1), or None: when
    the robot's reference ``T0`` is unset it becomes the mean of ``temp`` per joint,
    :mod:`~manip_id.identification.temperature`, recorded in
    ``context["friction_shapes"]``)."""
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    check_method(method)
    q, dq, ddq, tau, temp = samples
    online_options = opts.online
    if opts.model.name != "dynamic":
        return _identify_acceleration_free(robot, (q, dq, tau), method, validation, base, opts)
    q, dq, ddq, tau = check_samples(robot, q, dq, ddq, tau)
    robot = reference_from_arrays(robot, temp)  # the temperature law's T0 (else robot)
    temp = check_temperature(robot, temp, dq) if robot.layout.needs_temperature else None
    n = q.shape[0]
    blocks = validation_blocks(robot, validation)
    timings["checks"] = time.perf_counter() - t_start
    base = resolve_base(robot, base, timings)
    ind, r = base.independent, base.n_base
    check_equations(n * robot.nv, r, f"{n} samples")
    run_o = opts.run
    dt = 1.0 if online_options.dt is None else float(online_options.dt)
    online_run = None
    if method in ONLINE:
        est, what = online_estimator(method, r, online_options, n)
        states = (q, dq, ddq, tau, temp)
        acc, times = accumulate_online(
            robot, states, ind, est, dt, run=run_o, uncertainty=opts.uncertainty
        )
        online_run = OnlineRun(est, what)
    else:
        acc, times = accumulate_arrays(
            robot, q, dq, ddq, tau, ind, run=run_o, uncertainty=opts.uncertainty, temp=temp
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
    )
    result = _solve(problem, method, opts)
    # an implausible consistent fit: would a joint term the model lacks lower the error?
    train = next(array_part(q, dq, ddq, tau, 0, n, temp))
    result.warnings.extend(
        missing_term_warnings(robot, result.standard, [train], blocks, ind, run_o.chunk)
    )
    return note_reference(result, robot)  # the T0 the coefficients fvt, fct refer to


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


class _Opts:
    """The option objects of one call, each from its value (None: the defaults)."""

    def __init__(
        self, consistent=None, model=None, rank=None, run=None, uncertainty=None, online=None
    ):
        self.online = OnlineOptions.from_value(online)
        self.consistent = ConsistentOptions.from_value(consistent)
        self.model = ModelOptions.from_value(model)
        self.rank = RankOptions.from_value(rank)
        self.run = RunOptions.from_value(run)
        self.uncertainty = UncertaintyOptions.from_value(uncertainty)


def _solve(problem: Problem, method: str, opts: _Opts) -> IdentificationResult:
    """:func:`solve` with the call's options."""
    return solve(
        problem,
        method,
        consistent=opts.consistent,
        minimum_norm=opts.rank.minimum_norm,
        uncertainty=opts.uncertainty,
    )


def _identify_acceleration_free(
    robot: Robot, data: tuple, method: str, validation, base, opts: _Opts
) -> IdentificationResult:
    """The energy / momentum path of :func:`identify`: their rows, the usual solve."""
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    model = opts.model
    check_least_squares(method, f"the {model.name} model is solved by")
    q, dq, tau = data
    batched, (q, dq) = check_states(robot, q=q, dq=dq)
    if not batched:
        raise InputError(f"identification takes N samples (2-D arrays), got q.shape={q.shape}")
    tau = check_tau(robot, tau, q.shape[0])
    blocks = validation_blocks(robot, validation)
    timings["checks"] = time.perf_counter() - t_start
    base = resolve_base(robot, base, timings)
    t0 = time.perf_counter()
    accumulate = accumulate_energy if model.name == "energy" else accumulate_momentum
    dt = 1.0 if model.dt is None else float(model.dt)
    nv_rows = 1 if model.name == "energy" else robot.nv
    rows_unc = replace(opts.uncertainty, block_length=1)  # rows span windows: start at one
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
    )
    result = _solve(problem, method, opts)
    return replace(result, context={**result.context, "window": window.to_dict()})


def _are_parts(items: list) -> bool:
    """Whether every item is a part ``(func, args)`` (not a block of arrays)."""
    return all(isinstance(p, tuple) and len(p) == 2 and callable(p[0]) for p in items)


def _takes_parts(source, run: RunOptions) -> bool:
    """Whether :func:`identify_chunks` reads ``source`` as parts: with a scheduler, with
    ``workers > 1``, and with ``"auto"`` when it is a non-empty list or tuple of parts."""
    if run.scheduler is not None:
        return True
    if run.workers == AUTO:
        return isinstance(source, (list, tuple)) and bool(source) and _are_parts(list(source))
    return int(run.workers) > 1


def _check_parts(parts: list) -> None:
    for k, part in enumerate(parts):
        if not (isinstance(part, tuple) and len(part) == 2 and callable(part[0])):
            raise InputError(
                f"with workers > 1 or a scheduler, source must be parts (func, args); "
                f"part {k} is {type(part).__name__}"
            )


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


def identify_chunks(
    robot: Robot,
    source,
    *,
    method: str = "wls",
    validation=None,
    base: BaseParameters | None = None,
    consistent: ConsistentOptions | bool | dict | None = None,
    rank: RankOptions | dict | None = None,
    run: RunOptions | dict | None = None,
    uncertainty: UncertaintyOptions | str | dict | None = None,
) -> IdentificationResult:
    """Least-squares identification from data that arrive in blocks (files, logs, streams).

    ``source`` is either an iterable of blocks ``(q, dq, ddq, tau)`` (shapes
    (n, nq), (n, nv), (n, nv), (n, nv); processed in one process), or, with
    ``run.workers > 1``, ``"auto"`` or ``run.scheduler``, a list of parts ``(func, args)`` where
    ``func(*args)`` yields such blocks: each part is accumulated in its own forked
    process (or Dask task) and the accumulators merge by addition. Memory stays
    O(chunk nv p + nv r^2) per process however many samples flow through.
    ``validation`` is an iterable of blocks too. Methods: "ols" and "wls" (the online
    laws need the samples in order: use :func:`identify`). Options as :func:`identify`;
    for ``uncertainty`` the blocks of one iterable follow each other, each part is a
    record of its own.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    check_least_squares(method, "identify_chunks solves")
    opts = _Opts(consistent, None, rank, run, uncertainty)
    base = resolve_base(robot, base, timings)
    ind = base.independent
    t0 = time.perf_counter()
    run_o = opts.run
    if _takes_parts(source, run_o):
        parts = list(source)
        _check_parts(parts)
        acc, times = accumulate_parts(robot, parts, ind, run_o, uncertainty=opts.uncertainty)
        timings["accumulate_wall"] = time.perf_counter() - t0
    else:
        record = opts.uncertainty.blocks(len(ind), robot.nv)
        acc, times = accumulate_blocks(
            robot, source, ind, run_o.chunk, progress=run_o.progress, record=record
        )
    timings.update(times)
    check_equations(acc.n * robot.nv, base.n_base, f"{acc.n} samples")
    problem = Problem(
        robot,
        base,
        acc,
        acc.n,
        timings,
        t_start,
        validation_blocks=validation,
        chunk=run_o.chunk,
    )
    return _solve(problem, method, opts)


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


def identify_dataset(robot: Robot, dataset, *, ddq=None, validation=None, **kwargs):
    """:func:`identify` on a :class:`~manip_id.datasets.Dataset` (``ddq`` from the dataset
    unless given; its ``temp``, the measured temperature of the ``temperature`` friction
    law, with ``T0`` its mean when the robot has none); ``validation`` may be another
    Dataset. Other keywords as :func:`identify`.
    With the energy or momentum model no ddq is needed and the model's ``dt`` defaults to
    the dataset's mean sample time."""
    if validation is not None and hasattr(validation, "tau"):
        if validation.ddq is None:
            raise InputError("the validation dataset has no accelerations (ddq)")
        v = validation
        validation = (v.q, v.dq, v.ddq, v.tau) + (() if v.temp is None else (v.temp,))
    model = ModelOptions.from_value(kwargs.pop("model", None))
    if model.name != "dynamic":
        if model.dt is None:
            model = ModelOptions(
                model.name, model.window_length, float(np.mean(np.diff(dataset.t)))
            )
        return identify(
            robot,
            dataset.q,
            dataset.dq,
            None,
            dataset.tau,
            validation=validation,
            model=model,
            **kwargs,
        )
    acc_arr = dataset.ddq if ddq is None else ddq
    if acc_arr is None:
        raise InputError(
            "the dataset has no accelerations (ddq): estimate them first "
            "(manip_id.signals) or pass ddq="
        )
    method, base = kwargs.pop("method", "wls"), kwargs.pop("base", None)
    samples = (dataset.q, dataset.dq, acc_arr, dataset.tau, dataset.temp)
    return _identify(robot, samples, method, validation, base, _Opts(model=model, **kwargs))


__all__ = [
    "accumulate_parts",
    "identify",
    "identify_chunks",
    "identify_dataset",
    "online_estimator",
]
