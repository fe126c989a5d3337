"""Excitation design: random trajectories within the limits, and the condition-number optimum.

:func:`optimize_excitation` minimizes ``log cond(W(x))`` of the stacked base
regressor over the Fourier coefficients ``x`` subject to the sampled limits
``G x <= h`` (SLSQP; SciPy's optimizer is imported when it runs).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .._checks import as_int, as_real, random_generator
from ..errors import InfeasibleTrajectoryError, InputError, NumericalError
from ..identifiability import analyze
from ..resources import MAX_HARMONICS, check_count
from ..robot.model import Robot
from ..robot.regressor import iter_regressor
from .fourier import DEFAULT_WF, FourierTrajectory, trajectory_to_configuration
from .limits import (
    DEFAULT_CHECK_POINTS,
    LimitUsage,
    acceleration_limits,
    check_limits,
    check_margin,
    check_trajectory,
    design_position_bounds,
    limit_usage,
    sample_grid,
)


# ------------------------------------------------------------- random trajectory
def _design_limits(robot: Robot, margin: float, acceleration_limit):
    """Finite design bounds per DoF: (lo, hi, vel, acc) with margin; acc NaN when unset."""
    lo, hi = design_position_bounds(robot)
    width = hi - lo
    lo, hi = lo + margin * width, hi - margin * width
    vel = (1.0 - margin) * robot.velocity_bounds()
    acc = (1.0 - margin) * acceleration_limits(robot, acceleration_limit)
    return lo, hi, vel, acc


def _check_design_args(harmonics: int, wf: float) -> tuple[int, float]:
    harmonics = as_int(harmonics, "harmonics")
    if harmonics < 1:
        raise InputError(f"harmonics must be a positive integer, got {harmonics}")
    check_count(harmonics, MAX_HARMONICS, "the number of Fourier harmonics per joint")
    wf = as_real(wf, "wf", unit="rad/s")
    if not (np.isfinite(wf) and wf > 0):
        raise InputError(f"wf must be a positive pulsation [rad/s], got {wf}")
    return int(harmonics), float(wf)


def random_trajectory(
    robot: Robot,
    harmonics: int = 5,
    wf: float = DEFAULT_WF,
    seed: int = 0,
    *,
    margin: float = 0.05,
    acceleration_limit=None,
    fill: float = 0.98,
) -> FourierTrajectory:
    """A random trajectory that fits in the limits.

    ``q0`` is the middle of each joint's position range (0 for continuous
    joints); the coefficients ``a_jl, b_jl ~ N(0, 1)`` are scaled per joint so
    that the tightest of its position, velocity and (given) acceleration
    limits is used to the fraction ``fill`` (checked on a dense grid, then
    confirmed by :func:`check_limits`). Unset limits use the design bounds of
    the module docstring.
    """
    harmonics, wf = _check_design_args(harmonics, wf)
    margin = check_margin(margin)
    if not 0.0 < fill <= 1.0:
        raise InputError(f"fill must be in (0, 1], got {fill}")
    lo, hi, vel, acc = _design_limits(robot, margin, acceleration_limit)
    rng = random_generator(seed)
    a = rng.standard_normal((robot.nv, harmonics))
    b = rng.standard_normal((robot.nv, harmonics))
    traj = FourierTrajectory(0.5 * (lo + hi), a, b, wf)
    t = sample_grid(traj, None, 4 * DEFAULT_CHECK_POINTS)
    _, (pos, v, ac) = limit_usage(traj, t, lo, hi, vel, acc)
    peak = np.fmax(np.fmax(pos.max(axis=0), v.max(axis=0)), np.nan_to_num(ac.max(axis=0)))
    scale = fill / peak
    traj = FourierTrajectory(traj.q0, a * scale[:, None], b * scale[:, None], wf)
    check_limits(robot, traj, margin=margin, acceleration_limit=acceleration_limit)
    return traj


# --------------------------------------------------------------------- excitation
def base_columns(robot: Robot, seed: int = 0) -> np.ndarray:
    """Indices of the base (structurally independent) regressor columns, ascending.

    Those of :func:`manip_id.identifiability.analyze` (structural analysis at
    random states drawn with ``seed``).
    """
    return np.asarray(analyze(robot, seed=seed).base.independent, dtype=int)


def _condition(robot: Robot, q, dq, ddq, base: np.ndarray) -> float:
    """Condition number of the base regressor stacked over the samples (inf if rank deficient)."""
    n = q.shape[0]
    W = np.empty((n * robot.nv, base.size))
    for c in iter_regressor(robot, q, dq, ddq, chunk=max(n, 1)):
        W[c.start * robot.nv : c.stop * robot.nv] = c.Y[:, :, base].reshape(-1, base.size)
    s = np.linalg.svd(W, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else math.inf


def _cost_grid(period: float, n_points: int) -> np.ndarray:
    return np.arange(int(n_points)) * (period / int(n_points))


def excitation_condition_number(
    robot: Robot, trajectory: FourierTrajectory, n_points: int = 100, base=None
) -> float:
    """cond of the base regressor at ``n_points`` equally spaced times over one period.

    ``base``: column indices (default :func:`base_columns`).
    """
    check_trajectory(robot, trajectory)
    if int(n_points) < 1:
        raise InputError(f"n_points must be positive, got {n_points}")
    base = base_columns(robot) if base is None else np.asarray(base, dtype=int)
    angles, dq, ddq = trajectory.sample(_cost_grid(trajectory.period, n_points))
    return _condition(robot, trajectory_to_configuration(robot, angles), dq, ddq, base)


@dataclass(frozen=True)
class ExcitationResult:
    """Outcome of :func:`optimize_excitation`.

    Condition numbers are those of the base regressor on the optimization's
    time grid (``n_points`` samples over one period).
    """

    trajectory: FourierTrajectory
    condition_number_initial: float
    condition_number: float
    condition_number_random: float
    condition_numbers_random: np.ndarray
    iterations: int
    evaluations: int
    time: float
    n_points: int
    base: np.ndarray
    success: bool
    message: str
    usage: LimitUsage


def _linear_constraints(traj_shape, wf, lo, hi, vel, acc, n_constraint_points):
    """G, h with G x <= h for x = [q0 (nv), then per joint (a_j, b_j) (nv * 2L)]."""
    nv, L = traj_shape
    proto = FourierTrajectory(np.zeros(nv), np.zeros((nv, L)), np.zeros((nv, L)), wf)
    t = sample_grid(proto, None, n_constraint_points)
    P, V, A = proto.basis(t)  # (M, 2L)
    M = t.size
    n_x = nv + nv * 2 * L
    rows, rhs = [], []
    for j in range(nv):
        cols = slice(nv + j * 2 * L, nv + (j + 1) * 2 * L)
        e = np.zeros((M, n_x))
        e[:, j] = 1.0
        e[:, cols] = P
        rows += [e, -e]
        rhs += [np.full(M, hi[j]), np.full(M, -lo[j])]
        for basis, limit in ((V, vel[j]), (A, acc[j])):
            if not np.isfinite(limit):
                continue
            g = np.zeros((M, n_x))
            g[:, cols] = basis
            rows += [g, -g]
            rhs += [np.full(M, limit), np.full(M, limit)]
    return np.vstack(rows), np.concatenate(rhs)


class ExcitationObjective:
    """``f(x) = log cond(W(x))`` and its gradient, for ``x = (q0, a, b)``.

    ``W`` stacks the base regressor columns ``Y(q(t_k), dq(t_k), ddq(t_k))[:, base]``
    over ``t_k = k T / n_points``. With the thin SVD ``W = U S V^T``::

        df = u_1^T dW v_1 / s_1 - u_n^T dW v_n / s_n = <G, dW>,
        G = u_1 v_1^T / s_1 - u_n v_n^T / s_n

    so the gradient needs ``dY_k / d(q_k, dq_k, ddq_k)`` contracted with the
    block ``G_k`` of each sample, then the chain rule through the linear maps
    ``q_k = q0 + P_k [a, b]``, ``dq_k = V_k [a, b]``, ``ddq_k = A_k [a, b]``.
    The rigid-body part ``dY_k / dq`` and ``dY_k / ddq`` comes from forward
    differences of ``pinocchio.computeJointTorqueRegressor`` (step ``h`` for
    positions and velocities; ``Y`` is linear in ``ddq``, so a unit step is
    exact); the joint-term columns are differentiated analytically (Coulomb's
    ``sign(dq)`` has zero derivative), so no difference straddles its jump.
    The extreme singular pairs come from the eigen-decomposition of the small
    Gram matrix ``W^T W`` (``u_i = W v_i / s_i``; an SVD of ``W`` when
    ``cond(W) > 1e5``, where the Gram matrix would lose precision). One
    gradient costs ``n_points (1 + 3 nv)`` regressor calls.
    """

    def __init__(
        self, robot: Robot, base, harmonics: int, wf: float, n_points: int, h: float = 1e-6
    ):
        self.robot = robot
        self.base = np.asarray(base, dtype=int)
        self.nv, self.L, self.wf = robot.nv, int(harmonics), float(wf)
        proto = FourierTrajectory(
            np.zeros(self.nv), np.zeros((self.nv, self.L)), np.zeros((self.nv, self.L)), self.wf
        )
        self.P, self.V, self.A = proto.basis(_cost_grid(proto.period, n_points))
        self.n = int(n_points)
        self.h = float(h)
        self.model = robot.model
        self.data = robot.model.createData()
        rigid = self.base < robot.n_rigid
        self.base_rigid = self.base[rigid]
        self._rigid_pos = np.flatnonzero(rigid)
        # analytic joint-term derivatives: (position in base, dof, state kind 0/1/2)
        kind_of = {"k": 0, "fv": 1, "Ia": 2}
        self._joint_derivs = []
        for pos in np.flatnonzero(~rigid):
            owner = robot.layout.owner(int(self.base[pos]))
            if owner.kind == "motor":  # columns of R^T: no analytic derivative here
                raise InputError(
                    "excitation design does not take motor terms (manip_id.robot.transmission): "
                    "design it on the robot without them (Robot.with_transmission(None))"
                )
            if owner.parameter in kind_of:
                self._joint_derivs.append((int(pos), owner.index, kind_of[owner.parameter]))
        self.evaluations = 0

    def states(self, x: np.ndarray):
        """Joint coordinates, velocities, accelerations at the cost grid, each (n_points, nv)."""
        ab = x[self.nv :].reshape(self.nv, 2 * self.L)
        return x[: self.nv] + self.P @ ab.T, self.V @ ab.T, self.A @ ab.T

    def _matrix(self, x: np.ndarray):
        angles, dq, ddq = self.states(x)
        q = trajectory_to_configuration(self.robot, angles)
        n, nv = self.n, self.nv
        W = np.empty((n * nv, self.base.size))
        for c in iter_regressor(self.robot, q, dq, ddq, chunk=n):
            W[c.start * nv : c.stop * nv] = c.Y[:, :, self.base].reshape(-1, self.base.size)
        self.evaluations += 1
        return W, (angles, q, dq, ddq)

    def value(self, x: np.ndarray) -> float:
        """``log cond(W(x))`` (1e3 when W is rank deficient)."""
        W, _ = self._matrix(np.asarray(x, dtype=float))
        lam = np.linalg.eigvalsh(W.T @ W)
        if lam[0] > 1e-10 * lam[-1]:
            return 0.5 * math.log(lam[-1] / lam[0])
        s = np.linalg.svd(W, compute_uv=False)
        return math.log(s[0] / s[-1]) if s[-1] > 0 else 1e3

    def value_and_gradient(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """``(f(x), df/dx)``, the gradient of shape (nv + 2 nv L,)."""
        x = np.asarray(x, dtype=float)
        W, (angles, q, dq, ddq) = self._matrix(x)
        lam, E = np.linalg.eigh(W.T @ W)  # s_i^2 ascending; v_i; u_i = W v_i / s_i
        if lam[0] > 1e-10 * lam[-1]:
            value = 0.5 * math.log(lam[-1] / lam[0])
            v1, vn = E[:, -1], E[:, 0]
            G = np.outer(W @ v1, v1) / lam[-1] - np.outer(W @ vn, vn) / lam[0]
        else:  # ill-conditioned: the Gram matrix loses the smallest singular value
            U, s, Vt = np.linalg.svd(W, full_matrices=False)
            if not s[-1] > 0:
                return 1e3, np.zeros_like(x)
            value = math.log(s[0] / s[-1])
            G = np.outer(U[:, 0], Vt[0]) / s[0] - np.outer(U[:, -1], Vt[-1]) / s[-1]
        n, nv, h = self.n, self.nv, self.h
        G = G.reshape(n, nv, self.base.size)
        g = np.zeros((3, n, nv))  # d f / d (angle, dq, ddq) per sample and dof
        br = self.base_rigid
        if br.size:
            Gr = G[:, :, self._rigid_pos]
            m, d = self.model, self.data

            def f(qk, vk, ak):  # rigid base columns, (nv, n_rigid_base); 1-DoF models give 1-D
                return pin.computeJointTorqueRegressor(m, d, qk, vk, ak).reshape(nv, -1)[:, br]

            eye = np.eye(nv)
            q_pert = trajectory_to_configuration(
                self.robot, (angles[:, None, :] + h * eye[None]).reshape(n * nv, nv)
            ).reshape(n, nv, -1)
            for k in range(n):
                Gk = Gr[k]
                y0 = np.vdot(Gk, f(q[k], dq[k], ddq[k]))
                for i in range(nv):
                    g[0, k, i] = np.vdot(Gk, f(q_pert[k, i], dq[k], ddq[k])) - y0
                    g[1, k, i] = np.vdot(Gk, f(q[k], dq[k] + h * eye[i], ddq[k])) - y0
                    g[2, k, i] = np.vdot(Gk, f(q[k], dq[k], ddq[k] + eye[i])) - y0
            g[:2] /= h
        for pos, dof, kind in self._joint_derivs:
            g[kind, :, dof] += G[:, dof, pos]
        grad_q0 = g[0].sum(axis=0)
        grad_ab = self.P.T @ g[0] + self.V.T @ g[1] + self.A.T @ g[2]  # (2L, nv)
        return value, np.concatenate([grad_q0, grad_ab.T.ravel()])


@dataclass(frozen=True)
class ExcitationSearch:
    """The budget of :func:`optimize_excitation`.

    Attributes
    ----------
    n_points : int
        Times of one period at which the base regressor is stacked (the objective).
    maxiter : int
        SLSQP iterations at most.
    n_constraint_points : int
        Times of one period at which the limits are imposed (linear inequalities).
    n_random : int
        Random feasible trajectories whose median condition number is reported beside.
    """

    n_points: int = 60
    maxiter: int = 100
    n_constraint_points: int = 200
    n_random: int = 10


def optimize_excitation(
    robot: Robot,
    harmonics: int = 5,
    wf: float = DEFAULT_WF,
    seed: int = 0,
    *,
    margin: float = 0.05,
    acceleration_limit=None,
    base=None,
    search: ExcitationSearch | None = None,
) -> ExcitationResult:
    """Fourier coefficients minimizing the condition number of the base regressor.

    Minimizes ``log cond(W(x))`` over ``x = (q0, a, b)``, where ``W`` is the
    base regressor stacked over ``search.n_points`` equally spaced times of one
    period, subject to the position, velocity and (given) acceleration limits
    sampled at ``search.n_constraint_points`` times (linear inequalities), with
    ``scipy.optimize.minimize(method="SLSQP")`` and the gradient of
    :class:`ExcitationObjective`, from ``random_trajectory(robot, harmonics,
    wf, seed)``. The result is confirmed with :func:`check_limits` on a dense grid; should the
    optimum overshoot a limit between constraint samples, its coefficients
    are shrunk about ``q0`` until it fits.

    ``condition_number_random`` is the median over ``search.n_random`` random
    feasible trajectories (seeds ``seed + 1, ...``) for comparison.
    Cost per iteration: about ``n_points (1 + 3 nv)`` regressor calls and a
    small eigen-decomposition (plus line-search evaluations); ``base``
    defaults to :func:`base_columns`. Condition numbers in the result come
    from an SVD of ``W`` (:func:`excitation_condition_number`). ``search``: the
    budget (:class:`ExcitationSearch`; default 60 points, 100 iterations).
    """
    search = ExcitationSearch() if search is None else search
    n_points, maxiter = search.n_points, search.maxiter
    n_constraint_points, n_random = search.n_constraint_points, search.n_random
    harmonics, wf = _check_design_args(harmonics, wf)
    margin = check_margin(margin)
    _check_counts(n_points=(n_points, 1), maxiter=(maxiter, 0), n_random=(n_random, 0))
    _check_counts(n_constraint_points=(n_constraint_points, 2))
    t0 = time.perf_counter()
    base = base_columns(robot) if base is None else np.asarray(base, dtype=int)
    nv, L = robot.nv, harmonics
    lo, hi, vel, acc = _design_limits(robot, margin, acceleration_limit)
    G, h = _linear_constraints((nv, L), wf, lo, hi, vel, acc, n_constraint_points)
    start = random_trajectory(
        robot, L, wf, seed, margin=margin, acceleration_limit=acceleration_limit
    )
    objective = ExcitationObjective(robot, base, L, wf, n_points)
    x0 = start.to_vector()
    f0 = objective.value(x0)
    res = _slsqp(objective, x0, G, h, int(maxiter))
    x = res.x if objective.value(res.x) <= f0 else x0
    traj = FourierTrajectory.from_vector(x, nv, L, wf)
    traj = _fit_into_limits(robot, traj, margin, acceleration_limit)
    usage = check_limits(robot, traj, margin=margin, acceleration_limit=acceleration_limit)
    cond0 = excitation_condition_number(robot, start, n_points, base)
    cond = excitation_condition_number(robot, traj, n_points, base)
    limits = {"margin": margin, "acceleration_limit": acceleration_limit}
    seeds = range(seed + 1, seed + 1 + int(n_random))
    others = [random_trajectory(robot, L, wf, s, **limits) for s in seeds]
    randoms = np.array([excitation_condition_number(robot, o, n_points, base) for o in others])
    return ExcitationResult(
        trajectory=traj,
        condition_number_initial=cond0,
        condition_number=cond,
        condition_number_random=float(np.median(randoms)) if randoms.size else math.nan,
        condition_numbers_random=randoms,
        iterations=int(getattr(res, "nit", 0)),
        evaluations=objective.evaluations,
        time=time.perf_counter() - t0,
        n_points=int(n_points),
        base=base,
        success=bool(res.success),
        message=str(res.message),
        usage=usage,
    )


def _check_counts(**counts: tuple) -> None:
    """Each ``name=(value, least)`` must be an integer >= least."""
    for name, (value, least) in counts.items():
        if int(value) != value or value < least:
            raise InputError(f"{name} must be an integer >= {least}, got {value}")


def _slsqp(objective: ExcitationObjective, x0: np.ndarray, G, h, maxiter: int):
    """SLSQP on ``log cond(W(x))`` with the linear limits ``G x <= h``."""
    import scipy.optimize  # heavy: only when an optimization runs

    constraint = {"type": "ineq", "fun": lambda x: h - G @ x, "jac": lambda _x: -G}
    try:
        return scipy.optimize.minimize(
            objective.value_and_gradient,
            x0,
            jac=True,
            method="SLSQP",
            constraints=[constraint],
            options={"maxiter": maxiter, "ftol": 1e-6},
        )
    except ValueError as exc:  # pragma: no cover - SLSQP breaking down on its own iterates
        raise NumericalError("excitation optimization (SLSQP)", str(exc)) from exc


def _fit_into_limits(robot, traj, margin, acceleration_limit) -> FourierTrajectory:
    """Shrink the coefficients about ``q0`` until :func:`check_limits` passes (at most ~5%)."""
    for _ in range(50):
        try:
            check_limits(robot, traj, margin=margin, acceleration_limit=acceleration_limit)
            return traj
        except InfeasibleTrajectoryError:
            traj = traj.scaled(0.999)
    # q0 itself outside the range cannot be fixed by shrinking: report it
    check_limits(robot, traj, margin=margin, acceleration_limit=acceleration_limit)
    return traj
