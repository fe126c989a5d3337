"""Closed-loop estimators with a known controller: IDIM-IV and DIDIM.

A log recorded in closed loop (the controller of :mod:`manip_id.controller` tracking a
reference) makes inverse-dynamics least squares biased when ``ddq`` is differentiated
from noisy positions: the noise is in the regressor ``Y(q, dq, ddq)`` and, through the
controller, in the torque too. Both estimators here simulate the model of the current
estimate ``theta_k`` in closed loop with the same controller and reference
(:func:`manip_id.controller.track`, forward dynamics of :mod:`.forward`), which gives
noise-free states ``(q_s, dq_s, ddq_s)`` and their regressor ``Y_s = Y(q_s, dq_s, ddq_s)``
(base columns, the Coulomb column regularized as the simulation is), then:

    IV    (IDIM-IV, Janot, Vandanjon, Gautier 2014): instruments Y_s,
          theta_{k+1} = (Y_s^T W Y)^-1 Y_s^T W tau
    DIDIM (Gautier, Janot, Vandanjon 2013): least squares of tau on Y_s,
          theta_{k+1} = (Y_s^T W Y_s)^-1 Y_s^T W tau

from the least-squares start ``theta_0`` (OLS; the nominal model, DIDIM's classical a
priori start, when the least-squares model diverges in closed loop, as an estimate that
is not positive definite may), iterated until the relative step
``||theta_{k+1} - theta_k|| / ||theta_k||`` falls below the tolerance (converged) or the
iterations run out (stated). A step whose model diverges in closed loop is halved until it
does not (``step_factor`` in the history). ``W`` weighs joint ``j`` by
``1 / sigma_j^2``, the variance of the start's residuals on joint ``j`` (fixed over the
iterations). Memory: the sums
``Y_s^T W Y``, ``Y_s^T W Y_s`` (r, r) and ``Y_s^T W tau`` (r,) accumulated chunk by chunk
of samples, each chunk's two regressors computed side by side; the simulated states of one
log are held (N, nv) as the data are.

Covariance (white residuals, stated in ``uncertainty``): with ``A = Y_s^T W Y``,
``S = Y_s^T W Y_s`` and ``s^2`` the weighted residual variance at the estimate,
``cov = s^2 A^-1 S A^-T`` (IV), ``s^2 S^-1`` (DIDIM).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..controller import Controller, check_reference, on_grid, read_reference, track
from ..datasets import Dataset, parse_file_spec
from ..errors import InputError, NumericalError
from ..robot.model import Robot
from ..robot.regressor import iter_regressor
from .forward import DEFAULT_EPS, ForwardModel, coulomb_width, standard_with_base
from .options import PreprocessOptions
from .refine import with_errors_of
from .result import IdentificationResult
from .rollout import read_logs

#: The closed-loop estimators: name -> what it is.
CLOSED_LOOP_METHODS: dict[str, str] = {
    "iv": "IDIM-IV: instruments from the model simulated in closed loop with the controller",
    "didim": "DIDIM: least squares on the regressor of the simulated closed loop",
}
#: How the covariance of each estimator is made (the result's ``uncertainty.reason``).
_COVARIANCE = {
    "iv": "iv: s^2 A^-1 S A^-T, A = Y_s^T W Y, S = Y_s^T W Y_s, white residuals",
    "didim": "didim: s^2 (Y_s^T W Y_s)^-1, white residuals",
}
#: Most halvings of a step whose model diverges in closed loop.
MAX_HALVINGS = 10
#: What a result's context says of the least-squares estimate alone (dropped here).


@dataclass(frozen=True)
class ClosedLoopOptions:
    """How a closed-loop estimator runs.

    Attributes
    ----------
    method
        ``"iv"`` or ``"didim"`` (:data:`CLOSED_LOOP_METHODS`).
    controller
        the controller of the logs (:class:`manip_id.controller.Controller`).
    iterations
        most iterations.
    tolerance
        converged when the relative step of the estimate falls below it.
    substeps
        semi-implicit Euler steps per log period of the simulation.
    eps
        smallest Coulomb regularization width [rad/s or m/s] (:mod:`.forward`).
    """

    method: str
    controller: Controller
    iterations: int = 30
    tolerance: float = 1e-5
    substeps: int = 4
    eps: float = DEFAULT_EPS

    def __post_init__(self):
        if self.method not in CLOSED_LOOP_METHODS:
            raise InputError(
                f"closed-loop method must be one of {list(CLOSED_LOOP_METHODS)}, "
                f"got {self.method!r}"
            )
        if not isinstance(self.controller, Controller):
            raise InputError(
                f"controller must be a Controller, got {type(self.controller).__name__}"
            )
        if int(self.iterations) != self.iterations or self.iterations < 1:
            raise InputError(f"the number of iterations must be >= 1, got {self.iterations}")
        if not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise InputError(f"the tolerance must be > 0, got {self.tolerance}")
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise InputError(f"substeps must be a positive integer, got {self.substeps}")
        if not (np.isfinite(self.eps) and self.eps > 0):
            raise InputError(f"the Coulomb regularization width must be > 0, got {self.eps}")


@dataclass(frozen=True)
class ClosedLoopLog:
    """One log of a closed-loop estimator: the preprocessed data (``t`` uniform, ``q``,
    ``dq``, ``ddq``, ``tau``: a :class:`~manip_id.datasets.Dataset`) and the controller's
    reference on the same samples, ``q_ref``, ``dq_ref`` (N, nv)."""

    data: Dataset
    q_ref: np.ndarray
    dq_ref: np.ndarray

    @property
    def dt(self) -> float:
        """The log step [s] (the mean one)."""
        t = np.asarray(self.data.t, dtype=float)
        return float((t[-1] - t[0]) / (len(t) - 1))


def check_closed_loop(robot: Robot, options: ClosedLoopOptions, specs) -> None:
    """Refuse, before any work, what a closed-loop estimator cannot do with these files:
    a controller of another size, a motor-side drive train, files without a reference."""
    options.controller.check_size(robot.nv)
    tr = robot.transmission
    if tr is not None and tr.signals == "motor":
        raise InputError(
            "the closed-loop estimators read joint-side logs; the drive train's signals are "
            "motor-side (the controller's reference would be too)"
        )
    if robot.nq != robot.nv:
        raise InputError(
            f"the closed-loop estimators integrate q with dq: robot.nq={robot.nq} but "
            f"robot.nv={robot.nv} (continuous joints are not supported)"
        )
    for spec in specs:
        spec = parse_file_spec(spec)
        if spec.path.suffix.lower() not in (".npz", ".csv"):
            raise InputError(
                f"{spec.label}: the controller's reference is read from NPZ or CSV logs"
            )
        check_reference(spec.path, options.controller)


def closed_loop_logs(
    robot: Robot, files, options: PreprocessOptions | None, controller: Controller
) -> list[ClosedLoopLog]:
    """Each file preprocessed as identification reads it (:func:`.rollout.read_logs`),
    with the controller's reference read from the same file and taken at its samples."""
    out = []
    for f, data in zip(files, read_logs(robot, files, options), strict=True):
        path = parse_file_spec(f).path
        t_ref, q_ref, dq_ref = read_reference(path, controller, robot.nv)
        out.append(
            ClosedLoopLog(data, on_grid(t_ref, q_ref, data.t), on_grid(t_ref, dq_ref, data.t))
        )
    return out


