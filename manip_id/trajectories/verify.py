"""The check of a designed motion on the run's own grid (``rate``), independent of the optimizer.

Every sample ``t_k = k / rate`` over ``[0, duration]`` is checked against the limits with
their margin (position, velocity, acceleration, torque = ``pinocchio.rnea`` of the model)
and against the clearance with a continuous-time allowance: between two samples a point
of the robot moves at most ``dt/2`` times its speed bound ``sum_j |dq_j| reach_j``
(:meth:`CollisionScene.point_speed_bound`), and both members of a pair may move, so each
sample must keep ``d_k >= clearance + dt * v_k`` (``v_k`` the larger bound of the two
neighbouring samples). Then ``d(t) >= clearance`` at every time, not only at samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import InfeasibleTrajectoryError
from ..robot.model import Robot
from .constraints import Bounds
from .fourier import FourierTrajectory, trajectory_to_configuration
from .world import CollisionScene

KINDS = ("position", "velocity", "acceleration", "torque")
#: :func:`verify_design` checks the nominal model's torques (``pinocchio.rnea``).
NOMINAL = "nominal"


@dataclass(frozen=True)
class DesignCheck:
    """Result of :func:`verify_design`.

    ``usage[kind]``: per joint, peak use of the limit with its margin (1 = reached, NaN =
    unset), shape (nv,); ``min_clearance`` [m] the least distance over the samples
    (inf without pairs) between ``closest_pair`` at ``closest_time`` [s], at the witness
    points ``closest_points`` (one on each member, base frame [m], shape (2, 3));
    ``clearance_allowance`` [m] the largest continuous-time allowance used; ``violation``
    ``(kind, what, time, value, allowed)`` of the worst violation, or None.
    """

    usage: dict
    min_clearance: float
    closest_pair: tuple[str, str] | None
    closest_time: float | None
    clearance_allowance: float
    violation: tuple | None
    closest_points: np.ndarray | None = None

    def usage_dict(self, joint_names: list[str]) -> dict:
        return {
            kind: {
                n: (None if not np.isfinite(u) else float(u))
                for n, u in zip(joint_names, use, strict=True)
            }
            for kind, use in self.usage.items()
        }

    def max_usage(self) -> dict:
        return {
            k: (float(np.nanmax(u)) if np.isfinite(u).any() else None)
            for k, u in self.usage.items()
        }

    def error(self) -> InfeasibleTrajectoryError:
        kind, what, t, value, allowed = self.violation  # type: ignore[misc]
        if kind == "clearance":
            msg = (
                f"no motion found keeping the clearance: {what[0]} and {what[1]} are "
                f"{value:.4g} m apart at t={t:.4g} s, need {allowed:.4g} m (clearance plus "
                "the between-samples allowance)"
            )
            return InfeasibleTrajectoryError(
                msg, joint=" / ".join(what), limit=kind, excess=allowed - value
            )
        msg = (
            f"no motion found within the {kind} limit of joint {what!r}: {value:.4g} at "
            f"t={t:.4g} s, allowed {allowed:.4g} with the margin"
        )
        return InfeasibleTrajectoryError(msg, joint=what, limit=kind, excess=abs(value) - allowed)


def verify_design(
    robot: Robot,
    trajectory: FourierTrajectory,
    duration: float,
    rate: float,
    bounds: Bounds,
    scene: CollisionScene | None,
    *,
    clearance: float,
    torque=NOMINAL,
) -> DesignCheck:
    """Check ``trajectory`` at ``rate`` [Hz] over ``[0, duration]`` (module docstring);
    ``torque``: :data:`NOMINAL` (``pinocchio.rnea`` of the robot's model), None (torques
    not checked) or an :class:`~.identified_torque.IdentifiedTorques`, whose torques with
    their ``k`` standard deviations are checked."""
    n = int(round(duration * rate)) + 1
    t = np.linspace(0.0, duration, n)
    angles, dq, ddq = trajectory.sample(t)
    q = trajectory_to_configuration(robot, angles)
    if torque is not None and torque is not NOMINAL:
        tau = torque.magnitude(angles, dq, ddq)
    elif torque is NOMINAL:
        model, data = robot.model, robot.model.createData()
        tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(n)])
    else:
        tau = np.full_like(dq, np.nan)
    mid, half = 0.5 * (bounds.lo + bounds.hi), 0.5 * (bounds.hi - bounds.lo)
    with np.errstate(invalid="ignore", divide="ignore"):
        uses = {
            "position": np.abs(angles - mid) / half,
            "velocity": np.abs(dq) / bounds.velocity,
            "acceleration": np.abs(ddq) / bounds.acceleration,
            "torque": np.abs(tau) / bounds.effort,
        }
    values = {"position": angles, "velocity": dq, "acceleration": ddq, "torque": tau}
    usage = {k: _peak(u) for k, u in uses.items()}
    violation: tuple | None = None
    worst = 1.0 + 1e-9
    for kind, u in uses.items():
        uu = np.where(np.isfinite(u), u, -np.inf)
        k, j = np.unravel_index(np.argmax(uu), uu.shape)
        if uu[k, j] > worst:
            worst = float(uu[k, j])
            allowed = {
                "position": bounds.hi[j] if values[kind][k, j] > mid[j] else bounds.lo[j],
                "velocity": bounds.velocity[j],
                "acceleration": bounds.acceleration[j],
                "torque": bounds.effort[j],
            }[kind]
            violation = (
                kind,
                robot.dof_names[j],
                float(t[k]),
                float(values[kind][k, j]),
                float(allowed),
            )
    d_min, pair, t_min, allowance, points = np.inf, None, None, 0.0, None
    if scene is not None and scene.n_pairs:
        dists = np.empty(n)
        which = np.empty(n, dtype=int)
        for i in range(n):
            d = scene.distances(q[i])
            which[i] = int(np.argmin(d))
            dists[i] = d[which[i]]
        speed = np.abs(dq) @ scene.reach
        speed = np.maximum(speed, np.concatenate([speed[1:], speed[-1:]]))
        speed = np.maximum(speed, np.concatenate([speed[:1], speed[:-1]]))
        dt = duration / (n - 1)
        need = clearance + dt * speed
        kc = int(np.argmin(dists))
        a, b = scene.pairs[which[kc]]
        d_min, pair, t_min = float(dists[kc]), (scene.names[a], scene.names[b]), float(t[kc])
        points = np.array(scene.witness_points(q[kc], which[kc]))
        allowance = float(np.max(dt * speed))
        short = dists - need
        kk = int(np.argmin(short))
        if short[kk] < 0 and violation is None:
            a, b = scene.pairs[which[kk]]
            violation = ("clearance", (scene.names[a], scene.names[b]), float(t[kk]),
                         float(dists[kk]), float(need[kk]))  # fmt: skip
    return DesignCheck(usage, d_min, pair, t_min, allowance, violation, points)


def named_values(names, values) -> dict:
    """``{name: value}`` with None for a value that is not finite (JSON-safe)."""
    return {n: (float(v) if np.isfinite(v) else None) for n, v in zip(names, values, strict=True)}


def _peak(use: np.ndarray) -> np.ndarray:
    peak = np.max(np.where(np.isfinite(use), use, -np.inf), axis=0)
    return np.where(np.isneginf(peak), np.nan, peak)
