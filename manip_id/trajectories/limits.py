"""Joint limits of a trajectory: URDF position, velocity and acceleration limits with a margin.

A limit the description leaves unset (:func:`manip_id.robot.parameters.bounded_range`,
:func:`~manip_id.robot.parameters.bounded_rate`) is not checked; design uses finite
bounds instead (:meth:`Robot.sampling_bounds`, :meth:`Robot.velocity_bounds`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._checks import as_float_array
from ..errors import InfeasibleTrajectoryError, InputError
from ..robot.model import Robot
from ..robot.parameters import bounded_range, bounded_rate
from .fourier import FourierTrajectory, dof_layout

#: Default number of time samples per period for limit checks.
DEFAULT_CHECK_POINTS = 1000


def position_limits(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """URDF position limits per DoF, NaN where unset (continuous or absurd), shape (nv,) each."""
    idx, cont = dof_layout(robot)
    lo, hi = robot.lower[idx], robot.upper[idx]
    unset = cont | ~bounded_range(lo, hi)
    lo[unset], hi[unset] = np.nan, np.nan
    return lo, hi


def design_position_bounds(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Finite position bounds per DoF for designing trajectories, shape (nv,) each."""
    idx, cont = dof_layout(robot)
    lo, hi = robot.sampling_bounds()
    lo, hi = lo[idx], hi[idx]
    lo[cont], hi[cont] = -math.pi, math.pi
    return lo, hi


def velocity_limits(robot: Robot) -> np.ndarray:
    v = robot.velocity_limit
    v[~bounded_rate(v)] = np.nan
    return v


def acceleration_limits(robot: Robot, acceleration_limit) -> np.ndarray:
    if acceleration_limit is None:
        return np.full(robot.nv, np.nan)
    acc = as_float_array(acceleration_limit, "acceleration_limit", ndim=(0, 1))
    acc = np.broadcast_to(acc, (robot.nv,)).copy() if acc.ndim == 0 else acc.copy()
    if acc.shape != (robot.nv,):
        raise InputError(f"acceleration_limit.shape={acc.shape} but robot.nv={robot.nv}")
    if np.any(~(acc > 0)):
        raise InputError(f"acceleration limits must be positive [rad/s^2 or m/s^2], got {acc}")
    return acc


def check_margin(margin: float) -> float:
    margin = float(margin)
    if not 0.0 <= margin < 0.5:
        raise InputError(f"margin must be a fraction in [0, 0.5), got {margin}")
    return margin


def check_trajectory(robot: Robot, trajectory: FourierTrajectory) -> None:
    if not isinstance(trajectory, FourierTrajectory):
        raise InputError(f"expected a FourierTrajectory, got {type(trajectory).__name__}")
    if trajectory.nv != robot.nv:
        raise InputError(f"trajectory.nv={trajectory.nv} but robot.nv={robot.nv}")


@dataclass(frozen=True)
class LimitUsage:
    """Peak use of each limit by a trajectory, as a fraction of the allowed range.

    Each array has shape (nv,); 1 means the limit (with its margin) is just
    reached, NaN means the limit is not set. Position use is the largest
    distance from the middle of the allowed range over its half-width.
    """

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    @property
    def worst(self) -> float:
        """Largest use over every joint and limit (NaN-free; 0 when nothing is limited)."""
        vals = np.concatenate([self.position, self.velocity, self.acceleration])
        vals = vals[np.isfinite(vals)]
        return float(vals.max()) if vals.size else 0.0


def sample_grid(trajectory: FourierTrajectory, duration: float | None, n_points: int) -> np.ndarray:
    span = trajectory.period if duration is None else min(float(duration), trajectory.period)
    return np.linspace(0.0, span, int(n_points))


def limit_usage(trajectory, t, pos_lo, pos_hi, vel, acc):
    q, dq, ddq = trajectory.sample(t)
    mid, half = 0.5 * (pos_lo + pos_hi), 0.5 * (pos_hi - pos_lo)
    with np.errstate(invalid="ignore", divide="ignore"):
        pos = np.abs(q - mid) / half  # NaN columns stay NaN
        v = np.abs(dq) / vel
        a = np.abs(ddq) / acc
    return (q, dq, ddq), (pos, v, a)