def _simulated(fm: ForwardModel, log: ClosedLoopLog, controller: Controller, substeps: int):
    d = log.data
    run = track(
        fm.acceleration, controller, log.q_ref, log.dq_ref, (d.q[0], d.dq[0]), log.dt,
        substeps=substeps,
    )  # fmt: skip
    return run


def _sums(robot, base, fm, logs, controller, substeps, weights, chunk=2048):
    """``A = Y_s^T W Y``, ``S = Y_s^T W Y_s`` (r, r), ``b = Y_s^T W tau`` (r,), and the
    simulated closed loop's figures (torque error, tracking error of the model); None
    when the model diverges in closed loop."""
    r = base.n_base
    cols = np.asarray(base.independent)
    A, S, b = np.zeros((r, r)), np.zeros((r, r)), np.zeros(r)
    w = np.sqrt(weights)[None, :, None]
    fc = robot.layout.joint_columns("fc") if robot.layout.has_term("fc") else None
    err2 = tot2 = pos2 = 0.0
    n = 0
    for log in logs:
        run = _simulated(fm, log, controller, substeps)
        if run.diverged:
            return None
        d = log.data
        tau = np.asarray(d.tau, float)
        meas = iter_regressor(robot, d.q, d.dq, d.ddq, chunk)
        for cs in iter_regressor(robot, run.q, run.dq, run.ddq, chunk):
            sl = slice(cs.start, cs.stop)
            Ys = cs.Y.copy()
            if fc is not None:  # the simulation's regularized Coulomb column
                k = np.arange(robot.nv)
                Ys[:, k, fc] = np.tanh(run.dq[sl] / fm.eps)
            Ys = (Ys[:, :, cols] * w).reshape(-1, r)
            cm = next(meas)
            Y = (cm.Y[:, :, cols] * w).reshape(-1, r)
            z = (tau[sl] * w[:, :, 0]).reshape(-1)
            A += Ys.T @ Y
            S += Ys.T @ Ys
            b += Ys.T @ z
        err2 += float(np.sum((run.tau - tau) ** 2))
        tot2 += float(np.sum(tau**2))
        pos2 += float(np.sum((run.q - d.q) ** 2))
        n += tau.size
    return (
        A,
        S,
        b,
        {
            "simulated_torque_error": float(np.sqrt(err2 / tot2)) if tot2 > 0 else None,
            "position_rms": float(np.sqrt(pos2 / n)),
        },
    )


