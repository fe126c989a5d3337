"""One closed-loop run: a control step, the run over a reference, and the comparison with
the wrong parameters held fixed (see :mod:`manip_id.control.closed_loop`)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ..._checks import as_float_array, random_generator
from ...errors import InputError, NumericalError
from ...resources import MAX_STEPS, check_count
from ...robot.model import Robot
from ...robot.regressor import RegressorEvaluator
from ...trajectories import FourierTrajectory
from ..adaptive import AdaptiveGains, SlotineLiController, default_gains
from .plant import Plant, SensorNoise
from .recorder import Recorder
from .reference import angles_to_q, check_reference, default_reference, validation_states

#: Control steps whose reference is evaluated in one vectorized call.
_REFERENCE_CHUNK = 2048


@dataclass(frozen=True)
class ClosedLoopRun:
    """One closed-loop run. Recorded arrays have one row per recorded control step.

    Attributes
    ----------
    t : numpy.ndarray
        times [s], shape (K,)
    q, q_d : numpy.ndarray
        positions and reference [rad or m], shape (K, nq)
    dq : numpy.ndarray
        velocities, shape (K, nv)
    tau : numpy.ndarray
        applied torques [N m or N], shape (K, nv)
    s : numpy.ndarray
        sliding variable [rad/s], shape (K, nv)
    theta_hat : numpy.ndarray
        estimates, shape (K, p)
    prediction_error : numpy.ndarray
        relative torque error of theta_hat on the validation states
        ``||Y_val (theta_hat - theta)|| / ||Y_val theta||``, shape (K,)
    filtered_prediction_error : numpy.ndarray
        ``|eps|`` of the composite law [N m], shape (K,) (zeros
        without composite adaptation)
    theta_true, theta0 : numpy.ndarray
        shape (p,)
    rms_tracking_error : float
        sqrt(mean over all control steps and joints of q_tilde^2) [rad]
    rms_tracking_error_per_joint : numpy.ndarray
        shape (nv,) [rad]
    rms_tracking_error_tail : float
        the same over the last ``tail`` fraction of the run [rad]
    initial_tracking_error, final_tracking_error : float
        ``|q_tilde|`` at the first and last
        control step [rad]
    final_prediction_error, initial_prediction_error : float
        prediction error at the end and start
    wall_time : float
        seconds spent in the simulation loop [s]; real_time_factor: duration / wall_time
    dissipation : float
        integral of ``s^T (K_D + F_v) s + kappa |eps|^2 / m^2`` over the run [J] (the
        predicted decrease of the Lyapunov function in a noise-free, Coulomb-free run;
        with the RLS gain the composite part is ``kappa |eps|^2 / (2 m^2)`` and the
        Lyapunov function uses ``P(t)^-1``, see :mod:`manip_id.control.adaptive`; forgetting not
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


# ----------------------------------------------------------------------- step
class Setpoint(NamedTuple):
    """The reference at one control step: ``q_d`` shape (nq,), ``dq_d`` and ``ddq_d`` (nv,)."""

    q: np.ndarray  # [rad or m]
    dq: np.ndarray  # [rad/s]
    ddq: np.ndarray  # [rad/s^2]


def step(
    plant: Plant,
    ctrl: SlotineLiController,
    recorder: Recorder,
    k: int,
    q: np.ndarray,
    dq: np.ndarray,
    setpoint: Setpoint,
    noise: SensorNoise | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Control step ``k``: measure, torque, record, plant over one period, adapt.

    Parameters
    ----------
    q, dq : numpy.ndarray
        the true state at ``t = k dt``, shapes (nq,), (nv,).
    setpoint : Setpoint
        the reference ``(q_d, dq_d, ddq_d)`` at ``t``.
    noise : SensorNoise, optional
        measurement noise of what the controller sees (None: exact state).

    Returns
    -------
    tuple[numpy.ndarray, numpy.ndarray]
        The true state ``(q, dq)`` at ``t + dt``.

    Raises
    ------
    NumericalError
        the state diverged.
    """
    q_d, dq_d, ddq_d = setpoint
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
@dataclass(frozen=True)
class ClosedLoopOptions:
    """How a closed-loop run is simulated, sensed and recorded (:func:`simulate`).

    Attributes
    ----------
    duration : float
        Length of the run [s]; ``duration * rate`` control steps (must be an integer).
    rate : float
        Control rate [Hz].
    substeps : int
        Physics steps per control step (the torque is held).
    integrator : str
        ``"euler"`` (semi-implicit) or ``"rk4"``.
    initial_error : float or array_like
        Offset added to the reference's start angles [rad], scalar or shape (nv,).
    noise_q, noise_dq : float
        Standard deviations of Gaussian measurement noise [rad], [rad/s].
    seed : int
        Seed of the measurement noise.
    record_every : int
        Record one control step in this many (the last step is always kept).
    tail : float
        Fraction of the run at its end for ``rms_tracking_error_tail``, in (0, 1].
    """

    duration: float = 10.0
    rate: float = 1000.0
    substeps: int = 1
    integrator: str = "euler"
    initial_error: float | ArrayLike = 0.05
    noise_q: float = 0.0
    noise_dq: float = 0.0
    seed: int = 0
    record_every: int = 1
    tail: float = 0.25


def _check_timing(options: ClosedLoopOptions) -> tuple[float, float, int, int, int]:
    duration, rate = options.duration, options.rate
    substeps, record_every = options.substeps, options.record_every
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
    check_count(  # the integrator's steps, before any is taken (about 10 us each)
        float(n) * int(substeps), MAX_STEPS,
        "the closed-loop run's integration steps (duration x rate x substeps)",
    )  # fmt: skip
    if int(record_every) != record_every or int(record_every) < 1:
        raise InputError(f"record_every must be a positive integer, got {record_every}")
    return duration, rate, n, int(substeps), int(record_every)


def _check_sensing(options: ClosedLoopOptions) -> None:
    for name, val in (("noise_q", options.noise_q), ("noise_dq", options.noise_dq)):
        if not (math.isfinite(val) and val >= 0):
            raise InputError(f"{name} must be a standard deviation >= 0, got {val}")
    if not (0 < options.tail <= 1):
        raise InputError(f"tail must be in (0, 1], got {options.tail}")


def simulate(
    robot: Robot,
    theta_true,
    theta0,
    *,
    reference: FourierTrajectory | None = None,
    gains: AdaptiveGains | None = None,
    adapt: bool = True,
    validation: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    options: ClosedLoopOptions | None = None,
) -> ClosedLoopRun:
    """Run the adaptive controller on the true robot.

    Parameters
    ----------
    robot : Robot
        the robot; its joint terms are both the plant's and the estimate's.
    theta_true : array_like
        parameters of the plant, shape (p,).
    theta0 : array_like
        the controller's initial estimate, shape (p,).
    reference : FourierTrajectory, optional
        joint-angle reference (default :func:`default_reference`), checked
        against the joint limits (:func:`check_reference`).
    gains : AdaptiveGains, optional
        default :func:`default_gains` of ``theta0`` at the reference start.
    adapt : bool
        False holds the estimate at ``theta0``.
    validation : tuple[numpy.ndarray, numpy.ndarray, numpy.ndarray], optional
        states ``(q, dq, ddq)`` for the prediction error (default
        :func:`validation_states` of the reference).
    options : ClosedLoopOptions, optional
        duration, rate, integrator, start offset, measurement noise and recording
        (:class:`ClosedLoopOptions`; default ``ClosedLoopOptions()``: 10 s at 1 kHz).
    """
    options = ClosedLoopOptions() if options is None else options
    duration, rate, n_steps, substeps, record_every = _check_timing(options)
    plant = Plant(robot, theta_true, rate=rate, substeps=substeps, integrator=options.integrator)
    theta_true = plant.theta
    reference = default_reference(robot) if reference is None else reference
    check_reference(robot, reference, duration)
    _check_sensing(options)

    start_angles, start_dq, _ = reference.sample(0.0)
    q_start_ref = angles_to_q(robot, start_angles[None])[0]
    if gains is None:
        gains = default_gains(robot, theta0, q_start_ref)
    ctrl = SlotineLiController(robot, theta0, gains, adapt=adapt)
    q, dq = _initial_state(robot, start_angles, start_dq, options.initial_error)
    noise = _sensor_noise(options)
    fv = plant.viscous
    damping = ctrl.kd + (np.diag(fv) if fv is not None else 0.0)  # [N m s/rad]
    rec = Recorder(
        robot, n_steps, plant.dt, record_every=record_every, tail=options.tail, damping=damping
    )

    t0 = time.perf_counter()
    with np.errstate(over="ignore", invalid="ignore"):
        for c0 in range(0, n_steps, _REFERENCE_CHUNK):
            c1 = min(c0 + _REFERENCE_CHUNK, n_steps)
            ang_d, dq_d, ddq_d = reference.sample(np.arange(c0, c1) * plant.dt)
            q_d = angles_to_q(robot, ang_d)
            for k in range(c0, c1):
                i = k - c0
                setpoint = Setpoint(q_d[i], dq_d[i], ddq_d[i])
                q, dq = step(plant, ctrl, rec, k, q, dq, setpoint, noise)
    wall = time.perf_counter() - t0

    q_val, dq_val, ddq_val = (
        validation_states(robot, reference) if validation is None else validation
    )
    pred = _prediction_error(robot, rec.theta_hat, theta_true, q_val, dq_val, ddq_val)
    return _run_result(rec, pred, theta_true, theta0, ctrl, wall, (duration, rate, substeps))


def _initial_state(robot: Robot, start_angles, start_dq, initial_error):
    """The true start ``(q, dq)``: the reference's start, its angles offset by
    ``initial_error`` [rad] (scalar or shape (nv,))."""
    init = as_float_array(initial_error, "initial_error", (0, 1))
    off = np.broadcast_to(init, (robot.nv,))
    q = angles_to_q(robot, (start_angles + off)[None])[0].copy()
    return q, start_dq.copy()


def _sensor_noise(options: ClosedLoopOptions) -> SensorNoise | None:
    """The measurement noise of the options (None when there is none)."""
    noise_q, noise_dq = options.noise_q, options.noise_dq
    if noise_q > 0 or noise_dq > 0:
        return SensorNoise(noise_q, noise_dq, random_generator(options.seed))
    return None


def _run_result(rec: Recorder, pred, theta_true, theta0, ctrl, wall: float, timing):
    """The :class:`ClosedLoopRun` of a finished loop."""
    duration, rate, substeps = timing
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
        adapted=bool(ctrl.adapting),
        composite=ctrl.kappa > 0,
        wall_time=wall,
        real_time_factor=duration / wall,
        dissipation=rec.dissipation,
        gamma=ctrl.gamma,
    )


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


@dataclass(frozen=True)
class AdaptiveComparison:
    """The same run with adaptation and with the wrong parameters held fixed.

    Attributes
    ----------
    adaptive : ClosedLoopRun
        the run with adaptation (plain or composite as asked).
    fixed : ClosedLoopRun
        the same reference, plant, gains and initial state, ``theta_hat = theta0`` held.
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
