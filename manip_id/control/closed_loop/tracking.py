"""A closed-loop log: the true robot driven by a known PD/PID controller along a reference.

The robot is the :class:`~.plant.Plant` of the true parameters (its joint terms, exact
``sign(dq)`` Coulomb friction); the controller (:class:`manip_id.controller.Controller`)
tracks the reference ``q_ref(t), dq_ref(t)`` of an excitation, reading the measured
state, and its torque is held over each period (:func:`manip_id.controller.track`).
Logged at the control instants ``t_k = k / rate``::

    q_k, dq_k        the measured state: truth + Gaussian noise (std_q [rad], std_dq [rad/s])
    tau_k            the commanded torque + Gaussian noise (std relative to each joint's
                     RMS commanded torque)
    qref_k, dqref_k  the reference

No accelerations are logged: identification differentiates them from the noisy positions,
which is what biases least squares in closed loop (the noise also enters the loop).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...controller import Controller, track
from ...datasets import Dataset
from ...errors import InputError, NumericalError
from ...robot.model import Robot
from ...simulation import MeasurementNoise
from ...trajectories import FourierTrajectory
from .plant import Plant

#: Physics steps (semi-implicit Euler) per control period of the true robot.
SUBSTEPS = 10


@dataclass(frozen=True)
class TrackingLog:
    """A simulated closed-loop log: ``dataset`` (t, q, dq, tau; no ddq), the reference
    ``q_ref``, ``dq_ref`` (N, nv), the true parameters ``theta_true`` (p,), and the RMS
    tracking error per joint [rad or m] of the true state."""

    dataset: Dataset
    q_ref: np.ndarray
    dq_ref: np.ndarray
    theta_true: np.ndarray
    tracking_rms: np.ndarray


def simulate_tracking(
    robot: Robot,
    trajectory: FourierTrajectory,
    controller: Controller,
    *,
    duration: float,
    rate: float,
    theta=None,
    noise: MeasurementNoise | None = None,
    seed: int = 0,
) -> TrackingLog:
    """The closed-loop log of ``robot`` (true parameters ``theta``, default the nominal)
    tracking ``trajectory`` with ``controller`` (module docstring).

    ``duration`` [s], ``rate`` [Hz] (the control and log rate), :data:`SUBSTEPS` physics
    steps per control period; ``noise``: torque noise relative to each joint's RMS commanded
    torque, position [rad] and velocity [rad/s] noise of the measurement the controller
    reads and the log holds; ``seed``: the noise's.
    """
    if not isinstance(trajectory, FourierTrajectory):
        raise InputError(f"expected a FourierTrajectory, got {type(trajectory).__name__}")
    if trajectory.nv != robot.nv:
        raise InputError(f"trajectory.nv={trajectory.nv} but robot.nv={robot.nv}")
    if robot.nq != robot.nv:
        raise InputError(
            f"a closed-loop log integrates q with dq: robot.nq={robot.nq} but robot.nv={robot.nv}"
        )
    controller.check_size(robot.nv)
    if not (math.isfinite(duration) and duration > 0 and math.isfinite(rate) and rate > 0):
        raise InputError(f"duration [s] and rate [Hz] must be positive, got {duration}, {rate}")
    n = int(math.floor(duration * rate + 1e-9)) + 1
    noise = noise or MeasurementNoise()
    theta_true = robot.nominal_parameters if theta is None else np.asarray(theta, float)
    plant = Plant(robot, theta_true, rate=rate, substeps=SUBSTEPS)
    t = np.arange(n) / rate
    q_ref, dq_ref, _ = trajectory.sample(t)
    rng = np.random.default_rng(seed)
    sq, sv = float(noise.q), float(noise.dq)

    def measure(q, dq):
        nv = q.shape[0]
        return q + sq * rng.standard_normal(nv), dq + sv * rng.standard_normal(nv)

    run = track(
        plant.acceleration,
        controller,
        q_ref,
        dq_ref,
        (q_ref[0], dq_ref[0]),
        1.0 / rate,
        substeps=SUBSTEPS,
        measure=measure if (sq > 0 or sv > 0) else None,
    )
    if run.diverged:
        raise NumericalError(
            "closed-loop simulation",
            f"the state diverged after {run.q.shape[0]} of {n} samples",
            hint="gains too high for the rate: raise the rate or lower kd",
        )
    tau = run.tau
    if noise.tau > 0:
        rms = np.sqrt(np.mean(tau**2, axis=0))
        tau = tau + noise.tau * rms * rng.standard_normal(tau.shape)
    err = q_ref - run.q  # the measured tracking error
    data = Dataset(t=t, q=run.q, dq=run.dq, tau=tau, joint_names=tuple(robot.joint_names))
    return TrackingLog(data, q_ref, dq_ref, theta_true, np.sqrt(np.mean(err**2, axis=0)))


__all__ = ["SUBSTEPS", "TrackingLog", "simulate_tracking"]
