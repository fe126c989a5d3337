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

Pieces. :class:`Plant` (forward dynamics with joint terms, and the integrator),
:class:`SensorNoise` (what the controller sees), :class:`Recorder` (what is logged, at
which stride, and the running sums) and :func:`step` (one control step: measure, torque,
record, plant over one period, adapt). :func:`simulate` checks its inputs and runs
``step`` over the reference.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

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


# ---------------------------------------------------------------------- plant
class Plant:
    """The true robot: forward dynamics with its joint terms, and the integrator.

    ``ddq = aba(model(theta), q, dq, tau - tau_joint(q, dq))`` (see the module docstring),
    integrated over one control period ``dt = 1 / rate`` [s] in ``substeps`` fixed steps
    ``h = 1 / (rate * substeps)`` [s] with the torque held.

    Parameters
    ----------
    robot: the robot; its joint terms are the plant's.
    theta_true: parameters of the plant, shape (p,), physically consistent.
    rate: control rate [Hz].
    substeps: physics steps per control period.
    integrator: ``"euler"`` (semi-implicit) or ``"rk4"``.
    """

    def __init__(
        self,
        robot: Robot,
        theta_true: ArrayLike,
        *,
        rate: float,
        substeps: int = 1,
        integrator: str = "euler",
    ) -> None:
        if integrator not in ("euler", "rk4"):
            raise InputError(f"integrator must be 'euler' or 'rk4', got {integrator!r}")
        if not (math.isfinite(rate) and rate > 0):
            raise InputError(f"rate must be positive [Hz], got {rate}")
        if int(substeps) != substeps or int(substeps) < 1:
            raise InputError(f"substeps must be a positive integer, got {substeps}")
        p = robot.n_parameters
        theta = as_float_array(theta_true, "theta_true", 1)
        if theta.shape != (p,):
            raise InputError(f"{theta.shape=} but robot.n_parameters={p}")
        check_finite(theta, "theta_true")
        from .simulation import require_physical

        require_physical(robot, theta)  # a message naming the body
        robot.evaluator.refuse_load("the closed-loop plant (forward dynamics)")
        self.robot = robot
        self.theta = theta
        self.integrator = integrator
        self.substeps = int(substeps)
        self.dt = 1.0 / rate  # control period [s]
        self.h = 1.0 / (rate * self.substeps)  # physics step [s]
        self.model = robot.with_parameters(theta)
        self._data = self.model.createData()
        self._lie = robot.nq != robot.nv
        # joint terms other than armature (which is in the model's mass matrix)
        coef = robot.layout.joint_block(theta)
        if robot.layout.mask is not None:  # a per-joint model: the terms a joint lacks are 0
            coef = coef * robot.layout.mask
        self._joint_terms = [
            (term, coef[:, i].copy())
            for i, term in enumerate(robot.layout.term_table)
            if term.name != "Ia"
        ]
        self._needs_angles = any(term.needs_angles for term, _ in self._joint_terms)
        #: viscous friction coefficients [N m s/rad], shape (nv,), or None when not modelled
        self.viscous: np.ndarray | None = (
            coef[:, robot.layout.terms.index("fv")].copy() if robot.layout.has_term("fv") else None
        )

    def integrate(self, q: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """``q`` moved by the tangent vector ``dv`` (``pinocchio.integrate``), shape (nq,)."""
        return pin.integrate(self.model, q, dv) if self._lie else q + dv

    def joint_torque(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Friction, offset and spring torques ``tau_joint(q, dq)`` [N m], shape (nv,)."""
        angles = self.robot.dofs.angles(q) if self._needs_angles else None
        out = np.zeros(self.robot.nv)
        for term, c in self._joint_terms:
            out += term.torque(c, angles, dq, None, self.robot.layout.shapes)
        return out

    def acceleration(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Forward dynamics ``ddq`` [rad/s^2] under the applied torque ``tau`` [N m]."""
        u = tau - self.joint_torque(q, dq) if self._joint_terms else tau
        return pin.aba(self.model, self._data, q, dq, u)

    def advance(
        self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The state ``(q, dq)`` one control period later, the torque ``tau`` held."""
        h, lie, model = self.h, self._lie, self.model
        for _ in range(self.substeps):
            if self.integrator == "euler":
                dq = dq + h * self.acceleration(q, dq, tau)
                q = pin.integrate(model, q, h * dq) if lie else q + h * dq
            else:
                q, dq = _rk4(model, self.acceleration, q, dq, tau, h, lie)
        return q, dq


@dataclass(frozen=True)
class SensorNoise:
    """Gaussian measurement noise on what the controller sees.

    Attributes
    ----------
    std_q: standard deviation on positions [rad] (applied in the tangent space).
    std_dq: standard deviation on velocities [rad/s].
    rng: the generator; ``q`` is drawn before ``dq`` at every step.
    """

    std_q: float
    std_dq: float
    rng: np.random.Generator

    def measure(self, plant: Plant, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measured ``(q, dq)`` of the true state."""
        nv = int(dq.shape[0])
        qm = plant.integrate(q, self.std_q * self.rng.standard_normal(size=nv))
        dqm = dq + self.std_dq * self.rng.standard_normal(size=nv)
        return qm, dqm


# ------------------------------------------------------------------- recorder
class Recorder:
    """What a run logs, and at which stride.

    Control step ``k`` is recorded in full when ``k`` is a multiple of ``record_every`` and
    at the last step (:attr:`indices`): t, q, q_d, dq, tau, s, theta_hat and the composite
    law's ``|eps|``. At every step it sums the tracking error ``q_tilde^2`` (whole run and
    tail) and the dissipation ``dt (s^T D s + share kappa |eps|^2 / m^2)`` with the damping
    ``D = K_D + diag(f_v)`` and ``share = 1/2`` for the RLS gain, 1 otherwise.

    Parameters
    ----------
    robot: the robot (sizes nq, nv, p).
    n_steps: control steps of the run.
    dt: control period [s].
    record_every: stride of the full records.
    tail: fraction of the run at its end for :meth:`rms_tail`, in (0, 1].
    damping: ``D`` [N m s/rad], shape (nv, nv).
    """

    def __init__(
        self,
        robot: Robot,
        n_steps: int,
        dt: float,
        *,
        record_every: int = 1,
        tail: float = 0.25,
        damping: np.ndarray,
    ) -> None:
        nq, nv, p = robot.nq, robot.nv, robot.n_parameters
        idx = np.arange(0, n_steps, record_every)
        if idx[-1] != n_steps - 1:
            idx = np.append(idx, n_steps - 1)
        self.indices = idx
        K = idx.shape[0]
        self.n_steps, self.nv, self.dt = n_steps, nv, dt
        self.t = np.empty(K)  # [s]
        self.q = np.empty((K, nq))
        self.q_d = np.empty((K, nq))
        self.dq = np.empty((K, nv))
        self.tau = np.empty((K, nv))
        self.s = np.empty((K, nv))
        self.theta_hat = np.empty((K, p))
        self.eps = np.zeros(K)  # [N m]
        self._next, self._r = idx[0], 0
        self.sq_sum = np.zeros(nv)  # [rad^2]
        self.tail_start = n_steps - max(int(round(tail * n_steps)), 1)
        self.tail_sum = 0.0  # [rad^2]
        self.damping = damping
        self.dissipation = 0.0  # [J]
        self.first_error = self.last_error = 0.0  # [rad]

    def observe(
        self,
        k: int,
        q: np.ndarray,
        q_d: np.ndarray,
        dq: np.ndarray,
        tau: np.ndarray,
        ctrl: SlotineLiController,
    ) -> None:
        """Log control step ``k`` after the controller's torque, before its adaptation."""
        dt = self.dt
        e = ctrl.q_tilde
        e2 = e * e
        self.sq_sum += e2
        if k >= self.tail_start:
            self.tail_sum += e2.sum()
        s = ctrl.s
        self.dissipation += dt * float(s @ (self.damping @ s))
        kappa = ctrl.kappa
        if kappa > 0:
            share = 0.5 if ctrl.rls else 1.0
            self.dissipation += dt * share * kappa * float(ctrl.eps @ ctrl.eps) / ctrl.norm2
        if k == 0:
            self.first_error = math.sqrt(e2.sum())
        if k == self._next:
            r = self._r
            self.t[r] = k * dt
            self.q[r] = q
            self.q_d[r] = q_d
            self.dq[r] = dq
            self.tau[r] = tau
            self.s[r] = s
            self.theta_hat[r] = ctrl.theta_hat
            if ctrl.kappa > 0:
                self.eps[r] = math.sqrt(float(ctrl.eps @ ctrl.eps))
            self._r = r + 1
            self._next = self.indices[r + 1] if r + 1 < self.indices.shape[0] else -1
        if k == self.n_steps - 1:
            self.last_error = math.sqrt(e2.sum())

    def rms_per_joint(self) -> np.ndarray:
        """RMS tracking error per joint over all control steps [rad], shape (nv,)."""
        return np.sqrt(self.sq_sum / self.n_steps)

    def rms(self) -> float:
        """RMS tracking error over all control steps and joints [rad]."""
        return float(np.sqrt(self.sq_sum.sum() / (self.n_steps * self.nv)))

    def rms_tail(self) -> float:
        """RMS tracking error over the tail of the run [rad]."""
        return float(np.sqrt(self.tail_sum / ((self.n_steps - self.tail_start) * self.nv)))


# ----------------------------------------------------------------------- step
def step(
    plant: Plant,
    ctrl: SlotineLiController,
    recorder: Recorder,
    k: int,
    q: np.ndarray,
    dq: np.ndarray,
    q_d: np.ndarray,
    dq_d: np.ndarray,
    ddq_d: np.ndarray,
    noise: SensorNoise | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Control step ``k``: measure, torque, record, plant over one period, adapt.

    Parameters
    ----------
    q, dq: the true state at ``t = k dt``, shapes (nq,), (nv,).
    q_d, dq_d, ddq_d: the reference at ``t``, shapes (nq,), (nv,), (nv,).
    noise: measurement noise of what the controller sees (None: exact state).

    Returns
    -------
    The true state ``(q, dq)`` at ``t + dt``.

    Raises
    ------
    NumericalError: the state diverged.
    """
    qm, dqm = (q, dq) if noise is None else noise.measure(plant, q, dq)
    tau = ctrl.torque(qm, dqm, q_d, dq_d, ddq_d)
    recorder.observe(k, q, q_d, dq, tau, ctrl)
    q, dq = plant.advance(q, dq, tau)
    ctrl.adapt(plant.dt)
    if not math.isfinite(float(dq @ dq)):
        raise NumericalError(
            "closed-loop simulation",
            f"the state diverged at t={k * plant.dt:.4f} s",
            hint="lower the gains or raise the rate",
        )
    return q, dq


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
    plant = Plant(robot, theta_true, rate=rate, substeps=substeps, integrator=integrator)
    theta_true = plant.theta
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

    # initial state
    off = np.broadcast_to(as_float_array(initial_error, "initial_error", (0, 1)), (robot.nv,))
    q = _angles_to_q(robot, (start_angles + off)[None])[0].copy()
    dq = start_dq.copy()
    noise = (
        SensorNoise(noise_q, noise_dq, random_generator(seed))
        if noise_q > 0 or noise_dq > 0
        else None
    )
    fv = plant.viscous
    damping = ctrl.kd + (np.diag(fv) if fv is not None else 0.0)  # [N m s/rad]
    rec = Recorder(robot, n_steps, plant.dt, record_every=record_every, tail=tail, damping=damping)

    t0 = time.perf_counter()
    with np.errstate(over="ignore", invalid="ignore"):
        for c0 in range(0, n_steps, _REFERENCE_CHUNK):
            c1 = min(c0 + _REFERENCE_CHUNK, n_steps)
            ang_d, dq_d, ddq_d = reference.sample(np.arange(c0, c1) * plant.dt)
            q_d = _angles_to_q(robot, ang_d)
            for k in range(c0, c1):
                i = k - c0
                q, dq = step(plant, ctrl, rec, k, q, dq, q_d[i], dq_d[i], ddq_d[i], noise)
    wall = time.perf_counter() - t0

    q_val, dq_val, ddq_val = (
        validation_states(robot, reference) if validation is None else validation
    )
    pred = _prediction_error(robot, rec.theta_hat, theta_true, q_val, dq_val, ddq_val)
    return ClosedLoopRun(
        t=rec.t,
        q=rec.q,
        q_d=rec.q_d,
        dq=rec.dq,
        tau=rec.tau,
        s=rec.s,
        theta_hat=rec.theta_hat,
        prediction_error=pred,
        filtered_prediction_error=rec.eps,
        theta_true=theta_true.copy(),
        theta0=np.array(theta0, dtype=float),
        rms_tracking_error=rec.rms(),
        rms_tracking_error_per_joint=rec.rms_per_joint(),
        rms_tracking_error_tail=rec.rms_tail(),
        initial_tracking_error=rec.first_error,
        final_tracking_error=rec.last_error,
        initial_prediction_error=float(pred[0]),
        final_prediction_error=float(pred[-1]),
        duration=duration,
        rate=rate,
        substeps=substeps,
        adapted=bool(adapt),
        composite=ctrl.kappa > 0,
        wall_time=wall,
        real_time_factor=duration / wall,
        dissipation=rec.dissipation,
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
