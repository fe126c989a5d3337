"""Output-error refinement: base parameters that make the model simulate like the robot.

Starting from a least-squares (or consistent) estimate ``theta_b``, Levenberg-Marquardt on
the multiple-shooting output error over short windows: from each window's measured start
state the model is rolled out (:mod:`.rollout`, the measured torque as input) and

    J(theta_b) = sum_windows sum_k ||q_sim,k - q_k||^2 + w^2 ||dq_sim,k - dq_k||^2

(``w`` [s] weighs velocity errors against position errors), plus the inverse-dynamics
least-squares cost of the same data, ``T(theta_b) = ||Y_b theta_b - tau||^2``, weighted
so that the torque fit cannot be traded away::

    F(theta_b) = J(theta_b) + mu T(theta_b),     mu = rho J(theta_0) / T(theta_0)

Every accepted step lowers F, so ``T <= T(theta_0) (1 + 1/rho)`` from any start: the
training torque error grows by at most ``sqrt(1 + 1/rho)`` (1.095 for the default
rho = 5). The residuals' exact
parameter sensitivities come from differentiating the integrator step
(:meth:`.forward.ForwardModel.linearization`)::

    S_dq,k+1 = S_dq,k + dt (A_q S_q,k + A_dq S_dq,k - M^-1 Y_b)
    S_q,k+1  = S_q,k + dt S_dq,k+1                  S_.,0 = 0 (measured start state)

and the normal equations ``(H + lambda diag H) d = -g`` are accumulated window by
window (memory O(r^2)). The cost per iteration is ``windows x horizon`` linearizations,
whatever the length of the log: the windows are spread over the data and their number is
bounded (:class:`RefineOptions`); the torque sums take one regressor pass over the data,
once. The covariance of the refined estimate is the sandwich of ``F``
over blocks of the data, one per window (each sample with the window whose start is
nearest)::

    cov = H^-1 (sum_w s_w s_w^T) H^-1,   H = sum J_k^T J_k + mu Y_b^T Y_b,
    s_w = sum_(k in w) J_k^T e_k + mu Y_b,w^T (Y_b,w theta_b - tau_w)

(the residuals within a window are correlated; blocks are taken as independent).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..robot.model import Robot
from ..robot.regressor import iter_regressor
from .forward import DEFAULT_EPS, ForwardModel, coulomb_width, standard_with_base
from .result import IdentificationResult
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

    Attributes
    ----------
    horizon
        window length [s] (default 0.1).
    windows
        number of windows (default: as many as fit :data:`STEP_BUDGET` linearization
        steps per iteration, at least ``4 r``, at most the start points the data hold;
        windows may overlap).
    iterations
        most Levenberg-Marquardt iterations.
    velocity_weight
        ``w`` [s] of the velocity residuals (default the horizon).
    eps
        smallest Coulomb regularization width [rad/s or m/s] (:mod:`.forward`).
    tolerance
        stop when an accepted step lowers the cost by less than this fraction.
    torque_weight
        ``rho`` of the inverse-dynamics term (module docstring); 0: pure output error.
    """

    horizon: float = DEFAULT_HORIZON
    windows: int | None = None
    iterations: int = 10
    velocity_weight: float | None = None
    eps: float = DEFAULT_EPS
    tolerance: float = 1e-4
    torque_weight: float = 5.0

    def __post_init__(self):
        if not (np.isfinite(self.horizon) and self.horizon > 0):
            raise InputError(f"the refinement horizon must be > 0 seconds, got {self.horizon}")
        if self.windows is not None and (int(self.windows) != self.windows or self.windows < 1):
            raise InputError(f"the number of windows must be >= 1, got {self.windows}")
        if not (np.isfinite(self.torque_weight) and self.torque_weight >= 0):
            raise InputError(f"the torque weight must be >= 0, got {self.torque_weight}")
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
            e = np.concatenate(
                [q[1:] - log.q[s + 1 : s + steps + 1], w * (v[1:] - log.dq[s + 1 : s + steps + 1])]
            )
            c = float(np.sum(e**2))
            if not np.isfinite(c):
                return np.inf
            cost += c
    return cost


