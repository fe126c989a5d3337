"""The true robot of a closed-loop run: forward dynamics with its joint terms, the
integrator, and the sensors the controller reads (see :mod:`manip_id.control.closed_loop`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from ..._checks import as_float_array, check_finite
from ...errors import InputError
from ...physics.perturbation import require_physical
from ...robot.model import Robot


class Plant:
    """The true robot: forward dynamics with its joint terms, and the integrator.

    ``ddq = aba(model(theta), q, dq, tau - tau_joint(q, dq))`` (see the module docstring),
    integrated over one control period ``dt = 1 / rate`` [s] in ``substeps`` fixed steps
    ``h = 1 / (rate * substeps)`` [s] with the torque held.

    Parameters
    ----------
    robot : Robot
        the robot; its joint terms are the plant's.
    theta_true : array_like
        parameters of the plant, shape (p,), physically consistent.
    rate : float
        control rate [Hz].
    substeps : int
        physics steps per control period.
    integrator : str
        ``"euler"`` (semi-implicit) or ``"rk4"``.
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
        require_physical(robot, theta)  # a message naming the body
        robot.evaluator.refuse_load("the closed-loop plant (forward dynamics)")
        robot.evaluator.refuse_temperature("the closed-loop plant (forward dynamics)")
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
    std_q : float
        standard deviation on positions [rad] (applied in the tangent space).
    std_dq : float
        standard deviation on velocities [rad/s].
    rng : numpy.random.Generator
        the generator; ``q`` is drawn before ``dq`` at every step.
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
