"""The constraints of an excitation design on a time grid, with their Jacobians in ``z``.

All are ``c(z) >= 0`` (SciPy's convention) over the grid ``t_k`` (spacing ``dt``):

    position      lo_j + m w_j + s_j  <=  q_j(t_k)  <=  hi_j - m w_j - s_j
    velocity      |dq_j(t_k)|  <= (1 - m) v_j - s_j B
    acceleration  |ddq_j(t_k)| <= (1 - m) a_j - s_j B^2
    torque        |tau_j(t_k)| <= (1 - m) e_j                   (tau = rnea of the model)
    clearance     d(q(t_k))    >= clearance + buffer           (the closest pair)

with ``w_j = hi_j - lo_j``, ``v_j``, ``a_j``, ``e_j`` the velocity, acceleration and
effort limits and ``m`` the relative margin. The slacks ``s_j = dt^2/8 min(a_j, B v_j)``
keep each signal within its limit between grid times: at an extremum between two
samples the derivative vanishes, so the overshoot over the nearest sample (at most
``dt/2`` away) is at most ``dt^2/8`` times the largest second derivative; and by
Bernstein's inequality a trigonometric polynomial of top pulsation ``B = L wf``
has ``max |f'| <= B max |f - c|``, so ``|ddq| <= B v_j`` and each further derivative
costs another factor ``B``. The first three are linear
in ``z`` (``G z <= h``); torque and clearance are not, their Jacobians are exact
(``pinocchio.computeRNEADerivatives``; the witness-point Jacobian of
:mod:`.world`). The final trajectory is checked again on the dense grid of the
run (:mod:`.verify`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot.model import Robot
from .fourier import trajectory_to_configuration
from .rest import RestFourier
from .world import CollisionScene


@dataclass(frozen=True)
class Bounds:
    """Per-DoF limits with the margin applied (NaN or inf: none), shape (nv,) each."""

    lo: np.ndarray  # [rad or m]
    hi: np.ndarray
    velocity: np.ndarray  # [rad/s or m/s]
    acceleration: np.ndarray  # [rad/s^2 or m/s^2], NaN when unset
    effort: np.ndarray  # [N m or N], NaN when unset


def linear_constraints(family: RestFourier, t: np.ndarray, bounds: Bounds):
    """``(G, h)`` with ``G z <= h`` for the position, velocity and acceleration limits on ``t``."""
    P, V, A = family.bases(t)
    nv, k = family.nv, P.shape[1]
    dt = float(t[1] - t[0]) if t.size > 1 else 0.0
    rows, rhs = [], []
    for j in range(nv):
        block = np.zeros((t.size, family.n_free))
        cols = slice(j * k, (j + 1) * k)
        acc = bounds.acceleration[j]
        top = family.harmonics * family.wf  # [rad/s] B
        s = dt**2 / 8.0 * np.fmin(acc, top * bounds.velocity[j])
        vel = bounds.velocity[j] - s * top
        for basis, upper, lower in (
            (P, bounds.hi[j] - family.start[j] - s, bounds.lo[j] - family.start[j] + s),
            (V, vel, -vel),
            (A, acc - s * top**2, -acc + s * top**2),
        ):
            if not np.isfinite(upper):
                continue
            g = block.copy()
            g[:, cols] = basis
            rows += [g, -g]
            rhs += [np.full(t.size, upper), np.full(t.size, -lower)]
    return np.vstack(rows), np.concatenate(rhs)


def chain_jacobian(family: RestFourier, t: np.ndarray, dq_: np.ndarray, dv_: np.ndarray, da_):
    """``d c / d z`` from ``d c / d(q, dq, ddq)`` per sample, each (n, m, nv); shape (n m, nz)."""
    P, V, A = family.bases(t)
    n, m, nv = dq_.shape
    J = dq_[..., None] * P[:, None, None, :] + dv_[..., None] * V[:, None, None, :]
    J += da_[..., None] * A[:, None, None, :]
    return J.reshape(n * m, nv * P.shape[1])


class TorqueConstraint:
    """``(1 - m) e_j -+ tau_j(t_k) >= 0`` on the joints with an effort limit."""

    def __init__(self, robot: Robot, family: RestFourier, t: np.ndarray, effort: np.ndarray):
        self.robot, self.family, self.t = robot, family, t
        self.joints = np.flatnonzero(np.isfinite(effort))
        self.effort = effort[self.joints]
        self.effort_all = np.asarray(effort, float)
        self.model = robot.model
        self.data = robot.model.createData()

    def torques(self, angles, dq, ddq, derivatives: bool = False):
        q = trajectory_to_configuration(self.robot, angles)
        n, nv = q.shape[0], self.robot.nv
        tau = np.empty((n, nv))
        D = np.empty((3, n, nv, nv)) if derivatives else None
        for k in range(n):
            if derivatives:
                dtq, dtv, dta = pin.computeRNEADerivatives(
                    self.model, self.data, q[k], dq[k], ddq[k]
                )
                D[0, k], D[1, k] = dtq, dtv  # type: ignore[index]
                D[2, k] = np.triu(dta) + np.triu(dta, 1).T  # type: ignore[index]
                tau[k] = pin.rnea(self.model, self.data, q[k], dq[k], ddq[k])
            else:
                tau[k] = pin.rnea(self.model, self.data, q[k], dq[k], ddq[k])
        return tau, D

    def __call__(self, z):
        tau, _ = self.torques(*self.family.states(z, self.t))
        tj = tau[:, self.joints]
        return np.concatenate([(self.effort - tj).ravel(), (self.effort + tj).ravel()])

    def jacobian(self, z):
        _, D = self.torques(*self.family.states(z, self.t), derivatives=True)
        Dj = D[:, :, self.joints]
        J = chain_jacobian(self.family, self.t, Dj[0], Dj[1], Dj[2])
        return np.vstack([-J, J])

    def screen(self, z, near) -> tuple[np.ndarray]:
        """``(rows,)``: a bool mask of the rows ``near`` (:mod:`.working_set`) finds close
        to their bound at ``z``, shape (2 n nj,); the room of a row is its effort limit."""
        nj, n = self.joints.size, self.t.size
        blocks = self(z).reshape(2, n, nj).transpose(0, 2, 1).reshape(2 * nj, n)
        mask = near(blocks, np.tile(self.effort, 2)[:, None])
        return (mask.reshape(2, nj, n).transpose(0, 2, 1).ravel(),)

    def restricted(self, mask) -> _RowSubset | None:
        """The rows of ``mask`` (:meth:`screen`), evaluated at their grid times only."""
        (rows,) = mask
        if not rows.any():
            return None
        nj, n = self.joints.size, self.t.size
        times = rows.reshape(2, n, nj).any(axis=(0, 2))
        sub = self._like(self.t[times], self.effort_all)
        return _RowSubset(sub, rows.reshape(2, n, nj)[:, times, :].ravel())

    def _like(self, t, effort) -> TorqueConstraint:
        """The same constraint on other grid times ``t`` and effort limits."""
        return TorqueConstraint(self.robot, self.family, t, effort)

    def rows(self, mask) -> int:
        return 0 if mask is None else int(mask[0].sum())


class _RowSubset:
    """Some rows of a constraint (values and Jacobian)."""

    def __init__(self, constraint, rows: np.ndarray):
        self.constraint, self.keep = constraint, rows

    def __call__(self, z):
        return self.constraint(z)[self.keep]

    def jacobian(self, z):
        return self.constraint.jacobian(z)[self.keep]


class ClearanceConstraint:
    """``d(q(t_k)) - limit - dt v_k >= 0`` for the closest pair at each grid time.

    ``v_k = sum_j |dq_j(t_k)| reach_j`` bounds the speed of every robot point
    (:meth:`CollisionScene.point_speed_bound`); ``dt v_k`` covers both members of a
    pair moving for ``dt/2`` towards each other, so the clearance holds between grid
    times too (up to the speed changing within ``dt/2``: the final check covers that).
    """

    #: Least room [m] a clearance row is screened against (:meth:`screen`).
    MIN_ROOM = 0.05

    def __init__(
        self,
        scene: CollisionScene,
        family: RestFourier,
        t: np.ndarray,
        limit: float,
        dt: float | None = None,
    ):
        self.scene, self.family, self.t, self.limit = scene, family, t, float(limit)
        if dt is None:
            dt = float(t[1] - t[0]) if t.size > 1 else 0.0
        self.dt = float(dt)  # [s] the grid spacing the between-samples allowance covers
        self._cache: tuple[bytes, np.ndarray, np.ndarray, np.ndarray] | None = None

    def _eval(self, z):
        key = np.asarray(z, float).tobytes()
        if self._cache is None or self._cache[0] != key:
            angles, dq, _ = self.family.states(z, self.t)
            q = trajectory_to_configuration(self.scene.robot, angles)
            n, nv = q.shape[0], self.family.nv
            d, g = np.empty(n), np.empty((n, nv))
            for k in range(n):
                best, grad = self.scene.closest(q[k], gradient=True)
                d[k], g[k] = best.distance, grad
            self._cache = (key, d, g, dq)
        return self._cache[1:]

    def __call__(self, z):
        d, _, dq = self._eval(z)
        return d - self.limit - self.dt * (np.abs(dq) @ self.scene.reach)

    def jacobian(self, z):
        _, g, dq = self._eval(z)
        dv = -self.dt * np.sign(dq) * self.scene.reach
        zero = np.zeros_like(g)[:, None, :]
        return chain_jacobian(self.family, self.t, g[:, None, :], dv[:, None, :], zero)

    def screen(self, z, near) -> tuple[np.ndarray]:
        """``(times,)``: the grid times ``near`` (:mod:`.working_set`) finds close to the
        clearance at ``z``; the room is the start pose's slack (at least :data:`MIN_ROOM`)."""
        q = trajectory_to_configuration(self.scene.robot, self.family.start[None, :])[0]
        room = max(self.scene.closest(q)[0].distance - self.limit, self.MIN_ROOM)
        return (near(self(z)[None, :], np.array([[room]]))[0],)

    def restricted(self, mask) -> ClearanceConstraint | None:
        """The constraint on the grid times of ``mask`` (:meth:`screen`), same allowance."""
        (times,) = mask
        if not times.any():
            return None
        return ClearanceConstraint(self.scene, self.family, self.t[times], self.limit, self.dt)

    def rows(self, mask) -> int:
        return 0 if mask is None else int(mask[0].sum())
