"""Synthetic measurements: inverse dynamics along a trajectory, with the true parameters and noise.

Along a :class:`~manip_id.trajectories.FourierTrajectory` sampled at ``rate``
[Hz] (``t_k = k / rate``, ``k = 0 .. floor(duration * rate)``) the torques are::

    tau(t) = rnea(model(theta), q, dq, ddq) + joint_torques(theta, q, dq)

``model(theta)`` is :meth:`Robot.with_parameters` (rigid bodies, and the
armature, which ``pinocchio.rnea`` includes); friction, offset and spring come
from :func:`manip_id.regressor.joint_torques`. None of it goes through the
regressor, so ``regressor(robot, q, dq, ddq) @ theta_true`` reproducing the
simulated torques is an independent check of both.

Noise (seeded, Gaussian, independent per sample and joint)::

    tau_meas_j = tau_j + noise_tau * rms(tau_j) * e,   rms(tau_j) = sqrt(mean_k tau_j(t_k)^2)
    angle_meas_j = angle_j + noise_q * e                [rad or m]
    dq_meas_j = dq_j + noise_dq * e                     [rad/s or m/s]

``noise_tau`` is relative to each joint's noise-free torque RMS over the
record; ``noise_q`` and ``noise_dq`` are absolute. Noise on a continuous
joint's position is added to the angle before it is stored as (cos, sin).
The dataset's ``ddq`` is the exact (analytic) acceleration. The torque, the
position and the velocity noise, and the parameter perturbation, draw from
independent streams of one seed, so switching one on does not change the others.

Perturbed parameters (:func:`perturb_parameters`) stay physically consistent:
each body keeps a positive mass and an inertia at the centre of mass that is
positive definite and satisfies the triangle inequalities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ._checks import as_float_array, check_finite
from .datasets import Dataset
from .errors import InputError
from .regressor import joint_torques
from .robot import Robot
from .trajectories import FourierTrajectory, trajectory_to_configuration

#: Joint terms that must stay non-negative (offset may take either sign).
_POSITIVE_TERMS = ("Ia", "fv", "fc", "k")


@dataclass(frozen=True)
class SimulatedData:
    """A simulated record and the truth behind it.

    Attributes
    ----------
    dataset: the measurements (noisy ``q``, ``dq``, ``tau``; exact ``ddq``).
    theta_true: the parameters that produced the torques, shape (p,).
    tau_true: noise-free torques [N m or N], shape (N, nv).
    noise_tau: torque noise, relative to each joint's torque RMS.
    noise_q: position noise standard deviation [rad or m].
    noise_dq: velocity noise standard deviation [rad/s or m/s].
    perturb: relative perturbation applied to the parameters.
    rate: sampling rate [Hz].
    seed: the seed of every random draw.
    """

    dataset: Dataset
    theta_true: np.ndarray
    tau_true: np.ndarray
    noise_tau: float
    noise_q: float
    noise_dq: float
    perturb: float
    rate: float
    seed: int


def _streams(seed: int) -> list[np.random.Generator]:
    """Independent generators for: parameters, torque noise, position noise, velocity noise."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(4)]


def _check_theta(robot: Robot, theta) -> np.ndarray:
    theta = as_float_array(theta, "theta", ndim=1)
    if theta.shape[0] != robot.n_parameters:
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    check_finite(theta, "theta", robot.parameter_names)
    return theta


