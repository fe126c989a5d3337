"""Closed-loop simulation of the Slotine-Li adaptive controller on a "true" robot.

Plant. Forward dynamics of the true parameters ``theta``::

    ddq = aba(model(theta), q, dq, tau - tau_joint(q, dq))

where ``model(theta)`` (:meth:`Robot.with_parameters`) carries the true inertias and
armature (``pinocchio.aba`` includes ``model.armature``) and ``tau_joint`` are the
friction, offset and spring torques of ``theta`` (``fv dq + fc sign(dq) + fo + k q``).

Integration. Fixed physics step ``h = 1 / (rate * substeps)`` [s] with
semi-implicit (symplectic) Euler, ``dq+ = dq + h ddq``, ``q+ = integrate(q, h dq+)``
(``pinocchio.integrate``: correct for continuous joints), or classical RK4
(``integrator="rk4"``, four ``aba`` calls per step). The torque is computed at the
control rate and held (zero-order hold) over the ``substeps`` physics steps.

The controller sees ``q``, ``dq`` plus optional Gaussian measurement noise.
Recorded every ``record_every`` control steps: t, q, dq, q_d, tau, s, theta_hat
(and, for composite adaptation, the filtered prediction error).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ._checks import as_float_array, check_finite, random_generator
from .adaptive import AdaptiveGains, SlotineLiController, default_gains
from .errors import InputError, NumericalError
from .regressor import RegressorEvaluator
from .robot import Robot
from .trajectories import FourierTrajectory, check_limits, trajectory_to_configuration

#: Control steps whose reference is evaluated in one vectorized call.
_REFERENCE_CHUNK = 2048


# ----------------------------------------------------------------- parameters
def with_payload(robot: Robot, theta, mass: float, lever=None) -> np.ndarray:
    """Parameters with a point mass ``mass`` [kg] added to the last body.

    The point sits at ``lever`` [m] in the frame of the last joint; by default 0.1 m
    along the last joint's axis (a tool on the flange: no gravity torque about that
    axis itself), or along z when the axis is not a coordinate axis. Returns shape (p,).
    """
    mass = float(mass)
    if not math.isfinite(mass) or mass < 0:
        raise InputError(f"payload mass must be >= 0 [kg], got {mass}")
    if lever is None:
        kind = robot.model.joints[robot.model.njoints - 1].shortname()
        axis = {"X": 0, "Y": 1, "Z": 2}.get(kind[-1], 2) if kind[-2:-1] in ("R", "P") else 2
        lever = np.zeros(3)
        lever[axis] = 0.1
    lever = as_float_array(lever, "lever", 1)
    if lever.shape != (3,):
        raise InputError(f"lever must have shape (3,) [m], got {lever.shape=}")
    out = np.array(as_float_array(theta, "theta", 1), dtype=float)
    robot.rigid_body_parameters(out)  # shape check
    if mass > 0:
        point = pin.Inertia(mass, lever, np.zeros((3, 3)))
        i = robot.n_bodies - 1
        out[10 * i : 10 * i + 10] += point.toDynamicParameters()
    return out


# ------------------------------------------------------------------ reference
def default_reference(
    robot: Robot, amplitude: float = 0.4, period: float = 5.0, harmonics: int = 3, seed: int = 0
) -> FourierTrajectory:
    """A random Fourier reference around the middle of the joint ranges.

    Each joint moves at most ``amplitude`` times half its range (and at most
    ``amplitude`` rad) from the middle of :meth:`Robot.sampling_bounds`, with
    ``harmonics`` harmonics of period ``period`` [s]. For a continuous joint the
    trajectory is the joint angle.
    """
    if not (0 < amplitude < 1):
        raise InputError(
            f"amplitude must be in (0, 1) (a fraction of half the range), got {amplitude}"
        )
    if not (period > 0 and math.isfinite(period)):
        raise InputError(f"period must be positive [s], got {period}")
    if int(harmonics) < 1:
        raise InputError(f"harmonics must be >= 1, got {harmonics}")
    lo, hi = robot.sampling_bounds()
    angles_lo, angles_hi = _angle_bounds(robot, lo, hi)
    center = 0.5 * (angles_lo + angles_hi)
    reach = amplitude * np.minimum(0.5 * (angles_hi - angles_lo), 1.0)
    rng = random_generator(seed)
    L = int(harmonics)
    wf = 2 * math.pi / period
    a = rng.normal(size=(robot.nv, L))
    b = rng.normal(size=(robot.nv, L))
    bound = (np.abs(a) + np.abs(b)) @ (1.0 / (wf * np.arange(1, L + 1)))  # max |q - q0|
    a *= (reach / bound)[:, None]
    b *= (reach / bound)[:, None]
    return FourierTrajectory(q0=center, a=a, b=b, wf=wf)


def _angle_bounds(robot: Robot, lo: np.ndarray, hi: np.ndarray):
    """Per-DoF position bounds (angles of continuous joints: [-pi, pi])."""
    dofs = robot.dofs
    out_lo = np.where(dofs.continuous, -math.pi, lo[dofs.q_index])
    out_hi = np.where(dofs.continuous, math.pi, hi[dofs.q_index])
    return out_lo, out_hi


def _angles_to_q(robot: Robot, angles: np.ndarray) -> np.ndarray:
    """Configurations from per-DoF angles, shape (N, nv) -> (N, nq)."""
    return angles if robot.nq == robot.nv else trajectory_to_configuration(robot, angles)


def check_reference(robot: Robot, reference: FourierTrajectory, duration: float) -> None:
    """Raise :class:`InfeasibleTrajectoryError` when the reference leaves the joint limits.

    Positions (bounded joints) and velocities over ``min(duration, period)`` are checked
    against the URDF limits without margin (:func:`manip_id.trajectories.check_limits`).
    """
    if reference.nv != robot.nv:
        raise InputError(f"reference.nv={reference.nv} but robot.nv={robot.nv}")
    check_limits(robot, reference, duration=min(duration, reference.period), margin=0.0)


def validation_states(robot: Robot, reference: FourierTrajectory, n: int = 200, seed: int = 1):
    """``n`` new states in the region the reference excites.

    Positions uniform in the per-joint range of the reference over one period,
    velocities in +-max|dq_d| and accelerations in +-max|ddq_d|. Returns
    ``(q, dq, ddq)``, shapes (n, nq), (n, nv), (n, nv).
    """
    t = np.linspace(0.0, reference.period, 1000, endpoint=False)
    angles, dq, ddq = reference.sample(t)
    rng = random_generator(seed)
    a = rng.uniform(angles.min(0), angles.max(0), size=(n, robot.nv))
    vmax, amax = np.abs(dq).max(0), np.abs(ddq).max(0)
    v = rng.uniform(-vmax, vmax, size=(n, robot.nv))
    acc = rng.uniform(-amax, amax, size=(n, robot.nv))
    return _angles_to_q(robot, a), v, acc


# --------------------------------------------------------------------- result
@dataclass(frozen=True)
class ClosedLoopRun:
    """One closed-loop run. Recorded arrays have one row per recorded control step.

    Attributes
    ----------
    t: times [s], shape (K,)
    q, q_d: positions and reference [rad or m], shape (K, nq)
    dq: velocities, shape (K, nv)
    tau: applied torques [N m or N], shape (K, nv)
    s: sliding variable [rad/s], shape (K, nv)
    theta_hat: estimates, shape (K, p)
    prediction_error: relative torque error of theta_hat on the validation states
        ``||Y_val (theta_hat - theta)|| / ||Y_val theta||``, shape (K,)
    filtered_prediction_error: |eps| of the composite law [N m], shape (K,) (zeros
        without composite adaptation)
    theta_true, theta0: shape (p,)
    rms_tracking_error: sqrt(mean over all control steps and joints of q_tilde^2) [rad]
    rms_tracking_error_per_joint: shape (nv,) [rad]
    rms_tracking_error_tail: the same over the last ``tail`` fraction of the run [rad]
    initial_tracking_error, final_tracking_error: |q_tilde| at the first and last
        control step [rad]
    final_prediction_error, initial_prediction_error: prediction error at the end and start
    wall_time: seconds spent in the simulation loop [s]; real_time_factor: duration / wall_time
    dissipation: integral of ``s^T (K_D + F_v) s + kappa |eps|^2 / m^2`` over the run [J] (the
        predicted decrease of the Lyapunov function in a noise-free, Coulomb-free run;
        with the RLS gain the composite part is ``kappa |eps|^2 / (2 m^2)`` and the
        Lyapunov function uses ``P(t)^-1``, see :mod:`manip_id.adaptive`; forgetting not
        counted)
    """

    t: np.ndarray
    q: np.ndarray
    q_d: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    s: np.ndarray
    theta_hat: np.ndarray
    prediction_error: np.ndarray
    filtered_prediction_error: np.ndarray
    theta_true: np.ndarray
    theta0: np.ndarray
    rms_tracking_error: float
    rms_tracking_error_per_joint: np.ndarray
    rms_tracking_error_tail: float
    initial_tracking_error: float
    final_tracking_error: float
    initial_prediction_error: float
    final_prediction_error: float
    duration: float
    rate: float
    substeps: int
    adapted: bool
    composite: bool
    wall_time: float
    real_time_factor: float
    dissipation: float
    gamma: np.ndarray = field(repr=False)

    def time_to_prediction_error(self, level: float) -> float:
        """First recorded time [s] from which the prediction error stays below ``level``
        (``inf`` if it never does)."""
        above = np.nonzero(self.prediction_error >= level)[0]
        if above.size == 0:
            return float(self.t[0])
        if above[-1] + 1 >= self.t.shape[0]:
            return math.inf
        return float(self.t[above[-1] + 1])


# ----------------------------------------------------------------- simulation
def _check_timing(duration, rate, substeps, record_every) -> tuple[float, float, int, int, int]:
    try:
        duration, rate = float(duration), float(rate)
    except (TypeError, ValueError) as exc:
        raise InputError(f"duration and rate must be numbers, got {duration!r}, {rate!r}") from exc
    if not (math.isfinite(duration) and duration > 0):
        raise InputError(f"duration must be positive [s], got {duration}")
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"rate must be positive [Hz], got {rate}")
    steps = duration * rate
    n = round(steps)
    if n < 1 or abs(steps - n) > 1e-9 * max(steps, 1.0):
        raise InputError(
            f"the control period 1/rate = {1 / rate:g} s does not divide the "
            f"duration {duration:g} s (duration * rate = {steps:g}, not an integer)"
        )
    if int(substeps) != substeps or int(substeps) < 1:
        raise InputError(f"substeps must be a positive integer, got {substeps}")
    if int(record_every) != record_every or int(record_every) < 1:
        raise InputError(f"record_every must be a positive integer, got {record_every}")
    return duration, rate, n, int(substeps), int(record_every)


def simulate(
    robot: Robot,
    theta_true,
    theta0,
    *,
    reference: FourierTrajectory | None = None,
    gains: AdaptiveGains | None = None,
    duration: float = 10.0,
    rate: float = 1000.0,
    substeps: int = 1,
    integrator: str = "euler",
    adapt: bool = True,
    initial_error=0.05,
    noise_q: float = 0.0,
    noise_dq: float = 0.0,
    seed: int = 0,
    record_every: int = 1,
    tail: float = 0.25,
    validation: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> ClosedLoopRun:
    """Run the adaptive controller on the true robot.

    Parameters
    ----------
    robot: the robot; its joint terms are both the plant's and the estimate's.
    theta_true: parameters of the plant, shape (p,).
    theta0: the controller's initial estimate, shape (p,).
    reference: joint-angle reference (default :func:`default_reference`), checked
        against the joint limits (:func:`check_reference`).
    gains: default :func:`default_gains` of ``theta0`` at the reference start.
    duration [s], rate [Hz]: ``duration * rate`` control steps (must be an integer).
    substeps: physics steps per control step (the torque is held).
    integrator: ``"euler"`` (semi-implicit) or ``"rk4"``.
    adapt: False holds the estimate at ``theta0``.
    initial_error: offset added to the reference's start angles [rad], scalar or (nv,).
    noise_q, noise_dq: standard deviations of Gaussian measurement noise [rad], [rad/s].
    record_every: record one control step in this many (the last step is always kept).
    tail: fraction of the run at its end for ``rms_tracking_error_tail``.
    validation: states ``(q, dq, ddq)`` for the prediction error (default
        :func:`validation_states` of the reference).
    """
    duration, rate, n_steps, substeps, record_every = _check_timing(
        duration, rate, substeps, record_every
    )
    if integrator not in ("euler", "rk4"):
        raise InputError(f"integrator must be 'euler' or 'rk4', got {integrator!r}")
    p, nv, nq = robot.n_parameters, robot.nv, robot.nq
    theta_true = as_float_array(theta_true, "theta_true", 1)
    if theta_true.shape != (p,):
        raise InputError(f"{theta_true.shape=} but robot.n_parameters={p}")
    check_finite(theta_true, "theta_true")
    from .simulation import require_physical

    require_physical(robot, theta_true)  # the plant: a message naming the body
    reference = default_reference(robot) if reference is None else reference
    check_reference(robot, reference, duration)
    for name, val in (("noise_q", noise_q), ("noise_dq", noise_dq)):
        if not (math.isfinite(val) and val >= 0):
            raise InputError(f"{name} must be a standard deviation >= 0, got {val}")
    if not (0 < tail <= 1):
        raise InputError(f"tail must be in (0, 1], got {tail}")

    start_angles, start_dq, _ = reference.sample(0.0)
    q_start_ref = _angles_to_q(robot, start_angles[None])[0]
    if gains is None:
        gains = default_gains(robot, theta0, q_start_ref)
    ctrl = SlotineLiController(robot, theta0, gains, adapt=adapt)

    # plant
    model = robot.with_parameters(theta_true)
    data = model.createData()
    # joint terms other than armature (which is in the model's mass matrix)
    coef = robot.layout.joint_block(theta_true)
    joint_terms = [
        (term, coef[:, i].copy())
        for i, term in enumerate(robot.layout.term_table)
        if term.name != "Ia"
    ]
    needs_angles = any(term.needs_angles for term, _ in joint_terms)
    fv = coef[:, robot.layout.terms.index("fv")].copy() if robot.layout.has_term("fv") else None

    def joint_torque(q, dq):
        angles = robot.dofs.angles(q) if needs_angles else None
        out = np.zeros(nv)
        for term, c in joint_terms:
            out += term.torque(c, angles, dq, None)
        return out

    has_joint = bool(joint_terms)
    lie = nq != nv
    aba = pin.aba
    h = 1.0 / (rate * substeps)
    dt = 1.0 / rate

    def accel(q, dq, tau):
        u = tau - joint_torque(q, dq) if has_joint else tau
        return aba(model, data, q, dq, u)

    # initial state
    off = np.broadcast_to(as_float_array(initial_error, "initial_error", (0, 1)), (nv,))
    q = _angles_to_q(robot, (start_angles + off)[None])[0].copy()
    dq = start_dq.copy()
    rng = random_generator(seed)
    noisy = noise_q > 0 or noise_dq > 0

    # recording
    rec_idx = np.arange(0, n_steps, record_every)
    if rec_idx[-1] != n_steps - 1:
        rec_idx = np.append(rec_idx, n_steps - 1)
    K = rec_idx.shape[0]
    R = {
        "t": np.empty(K),
        "q": np.empty((K, nq)),
        "q_d": np.empty((K, nq)),
        "dq": np.empty((K, nv)),
        "tau": np.empty((K, nv)),
        "s": np.empty((K, nv)),
        "theta_hat": np.empty((K, p)),
        "eps": np.zeros(K),
    }
    next_rec, r = rec_idx[0], 0
    sq_sum = np.zeros(nv)
    tail_start = n_steps - max(int(round(tail * n_steps)), 1)
    tail_sum = 0.0
    diss_k = ctrl.kd + (np.diag(fv) if fv is not None else 0.0)
    kappa = ctrl.kappa
    dissipation = 0.0
    first_err = last_err = 0.0

    t0 = time.perf_counter()
    with np.errstate(over="ignore", invalid="ignore"):
        for c0 in range(0, n_steps, _REFERENCE_CHUNK):
            c1 = min(c0 + _REFERENCE_CHUNK, n_steps)
            ang_d, dq_d_all, ddq_d_all = reference.sample(np.arange(c0, c1) * dt)
            q_d_all = _angles_to_q(robot, ang_d)
            for k in range(c0, c1):
                i = k - c0
                q_d = q_d_all[i]
                if noisy:
                    qm = (
                        pin.integrate(model, q, noise_q * rng.standard_normal(nv))
                        if lie
                        else (q + noise_q * rng.standard_normal(nv))
                    )
                    dqm = dq + noise_dq * rng.standard_normal(nv)
                    tau = ctrl.torque(qm, dqm, q_d, dq_d_all[i], ddq_d_all[i])
                else:
                    tau = ctrl.torque(q, dq, q_d, dq_d_all[i], ddq_d_all[i])
                e = ctrl.q_tilde
                e2 = e * e
                sq_sum += e2
                if k >= tail_start:
                    tail_sum += e2.sum()
                s = ctrl.s
                dissipation += dt * float(s @ (diss_k @ s))
                if kappa > 0:
                    share = 0.5 if ctrl.rls else 1.0
                    dissipation += dt * share * kappa * float(ctrl.eps @ ctrl.eps) / ctrl.norm2
                if k == 0:
                    first_err = math.sqrt(e2.sum())
                if k == next_rec:
                    R["t"][r] = k * dt
                    R["q"][r] = q
                    R["q_d"][r] = q_d
                    R["dq"][r] = dq
                    R["tau"][r] = tau
                    R["s"][r] = s
                    R["theta_hat"][r] = ctrl.theta_hat
                    if ctrl.kappa > 0:
                        R["eps"][r] = math.sqrt(float(ctrl.eps @ ctrl.eps))
                    r += 1
                    next_rec = rec_idx[r] if r < K else -1
                if k == n_steps - 1:
                    last_err = math.sqrt(e2.sum())
                # plant over one control period with the torque held
                for _ in range(substeps):
                    if integrator == "euler":
                        dq = dq + h * accel(q, dq, tau)
                        q = pin.integrate(model, q, h * dq) if lie else q + h * dq
                    else:
                        q, dq = _rk4(model, accel, q, dq, tau, h, lie)
                ctrl.adapt(dt)
                if not math.isfinite(float(dq @ dq)):
                    raise NumericalError(
                        "closed-loop simulation",
                        f"the state diverged at t={k * dt:.4f} s",
                        hint="lower the gains or raise the rate",
                    )
    wall = time.perf_counter() - t0

    q_val, dq_val, ddq_val = (
        validation_states(robot, reference) if validation is None else validation
    )
    pred = _prediction_error(robot, R["theta_hat"], theta_true, q_val, dq_val, ddq_val)
    per_joint = np.sqrt(sq_sum / n_steps)
    return ClosedLoopRun(
        t=R["t"],
        q=R["q"],
        q_d=R["q_d"],
        dq=R["dq"],
        tau=R["tau"],
        s=R["s"],
        theta_hat=R["theta_hat"],
        prediction_error=pred,
        filtered_prediction_error=R["eps"],
        theta_true=theta_true.copy(),
        theta0=np.array(theta0, dtype=float),
        rms_tracking_error=float(np.sqrt(sq_sum.sum() / (n_steps * nv))),
        rms_tracking_error_per_joint=per_joint,
        rms_tracking_error_tail=float(np.sqrt(tail_sum / ((n_steps - tail_start) * nv))),
        initial_tracking_error=first_err,
        final_tracking_error=last_err,
        initial_prediction_error=float(pred[0]),
        final_prediction_error=float(pred[-1]),
        duration=duration,
        rate=rate,
        substeps=substeps,
        adapted=bool(adapt),
        composite=ctrl.kappa > 0,
        wall_time=wall,
        real_time_factor=duration / wall,
        dissipation=dissipation,
        gamma=ctrl.gamma,
    )


def _rk4(model, accel, q, dq, tau, h, lie):
    """One classical RK4 step of (q, dq) with the torque held."""

    def pos(dv):
        return pin.integrate(model, q, dv) if lie else q + dv

    a1 = accel(q, dq, tau)
    v2 = dq + 0.5 * h * a1
    a2 = accel(pos(0.5 * h * dq), v2, tau)
    v3 = dq + 0.5 * h * a2
    a3 = accel(pos(0.5 * h * v2), v3, tau)
    v4 = dq + h * a3
    a4 = accel(pos(h * v3), v4, tau)
    q_new = pos(h / 6.0 * (dq + 2 * v2 + 2 * v3 + v4))
    dq_new = dq + h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
    return q_new, dq_new


def _prediction_error(robot: Robot, theta_hat, theta, q, dq, ddq) -> np.ndarray:
    """``||Y (theta_hat_k - theta)|| / ||Y theta||`` on the given states, shape (K,)."""
    ev = RegressorEvaluator(robot)
    n = q.shape[0]
    # accumulate the Gram matrix: memory O(p^2) whatever the number of states
    G = np.zeros((robot.n_parameters, robot.n_parameters))
    for c in ev.iter_regressor(q, dq, ddq, 256):
        Yc = c.Y.reshape(-1, robot.n_parameters)
        G += Yc.T @ Yc
    del n
    d = theta_hat - theta
    num = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", d, G, d), 0.0))
    den = math.sqrt(float(theta @ G @ theta))
    return num / den


# ----------------------------------------------------------------- comparison
@dataclass(frozen=True)
class AdaptiveComparison:
    """The same run with adaptation and with the wrong parameters held fixed.

    Attributes
    ----------
    adaptive: the run with adaptation (plain or composite as asked).
    fixed: the same reference, plant, gains and initial state, ``theta_hat = theta0`` held.
    """

    adaptive: ClosedLoopRun
    fixed: ClosedLoopRun

    def summary(self) -> dict:
        """Figures for reports and JSON (floats only)."""
        a, f = self.adaptive, self.fixed
        return {
            "rms_tracking_error": {"adaptive": a.rms_tracking_error, "fixed": f.rms_tracking_error},
            "rms_tracking_error_tail": {
                "adaptive": a.rms_tracking_error_tail,
                "fixed": f.rms_tracking_error_tail,
            },
            "initial_tracking_error": a.initial_tracking_error,
            "final_tracking_error": {
                "adaptive": a.final_tracking_error,
                "fixed": f.final_tracking_error,
            },
            "initial_prediction_error": a.initial_prediction_error,
            "final_prediction_error": a.final_prediction_error,
            "real_time_factor": a.real_time_factor,
            "wall_time": a.wall_time,
            "duration": a.duration,
            "rate": a.rate,
            "composite": a.composite,
        }


def compare_fixed(robot: Robot, theta_true, theta0, **kwargs) -> AdaptiveComparison:
    """:func:`simulate` twice on the same run: adapting, and with ``theta0`` held fixed."""
    adaptive = simulate(robot, theta_true, theta0, adapt=True, **kwargs)
    fixed = simulate(robot, theta_true, theta0, adapt=False, **kwargs)
    return AdaptiveComparison(adaptive=adaptive, fixed=fixed)