def peak_usage(use: np.ndarray) -> np.ndarray:
    """Column maxima ignoring NaN; NaN for a column without any limit."""
    peak = np.max(np.where(np.isfinite(use), use, -np.inf), axis=0)
    peak[np.isneginf(peak)] = np.nan
    return peak


def _worst_violation(kinds, uses) -> tuple[float, str, int, int] | None:
    """``(use, kind, sample, joint)`` of the largest relative use above 1, or None."""
    worst = None
    for kind, use in zip(kinds, uses, strict=True):
        u = np.where(np.isfinite(use), use, -np.inf)
        kk, jj = np.unravel_index(np.argmax(u), u.shape)
        if u[kk, jj] > 1.0 + 1e-12 and (worst is None or u[kk, jj] > worst[0]):
            worst = (float(u[kk, jj]), kind, int(kk), int(jj))
    return worst


def check_limits(
    robot: Robot,
    trajectory: FourierTrajectory,
    *,
    duration: float | None = None,
    margin: float = 0.05,
    acceleration_limit=None,
    n_points: int = DEFAULT_CHECK_POINTS,
) -> LimitUsage:
    """Check a trajectory against position, velocity and acceleration limits.

    Parameters
    ----------
    robot : Robot
        the robot whose URDF limits apply.
    trajectory : FourierTrajectory
        a :class:`FourierTrajectory` with ``nv`` joints.
    duration : float, optional
        time span checked from t = 0 [s]; default (and at most, since
        the motion is periodic) one period.
    margin : float
        relative margin, a fraction of each position range and of each
        velocity and acceleration limit (see module docstring).
    acceleration_limit : array_like
        [rad/s^2 or m/s^2], scalar or shape (nv,); None: unchecked.
    n_points : int
        number of time samples over the checked span.

    Returns
    -------
    LimitUsage
        :class:`LimitUsage` (each entry <= 1) when feasible.

    Raises
    ------
    InfeasibleTrajectoryError
        naming the joint, the limit ("position", "velocity", "acceleration") and the
        excess [rad, rad/s, rad/s^2 or m...] of the worst violation (largest relative use).
    """
    check_trajectory(robot, trajectory)
    margin = check_margin(margin)
    if duration is not None and not (np.isfinite(duration) and duration > 0):
        raise InputError(f"duration must be a positive time [s], got {duration}")
    if int(n_points) < 2:
        raise InputError(f"n_points must be at least 2, got {n_points}")
    lo, hi = position_limits(robot)
    width = hi - lo
    lo_m, hi_m = lo + margin * width, hi - margin * width
    vel = (1.0 - margin) * velocity_limits(robot)
    acc = (1.0 - margin) * acceleration_limits(robot, acceleration_limit)
    t = sample_grid(trajectory, duration, n_points)
    states, uses = limit_usage(trajectory, t, lo_m, hi_m, vel, acc)
    usage = LimitUsage(*(peak_usage(u) for u in uses))
    kinds = ("position", "velocity", "acceleration")
    worst = _worst_violation(kinds, uses)
    if worst is None:
        return usage
    _, kind, k, j = worst
    name = robot.dof_names[j]
    unit = "m" if robot.is_prismatic(j) else "rad"
    value = states[kinds.index(kind)][k, j]
    if kind == "position":
        bound = hi_m[j] if value > hi_m[j] else lo_m[j]
        excess = abs(value - bound)
        allowed = f"[{lo_m[j]:.4g}, {hi_m[j]:.4g}] {unit}"
        unit_k = unit
    else:
        limit = vel[j] if kind == "velocity" else acc[j]
        excess = abs(value) - limit
        unit_k = f"{unit}/s" if kind == "velocity" else f"{unit}/s^2"
        allowed = f"+-{limit:.4g} {unit_k}"
    others = sum(int(np.any(np.nan_to_num(u) > 1.0 + 1e-12)) for u in uses) - 1
    also = f" (and {others} other limit kind(s) exceeded)" if others > 0 else ""
    raise InfeasibleTrajectoryError(
        f"joint {name!r} exceeds its {kind} limit by {excess:.4g} {unit_k} at t={t[k]:.4g} s: "
        f"{kind} {value:.4g} {unit_k}, allowed {allowed} with margin {margin:g}{also}",
        joint=name,
        limit=kind,
        excess=float(excess),
    )