def _joint_weights(robot, base, logs, theta_b) -> np.ndarray:
    """``1 / sigma_j^2`` from the residuals of ``theta_b`` on the logs (measured regressor)."""
    cols = np.asarray(base.independent)
    ss, n = np.zeros(robot.nv), 0
    for log in logs:
        d = log.data
        tau = np.asarray(d.tau, float)
        for c in iter_regressor(robot, d.q, d.dq, d.ddq):
            e = c.Y[:, :, cols] @ theta_b - tau[c.start : c.stop]
            ss += np.sum(e**2, axis=0)
        n += tau.shape[0]
    var = ss / max(n, 1)
    var[var <= 0] = max(float(var.max()), 1.0) if np.any(var > 0) else 1.0
    return 1.0 / var


def _iterate(sums_at, theta, cur, options: ClosedLoopOptions):
    """The fixed-point iterations of IV or DIDIM from ``theta`` (sums ``cur`` there):
    ``(theta, sums at it, history, converged, why it stopped early or None)``."""
    history: list[dict] = []
    converged, stopped = False, None
    for k in range(1, options.iterations + 1):
        A, S, b, figures = cur
        lhs = A if options.method == "iv" else S
        try:
            new = np.linalg.solve(lhs, b)
        except np.linalg.LinAlgError as exc:
            raise NumericalError(
                f"{options.method} estimate", f"the normal matrix is singular at iteration {k}"
            ) from exc
        step = float(np.linalg.norm(new - theta)) / max(float(np.linalg.norm(theta)), 1e-300)
        entry = {"iteration": k, "step": step, **figures}
        if step < options.tolerance:
            history.append(entry)
            theta, converged = new, True
            break
        # a step whose model diverges in closed loop is halved (at most MAX_HALVINGS times)
        factor, nxt = 1.0, sums_at(new)
        while nxt is None and factor > 0.5**MAX_HALVINGS:
            factor *= 0.5
            nxt = sums_at(theta + factor * (new - theta))
        history.append({**entry, "step_factor": factor})
        if nxt is None:
            stopped = "every shortened step diverged in closed loop"
            break
        theta, cur = theta + factor * (new - theta), nxt
    return theta, cur, history, converged, stopped