def _nonnegative(value: float, name: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise InputError(f"{name} must be a non-negative number, got {value}")
    return value


def _perturb_body(block: np.ndarray, rel: float, rng: np.random.Generator) -> np.ndarray:
    """One body's 10 parameters, perturbed and kept physically consistent.

    With ``Ic = R diag(lambda) R^T`` at the centre of mass, the second moments
    of the mass distribution along the principal axes are
    ``s_i = (lambda_j + lambda_k - lambda_i) / 2`` (>= 0 for a real body;
    ``lambda_i = s_j + s_k``, which is the triangle inequality). The mass and
    each ``s_i`` are multiplied by ``exp(rel e)``, the principal axes rotated
    by ``exp3(rel e)`` [rad] and the centre of mass moved by
    ``rel max(|c|, r_g) e / sqrt(3)`` (about ``rel max(|c|, r_g)`` in norm),
    ``r_g = sqrt(trace(Ic) / (2 m))`` the radius of gyration, with ``e``
    standard normal draws.
    """
    inertia = pin.Inertia.FromDynamicParameters(block)
    mass = inertia.mass
    if not mass > 0:  # massless placeholder bodies are left as they are
        return block.copy()
    com = np.array(inertia.lever)
    Ic = np.array(inertia.inertia)
    lam, R = np.linalg.eigh(0.5 * (Ic + Ic.T))
    s = 0.5 * (lam.sum() - 2.0 * lam)
    floor = 1e-9 * max(lam.max(), 1e-12)  # descriptions that violate the triangle inequality
    s = np.maximum(s, floor)
    e = rng.standard_normal(10)
    mass_p = mass * math.exp(rel * e[0])
    # second moments scale with the mass (same shape), then change by exp(rel e) each
    s_p = s * (mass_p / mass) * np.exp(rel * e[1:4])
    R_p = pin.exp3(rel * e[4:7]) @ R
    r_g = math.sqrt(max(lam.sum(), 0.0) / (2.0 * mass))
    com_p = com + rel * max(float(np.linalg.norm(com)), r_g) * e[7:10] / math.sqrt(3.0)
    lam_p = s_p.sum() - s_p
    Ic_p = R_p @ np.diag(lam_p) @ R_p.T
    return pin.Inertia(mass_p, com_p, 0.5 * (Ic_p + Ic_p.T)).toDynamicParameters()


def perturb_parameters(robot: Robot, rel: float, seed: int = 0, theta=None) -> np.ndarray:
    """Parameters perturbed by a relative amount ``rel`` while staying physically valid.

    Parameters
    ----------
    robot: the robot whose layout ``theta`` follows.
    rel: relative standard deviation of the perturbation (e.g. 0.1 for about 10%).
    seed: seed of the draws.
    theta: parameters to perturb, shape (p,); default ``robot.nominal_parameters``.

    Returns
    -------
    Perturbed parameters, shape (p,). Per body: mass times ``exp(rel e)``,
    principal second moments of the mass distribution times ``exp(rel e)``
    (the principal moments of inertia at the CoM then satisfy the triangle
    inequalities), principal axes rotated by about ``rel`` [rad], centre of
    mass moved by about ``rel`` times its distance from the joint (at least
    the radius of gyration); massless bodies are left unchanged. Joint terms
    times ``exp(rel e)``, so Ia, fv, fc, k keep their (non-negative) sign; a
    zero term stays zero.
    """
    rel = _nonnegative(rel, "rel")
    theta = robot.nominal_parameters.copy() if theta is None else _check_theta(robot, theta).copy()
    if rel == 0.0:
        return theta
    rng = np.random.default_rng(seed)
    blocks = robot.layout.rigid_blocks(theta)  # views into theta
    for i in range(robot.n_bodies):
        blocks[i] = _perturb_body(blocks[i], rel, rng)
    terms = robot.terms.enabled
    if terms:
        joint = robot.layout.joint_block(theta)
        joint *= np.exp(rel * rng.standard_normal(joint.shape))
        for k, t in enumerate(terms):
            if t in _POSITIVE_TERMS:
                joint[:, k] = np.abs(joint[:, k])
    return theta


def inverse_dynamics(robot: Robot, theta, q, dq, ddq) -> np.ndarray:
    """Joint torques of the full model with parameters ``theta``, without the regressor.

    ``pinocchio.rnea`` on ``robot.with_parameters(theta)`` (whose armature is
    zero unless the robot models it) plus :func:`joint_torques` (friction,
    offset, spring).

    Parameters
    ----------
    theta: shape (p,); q: (N, nq) [rad or m]; dq, ddq: (N, nv).

    Returns
    -------
    tau [N m or N], shape (N, nv).
    """
    theta = _check_theta(robot, theta)
    model = robot.with_parameters(theta)
    data = model.createData()
    n = q.shape[0]
    tau = np.empty((n, robot.nv))
    rnea = pin.rnea
    for k in range(n):
        tau[k] = rnea(model, data, q[k], dq[k], ddq[k])
    if robot.terms.enabled:  # (joint_torques needs at least one joint term)
        tau += joint_torques(robot, theta, q, dq)  # armature is already in rnea
    return tau


def simulate(
    robot: Robot,
    trajectory: FourierTrajectory,
    *,
    duration: float,
    rate: float,
    theta=None,
    perturb: float = 0.0,
    noise_tau: float = 0.0,
    noise_q: float = 0.0,
    noise_dq: float = 0.0,
    seed: int = 0,
) -> SimulatedData:
    """Simulated measurements along a trajectory.

    Parameters
    ----------
    robot: the robot (its joint terms decide which torques are added).
    trajectory: joint coordinates per DoF (see :mod:`manip_id.trajectories`).
    duration: length of the record [s].
    rate: sampling rate [Hz]; samples at ``t_k = k / rate``.
    theta: true parameters, shape (p,); default the nominal ones.
    perturb: relative perturbation of ``theta`` (see :func:`perturb_parameters`).
    noise_tau: torque noise standard deviation relative to each joint's torque RMS.
    noise_q: position noise standard deviation [rad or m].
    noise_dq: velocity noise standard deviation [rad/s or m/s].
    seed: seed of every random draw (module docstring).

    Returns
    -------
    :class:`SimulatedData` with the dataset and ``theta_true``.
    """
    if not isinstance(trajectory, FourierTrajectory):
        raise InputError(f"expected a FourierTrajectory, got {type(trajectory).__name__}")
    if trajectory.nv != robot.nv:
        raise InputError(f"trajectory.nv={trajectory.nv} but robot.nv={robot.nv}")
    duration, rate = float(duration), float(rate)
    if not (math.isfinite(duration) and duration > 0):
        raise InputError(f"duration must be a positive time [s], got {duration}")
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"rate must be a positive sampling rate [Hz], got {rate}")
    n = int(math.floor(duration * rate + 1e-9)) + 1
    if n < 2:
        raise InputError(f"duration * rate = {duration * rate:g} gives fewer than 2 samples")
    perturb = _nonnegative(perturb, "perturb")
    noise_tau = _nonnegative(noise_tau, "noise_tau")
    noise_q = _nonnegative(noise_q, "noise_q")
    noise_dq = _nonnegative(noise_dq, "noise_dq")
    g_theta, g_tau, g_q, g_dq = _streams(seed)

    base = robot.nominal_parameters if theta is None else _check_theta(robot, theta)
    theta_true = perturb_parameters(robot, perturb, seed=int(g_theta.integers(2**63)), theta=base)

    t = np.arange(n) / rate
    angles, dq, ddq = trajectory.sample(t)
    q = trajectory_to_configuration(robot, angles)
    tau_true = inverse_dynamics(robot, theta_true, q, dq, ddq)

    tau = tau_true
    if noise_tau > 0:
        rms = np.sqrt(np.mean(tau_true**2, axis=0))
        tau = tau_true + noise_tau * rms * g_tau.standard_normal(tau_true.shape)
    q_meas = q
    if noise_q > 0:
        q_meas = trajectory_to_configuration(
            robot, angles + noise_q * g_q.standard_normal(angles.shape)
        )
    dq_meas = dq + noise_dq * g_dq.standard_normal(dq.shape) if noise_dq > 0 else dq
    dataset = Dataset(
        t=t,
        q=q_meas,
        dq=dq_meas,
        tau=tau,
        ddq=ddq,
        joint_names=tuple(robot.dof_names),
        meta={
            "source": "simulation",
            "robot": robot.name,
            "perturb": perturb,
            "noise_tau": noise_tau,
            "noise_q": noise_q,
            "noise_dq": noise_dq,
            "rate": rate,
            "seed": int(seed),
        },
    )
    return SimulatedData(
        dataset=dataset,
        theta_true=theta_true,
        tau_true=tau_true,
        noise_tau=noise_tau,
        noise_q=noise_q,
        noise_dq=noise_dq,
        perturb=perturb,
        rate=rate,
        seed=int(seed),
    )


__all__ = ["SimulatedData", "inverse_dynamics", "perturb_parameters", "simulate"]