def _plan(logs: list[Log], options: RefineOptions, r: int) -> tuple[list, int, int]:
    steps = max(1, int(round(options.horizon / logs[0].dt)))
    room = sum(max(0, len(lg.t) - steps) for lg in logs)  # start points with a full window
    if room < 1:
        raise InputError(
            f"the refinement horizon of {float(steps):.4g} steps is longer than the data"
        )
    n = options.windows or max(STEP_BUDGET // steps, 4 * r)
    n = min(n, room)
    plan, total = [], sum(len(lg.t) for lg in logs)
    for lg in logs:
        if len(lg.t) > steps:
            k = max(1, round(n * len(lg.t) / total))
            plan.append((lg, start_points(len(lg.t), steps, k), steps))
    return plan, steps, sum(len(p[1]) for p in plan)


def torque_sums(robot: Robot, base, datasets, plan=None):
    """``A = Y_b^T Y_b`` (r, r), ``b = Y_b^T tau`` (r,), ``tau^T tau`` of the inverse-dynamics
    least squares on ``datasets``, chunk by chunk; with a window ``plan`` (one entry per
    dataset) also per window block (each sample to the window whose start is nearest),
    ``A_w`` (W, r, r) and ``b_w`` (W, r), for the window sandwich of the covariance."""
    r = base.n_base
    A, b, zz = np.zeros((r, r)), np.zeros(r), 0.0
    n_w = 0 if plan is None else sum(len(p[1]) for p in plan)
    Aw, bw = np.zeros((n_w, r, r)), np.zeros((n_w, r))
    offset = 0
    for i, d in enumerate(datasets):
        tau = np.asarray(d.tau, float)
        starts = None if plan is None else plan[i][1]
        for c in iter_regressor(robot, d.q, d.dq, d.ddq):
            Yb = c.Y[:, :, base.independent]
            z = tau[c.start : c.stop]
            if starts is not None:
                mid = (starts[:-1] + starts[1:]) // 2
                blk = np.searchsorted(mid, np.arange(c.start, c.stop), side="right")
                for w in np.unique(blk):
                    m = blk == w
                    Yw, zw = Yb[m].reshape(-1, r), z[m].reshape(-1)
                    Aw[offset + w] += Yw.T @ Yw
                    bw[offset + w] += Yw.T @ zw
            Yf, zf = Yb.reshape(-1, r), z.reshape(-1)
            A += Yf.T @ Yf
            b += Yf.T @ zf
            zz += float(zf @ zf)
        offset += 0 if starts is None else len(starts)
    return A, b, zz, Aw, bw


def _torque_error(result, robot, datasets) -> tuple[float, np.ndarray] | None:
    """Relative RMS torque error of ``result`` on ``datasets``, overall and per joint
    (sums file by file: no stacked copy of the logs)."""
    if not datasets:
        return None
    num = den = 0.0
    nj = np.zeros(robot.nv)
    dj = np.zeros(robot.nv)
    for d in datasets:
        tau = np.asarray(d.tau, float)
        err = tau - result.predict(robot, d.q, d.dq, d.ddq)
        num += float(np.sum(err**2))
        den += float(np.sum(tau**2))
        nj += np.sum(err**2, axis=0)
        dj += np.sum(tau**2, axis=0)
    return float(np.sqrt(num / den)), np.sqrt(nj / dj)


def with_errors_of(result, new, robot, datasets, validation, key: str, record: dict):
    """``new`` (an estimate replacing ``result``'s) with its own torque errors on the
    training and validation data, ``result``'s context less what no longer holds (the
    standard parameters, consistency), and ``record`` under ``key`` in the context."""
    train = _torque_error(new, robot, list(datasets))
    assert train is not None  # the training data are not empty (checked by the callers)
    valid = _torque_error(new, robot, list(validation or []))
    return replace(
        new,
        relative_error=replace(
            result.relative_error,
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
            key: record,
        },
    )


def _lm(start: np.ndarray, sums, cost, torque, options: RefineOptions):
    """Levenberg-Marquardt on ``F = J + mu T`` (module docstring); returns ``(theta_b,
    sums at it, cost of J and F before and after, iterations, accepted steps)``."""
    A, b, zz, mu = torque

    def T(tb):
        return float(tb @ A @ tb - 2 * b @ tb + zz)

    theta_b = start
    cur = sums(theta_b)
    if not np.isfinite(cur.cost):
        raise InputError(
            "the starting model does not simulate (a rollout diverged): its mass matrix is "
            "not positive definite along the data; start from a consistent estimate "
            "(--consistent)"
        )
    F0 = F = cur.cost + mu * T(theta_b)
    J0, lam, it, accepted = cur.cost, 1e-3, 0, 0
    while it < options.iterations:
        it += 1
        H = cur.H + mu * A
        g = cur.g + mu * (A @ theta_b - b)
        D = np.diag(H).copy()
        D[D <= 0] = max(float(D.max()), 1.0) * 1e-12
        cand, Fc = theta_b, np.inf
        while lam < 1e12:
            cand = theta_b + np.linalg.solve(H + lam * np.diag(D), -g)
            Fc = cost(cand) + mu * T(cand)
            if Fc < F:
                lam = max(lam / 3.0, 1e-9)
                break
            lam *= 4.0
        if not Fc < F:
            break
        accepted += 1
        gain = (F - Fc) / F
        theta_b, F = cand, Fc
        cur = sums(theta_b)
        if gain < options.tolerance:
            break
    return theta_b, cur, (J0, cur.cost, F0, F, T(start), T(theta_b)), it, accepted


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
    start = np.asarray(result.estimate, dtype=float).copy()
    configs = np.concatenate([lg.q[::50] for lg in logs])
    eps = coulomb_width(robot, standard_with_base(robot, start, base), configs, dt, options.eps)

    def model(tb):
        return ForwardModel(robot, standard_with_base(robot, tb, base), eps, base)

    def sums(tb) -> _Sums:
        out = _Sums(np.zeros((r, r)), np.zeros(r), 0.0, [], 0)
        fm = model(tb)
        for log, starts, st in plan:
            for s in starts:
                _window_sums(fm, log, s, st, w, out)
        return out

    A, b, zz, Aw, bw = torque_sums(robot, base, datasets, plan)
    T0 = float(start @ A @ start - 2 * b @ start + zz)
    J0 = _cost(model(start), plan, w)
    mu = 0.0 if options.torque_weight == 0 or T0 <= 0 else options.torque_weight * J0 / T0
    theta_b, cur, costs, it, accepted = _lm(
        start, sums, lambda tb: _cost(model(tb), plan, w), (A, b, zz, mu), options
    )
    record = {
        "method": "output-error",
        "horizon": steps * dt,
        "steps": steps,
        "windows": n_windows,
        "iterations": it,
        "accepted_steps": accepted,
        "cost_before": costs[0],
        "cost_after": costs[1],
        "total_cost_before": costs[2],
        "total_cost_after": costs[3],
        "torque_rss_before": costs[4],
        "torque_rss_after": costs[5],
        "torque_weight": options.torque_weight,
        "velocity_weight": w,
        "coulomb_width": eps.tolist(),
        "covariance": "sandwich H^-1 (sum_w s_w s_w^T) H^-1 of F over the window blocks",
        "start": result.method
        + (" (consistent)" if result.physically_consistent and result.standard else ""),
        "seconds": time.perf_counter() - t0,
    }
    H = cur.H + mu * A
    G = np.array(cur.scores) + mu * (Aw @ theta_b - bw)  # window scores of F / 2
    return _refined(result, robot, theta_b, (H, G, cur), record, datasets, validation)


def _refined(result, robot, theta_b, sandwich, record: dict, datasets, validation):
    """The refined :class:`IdentificationResult` (estimate, covariance, errors, record).

    ``sandwich`` = ``(H, G, sums)``: the Gauss-Newton matrix of ``F / 2`` (r, r), the
    windows' scores (W, r) and the output-error sums at the estimate."""
    H, G, _ = sandwich
    Hinv = np.linalg.pinv(H)
    cov = Hinv @ (G.T @ G) @ Hinv
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        std_pct = np.where(theta_b != 0, 100 * std / np.abs(theta_b), np.inf)
    refined = replace(
        result,
        estimate=theta_b,
        std=std,
        std_percent=std_pct,
        covariance=cov,
        covariance_white=None,
        std_white=None,
        uncertainty={
            "method": "windows",
            "n_blocks": record["windows"],
            "block_samples": record["steps"],
        },
        standard=None,
        timings={**result.timings, "refine": record["seconds"]},
    )
    return with_errors_of(result, refined, robot, datasets, validation, "refinement", record)


__all__ = ["DEFAULT_HORIZON", "STEP_BUDGET", "RefineOptions", "refine", "torque_sums"]