def closed_loop_estimate(
    result: IdentificationResult,
    robot: Robot,
    logs,
    *,
    options: ClosedLoopOptions,
    validation=None,
) -> IdentificationResult:
    """The result with its base parameters estimated by IV or DIDIM (module docstring).

    ``result``: the least-squares start (its ``base`` and ``estimate``); ``logs``: the
    training logs (:class:`ClosedLoopLog`); ``validation``: preprocessed datasets for the
    validation torque error. The returned result has ``method`` ``"iv"`` or ``"didim"``,
    and ``context["closed_loop"]`` = ``{method, controller, iterations, converged,
    tolerance, history, stopped, start}`` (the seconds in ``timings["closed_loop"]``;
    ``history``: per iteration the relative step,
    the simulated torque error and the model's position error against the log).
    """
    t0 = time.perf_counter()
    logs = list(logs)
    if not logs:
        raise InputError("a closed-loop estimator needs at least one log")
    base = result.base
    if list(base.names) != list(robot.parameter_names):
        raise InputError(
            f"the result was identified for {len(base.names)} parameters "
            f"({result.robot_name}) but the robot has {robot.n_parameters}"
        )
    ctrl = options.controller
    ctrl.check_size(robot.nv)
    for log in logs:
        if log.q_ref.shape != np.asarray(log.data.dq).shape:
            raise InputError(
                f"the reference has shape {log.q_ref.shape} but the data {log.data.dq.shape}"
            )
    start = np.asarray(result.estimate, dtype=float).copy()
    dt = logs[0].dt
    configs = np.concatenate([np.asarray(log.data.q)[::50] for log in logs])
    eps = coulomb_width(robot, standard_with_base(robot, start, base), configs, dt, options.eps)
    weights = _joint_weights(robot, base, logs, start)

    def sums_at(tb):
        fm = ForwardModel(robot, standard_with_base(robot, tb, base), eps)
        return _sums(robot, base, fm, logs, ctrl, options.substeps, weights)

    theta, start_name = start, result.method
    cur = sums_at(theta)
    if cur is None:  # DIDIM's classical start: the a priori (nominal) model
        theta = base.to_base(robot.nominal_parameters)
        start_name = f"nominal (the {result.method} estimate diverges in closed loop)"
        cur = sums_at(theta)
        if cur is None:
            raise NumericalError(
                "closed-loop simulation",
                f"neither the {result.method} estimate nor the nominal model simulates in "
                "closed loop with the controller",
                hint="check the controller's gains and the reference columns",
            )
    theta, cur, history, converged, stopped = _iterate(sums_at, theta, cur, options)
    A, S = cur[0], cur[1]
    record = {
        "method": options.method,
        "description": CLOSED_LOOP_METHODS[options.method],
        "controller": ctrl.to_dict(),
        "iterations": len(history),
        "converged": converged,
        "tolerance": options.tolerance,
        "substeps": options.substeps,
        "coulomb_width": eps.tolist(),
        "joint_weights": weights.tolist(),
        "history": history,
        "stopped": stopped,
        "start": start_name,
    }
    seconds = time.perf_counter() - t0  # in the timings (a run's figure, not the record's)
    return _estimated(result, robot, theta, logs, validation, record, weights, (A, S, seconds))


def _estimated(result, robot, theta_b, logs, validation, record, weights, sums):
    """The :class:`IdentificationResult` of the closed-loop estimate (covariance, errors)."""
    A, S, seconds = sums
    base = result.base
    cols = np.asarray(base.independent)
    wss, n_rows = 0.0, 0
    for log in logs:
        d = log.data
        tau = np.asarray(d.tau, float)
        for c in iter_regressor(robot, d.q, d.dq, d.ddq):
            e = c.Y[:, :, cols] @ theta_b - tau[c.start : c.stop]
            wss += float(np.sum(e**2 * weights))
        n_rows += tau.size
    r = base.n_base
    s2 = wss / max(n_rows - r, 1)
    if record["method"] == "iv":
        Ainv = np.linalg.pinv(A)
        cov = s2 * Ainv @ S @ Ainv.T
    else:
        cov = s2 * np.linalg.pinv(S)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        std_pct = np.where(theta_b != 0, 100 * std / np.abs(theta_b), np.inf)
    out = replace(
        result,
        method=record["method"],
        estimate=theta_b,
        std=std,
        std_percent=std_pct,
        covariance=cov,
        covariance_white=cov,
        std_white=std,
        uncertainty={"method": "white", "reason": _COVARIANCE[record["method"]]},
        solver=f"{record['method']}: {record['iterations']} closed-loop simulations from "
        f"{record['start']} ({'converged' if record['converged'] else 'not converged'}); "
        "each step a linear solve (LU)",
        standard=None,
        timings={**result.timings, "closed_loop": seconds},
    )
    datasets = [log.data for log in logs]
    return with_errors_of(result, out, robot, datasets, validation, "closed_loop", record)


__all__ = [
    "CLOSED_LOOP_METHODS",
    "ClosedLoopLog",
    "ClosedLoopOptions",
    "check_closed_loop",
    "closed_loop_estimate",
    "closed_loop_logs",
]
