"""The reference of a closed-loop run, its start and the states that validate it.

A joint-angle Fourier reference (:class:`~manip_id.trajectories.FourierTrajectory`) around
the middle of the joint ranges, checked against the limits; new states in the region it
excites, on which the prediction error ``||Y (theta_hat - theta)|| / ||Y theta||`` of an
estimate is measured; and a payload added to the plant's last body.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..._checks import as_float_array, as_real, random_generator
from ...errors import InputError
from ...resources import MAX_PAYLOAD_MASS
from ...robot.model import Robot
from ...trajectories import FourierTrajectory, check_limits, trajectory_to_configuration


def with_payload(robot: Robot, theta, mass: float, lever=None) -> np.ndarray:
    """Parameters with a point mass ``mass`` [kg] added to the last body.

    The point sits at ``lever`` [m] in the frame of the last joint; by default 0.1 m
    along the last joint's axis (a tool on the flange: no gravity torque about that
    axis itself), or along z when the axis is not a coordinate axis. Returns shape (p,).
    """
    mass = as_real(mass, "payload mass", minimum=0.0, unit="kg")
    if mass > MAX_PAYLOAD_MASS:
        raise InputError(f"payload mass must be <= {MAX_PAYLOAD_MASS:g} [kg], got {mass:g}")
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
    angles_lo, angles_hi = angle_bounds(robot, lo, hi)
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


def angle_bounds(robot: Robot, lo: np.ndarray, hi: np.ndarray):
    """Per-DoF position bounds (angles of continuous joints: [-pi, pi])."""
    dofs = robot.dofs
    out_lo = np.where(dofs.continuous, -math.pi, lo[dofs.q_index])
    out_hi = np.where(dofs.continuous, math.pi, hi[dofs.q_index])
    return out_lo, out_hi


def angles_to_q(robot: Robot, angles: np.ndarray) -> np.ndarray:
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
    return angles_to_q(robot, a), v, acc
