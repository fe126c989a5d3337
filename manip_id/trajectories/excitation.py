"""Random trajectories within the limits, and the condition number of a trajectory.

The designed (optimal) excitation is :func:`manip_id.trajectories.design_excitation`.
"""

from __future__ import annotations

import math

import numpy as np

from .._checks import as_int, as_real, random_generator
from ..errors import InputError
from ..identifiability import analyze
from ..resources import MAX_HARMONICS, check_count
from ..robot.model import Robot
from ..robot.regressor import iter_regressor
from .fourier import DEFAULT_WF, FourierTrajectory, trajectory_to_configuration
from .limits import (
    DEFAULT_CHECK_POINTS,
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
