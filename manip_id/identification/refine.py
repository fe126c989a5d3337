"""Output-error refinement: base parameters that make the model simulate like the robot.

Starting from a least-squares (or consistent) estimate ``theta_b``, Levenberg-Marquardt on
the multiple-shooting output error over short windows: from each window's measured start
state the model is rolled out (:mod:`.rollout`, the measured torque as input) and

    J(theta_b) = sum_windows sum_k ||q_sim,k - q_k||^2 + w^2 ||dq_sim,k - dq_k||^2

(``w`` [s] weighs velocity errors against position errors). The residuals' exact
parameter sensitivities come from differentiating the integrator step
(:meth:`.forward.ForwardModel.linearization`)::

    S_dq,k+1 = S_dq,k + dt (A_q S_q,k + A_dq S_dq,k - M^-1 Y_b)
    S_q,k+1  = S_q,k + dt S_dq,k+1                  S_.,0 = 0 (measured start state)

and the normal equations ``(H + lambda diag H) d = -g`` are accumulated window by
window (memory O(r^2)). The cost per iteration is ``windows x horizon`` linearizations,
whatever the length of the log: the windows are spread over the data and their number is
bounded (:class:`RefineOptions`). The covariance of the refined estimate is the sandwich
``H^-1 (sum_w g_w g_w^T) H^-1`` over the windows' scores ``g_w`` (the residuals within a
window are correlated; windows far apart are taken as independent).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..robot import Robot
from .forward import DEFAULT_EPS, ForwardModel, coulomb_width, standard_with_base
from .result import IdentificationResult, RelativeError
from .rollout import Log, as_log, simulate, start_points

#: What a result's context says of the least-squares estimate alone (dropped on refining).
_STALE = {"standard_parameters", "physically_consistent"}
#: Default horizon of a window [s].
DEFAULT_HORIZON = 0.1
#: Most linearization steps (windows x horizon) per iteration by default.
STEP_BUDGET = 20_000


@dataclass(frozen=True)
class RefineOptions:
    """How the output-error refinement runs.

    horizon: window length [s] (default 0.1).
    windows: number of windows (default: as many as fit :data:`STEP_BUDGET` linearization
        steps per iteration, at least ``2 r``, at most what the data hold).
    iterations: most Levenberg-Marquardt iterations.
    velocity_weight: ``w`` [s] of the velocity residuals (default the horizon).
    eps: smallest Coulomb regularization width [rad/s or m/s] (:mod:`.forward`).
    tolerance: stop when an accepted step lowers the cost by less than this fraction.
    """

    horizon: float = DEFAULT_HORIZON
    windows: int | None = None
    iterations: int = 10
    velocity_weight: float | None = None
    eps: float = DEFAULT_EPS
    tolerance: float = 1e-4

    def __post_init__(self):
        if not (np.isfinite(self.horizon) and self.horizon > 0):
            raise InputError(f"the refinement horizon must be > 0 seconds, got {self.horizon}")
        if self.windows is not None and (int(self.windows) != self.windows or self.windows < 1):
            raise InputError(f"the number of windows must be >= 1, got {self.windows}")
        if int(self.iterations) != self.iterations or self.iterations < 1:
            raise InputError(f"the number of iterations must be >= 1, got {self.iterations}")


@dataclass
class _Sums:
    """Normal equations of one pass: ``H`` (r, r), ``g`` (r,), cost, window scores."""

    H: np.ndarray
    g: np.ndarray
    cost: float
    scores: list
    n_residuals: int


def _window_sums(fm: ForwardModel, log: Log, s: int, steps: int, w: float, sums: _Sums):
    nv, r = log.dq.shape[1], len(fm.columns)
    dt = log.dt
    Sq, Sv = np.zeros((nv, r)), np.zeros((nv, r))
    q, v = log.q[s].copy(), log.dq[s].copy()
    gw = np.zeros(r)
    for k in range(steps):
        a, Aq, Av, At = fm.linearization(q, v, log.tau[s + k])
        Sv = Sv + dt * (Aq @ Sq + Av @ Sv + At)
        v = v + dt * a
        Sq = Sq + dt * Sv
        q = q + dt * v
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            sums.cost = np.inf
            return
        J = np.vstack([Sq, w * Sv])
        res = np.concatenate([q - log.q[s + k + 1], w * (v - log.dq[s + k + 1])])
        sums.H += J.T @ J
        gk = J.T @ res
        gw += gk
        sums.cost += float(res @ res)
    sums.g += gw
    sums.scores.append(gw)
    sums.n_residuals += 2 * nv * steps


def _cost(fm: ForwardModel, plan, w: float) -> float:
    cost = 0.0
    for log, starts, steps in plan:
        for s in starts:
            q, v = simulate(fm, log, s, steps)
            e = np.concatenate([q[1:] - log.q[s + 1 : s + steps + 1], w * (v[1:] - log.dq[s + 1 : s + steps + 1])])
            c = float(np.sum(e**2))
            if not np.isfinite(c):
                return np.inf
            cost += c
    return cost


def _plan(logs: list[Log], options: RefineOptions, r: int) -> tuple[list, int, int]:
    steps = max(1, int(round(options.horizon / logs[0].dt)))
    most = sum(max(0, (len(lg.t) - 1) // steps) for lg in logs)
    if most < 1:
        raise InputError(f"the refinement horizon of {steps} steps is longer than the data")
    n = options.windows or int(np.clip(STEP_BUDGET // steps, 2 * r, most))
    n = min(n, most)
    plan, total = [], sum(len(lg.t) for lg in logs)
    for lg in logs:
        k = max(1, round(n * len(lg.t) / total))
        plan.append((lg, start_points(len(lg.t), steps, k), steps))
    return plan, steps, sum(len(p[1]) for p in plan)


def _torque_error(result, robot, datasets) -> tuple[float, np.ndarray] | None:
    if not datasets:
        return None
    tau = np.concatenate([np.asarray(d.tau, float) for d in datasets])
    pred = np.concatenate([result.predict(robot, d.q, d.dq, d.ddq) for d in datasets])
    err = tau - pred
    return float(np.linalg.norm(err) / np.linalg.norm(tau)), np.linalg.norm(
        err, axis=0
    ) / np.linalg.norm(tau, axis=0)


def refine(
    result: IdentificationResult,
    robot: Robot,
    data,
    *,
    validation=None,
    options: RefineOptions | None = None,
) -> IdentificationResult:
    """The result with its base parameters refined by output error (module docstring).

    ``data``: the training logs (preprocessed datasets: uniform ``t``, ``q``, ``dq``,
    ``ddq``, ``tau``); ``validation``: other logs for the validation torque error. The
    returned result holds the refined ``estimate``, its window-sandwich covariance, the
    torque errors of the refined estimate, and ``context["refinement"]`` = ``{method,
    horizon, windows, iterations, cost_before, cost_after, ...}``.
    """
    options = options or RefineOptions()
    t0 = time.perf_counter()
    datasets = list(data)
    logs = [as_log(d) for d in datasets]
    if not logs:
        raise InputError("an output-error refinement needs at least one log")
    base = result.base
    if list(base.names) != list(robot.parameter_names):
        raise InputError(
            f"the result was identified for {len(base.names)} parameters "
            f"({result.robot_name}) but the robot has {robot.n_parameters}"
        )
    r = base.n_base
    plan, steps, n_windows = _plan(logs, options, r)
    dt = logs[0].dt
    w = options.horizon if options.velocity_weight is None else float(options.velocity_weight)
    theta_b = np.asarray(result.estimate, dtype=float).copy()
    configs = np.concatenate([lg.q[::50] for lg in logs])
    eps = coulomb_width(robot, standard_with_base(robot, theta_b, base), configs, dt, options.eps)

    def model(tb):
        return ForwardModel(robot, standard_with_base(robot, tb, base), eps, base)

    def sums(tb) -> _Sums:
        out = _Sums(np.zeros((r, r)), np.zeros(r), 0.0, [], 0)
        fm = model(tb)
        for log, starts, st in plan:
            for s in starts:
                _window_sums(fm, log, s, st, w, out)
        return out

    cur = sums(theta_b)
    if not np.isfinite(cur.cost):
        raise InputError(
            "the starting model does not simulate (a rollout diverged): its mass matrix is "
            "not positive definite along the data; start from a consistent estimate "
            "(--consistent)"
        )
    cost0, lam, it, accepted = cur.cost, 1e-3, 0, 0
    for it in range(1, options.iterations + 1):
        D = np.diag(cur.H).copy()
        D[D <= 0] = max(float(D.max()), 1.0) * 1e-12
        improved = False
        while lam < 1e12:
            step = np.linalg.solve(cur.H + lam * np.diag(D), -cur.g)
            cand = theta_b + step
            c = _cost(model(cand), plan, w)
            if c < cur.cost:
                improved, lam = True, max(lam / 3.0, 1e-9)
                break
            lam *= 4.0
        if not improved:
            break
        accepted += 1
        gain = (cur.cost - c) / cur.cost
        theta_b = cand
        cur = sums(theta_b)
        if gain < options.tolerance:
            break
    Hinv = np.linalg.pinv(cur.H)
    G = np.array(cur.scores)
    cov = Hinv @ (G.T @ G) @ Hinv
    dof = max(cur.n_residuals - r, 1)
    cov_white = cur.cost / dof * Hinv
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        std_pct = np.where(theta_b != 0, 100 * std / np.abs(theta_b), np.inf)
    record = {
        "method": "output-error",
        "horizon": steps * dt,
        "steps": steps,
        "windows": n_windows,
        "iterations": it,
        "accepted_steps": accepted,
        "cost_before": cost0,
        "cost_after": cur.cost,
        "velocity_weight": w,
        "coulomb_width": eps.tolist(),
        "covariance": "sandwich over the windows' scores",
        "start": result.method,
        "seconds": time.perf_counter() - t0,
    }
    refined = replace(
        result,
        estimate=theta_b,
        std=std,
        std_percent=std_pct,
        covariance=cov,
        covariance_white=cov_white,
        std_white=np.sqrt(np.clip(np.diag(cov_white), 0.0, None)),
        uncertainty={"method": "windows", "n_blocks": n_windows, "block_samples": steps},
        standard=None,
        timings={**result.timings, "refine": record["seconds"]},
    )
    train = _torque_error(refined, robot, datasets)
    valid = _torque_error(refined, robot, list(validation or []))
    rel = result.relative_error
    refined = replace(
        refined,
        relative_error=replace(
            rel,
            train=train[0],
            train_per_joint=train[1],
            validation=None if valid is None else valid[0],
            validation_per_joint=None if valid is None else valid[1],
            validation_per_file=None,
            train_moving=None,
            validation_moving=None,
        ),
        raw_error=None,
        context={
            **{k: v for k, v in result.context.items() if k not in _STALE},
            "refinement": record,
        },
    )
    return refined


__all__ = ["DEFAULT_HORIZON", "STEP_BUDGET", "RefineOptions", "refine"]
