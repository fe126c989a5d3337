"""Torque limits with an identified model and its uncertainty (a ``--from`` design).

With the base parameters ``theta_b`` of an identification result and their covariance
``C`` (shape (r, r)), the torque of joint ``j`` at a sample and its standard deviation::

    tau_j = y_j theta_b,        s_j = sqrt(y_j C y_j^T)

(``y_j`` = row ``j`` of the base regressor, joint terms included: the friction the
result identified counts). The limit holds with ``k`` standard deviations::

    |tau_j| + k s_j <= (1 - m) e_j,   i.e.   e - (tau + k s) >= 0  and  e + (tau - k s) >= 0

Both rows are differentiated exactly: ``d(tau_j +- k s_j) = <theta_b +- k C y_j / s_j,
d y_j>``, a weighted derivative of one regressor row, which
:meth:`.information.InformationModel.pullback` computes.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..robot.model import Robot
from .constraints import TorqueConstraint, chain_jacobian
from .information import InformationModel
from .rest import RestFourier


class IdentifiedTorques:
    """Torques of the identified model with ``k`` standard deviations (module docstring).

    Parameters
    ----------
    robot : Robot
        the robot, with the joint terms the result was identified with.
    base : array_like
        the result's base columns, shape (r,).
    estimate : array_like
        its base parameters, shape (r,).
    covariance : array_like
        their covariance, shape (r, r).
    k : float
        standard deviations added to the predicted torque magnitude (>= 0).
    """

    def __init__(self, robot: Robot, base, estimate, covariance, k: float):
        self.info = InformationModel(robot, base, np.ones(robot.nv))
        self.theta = np.asarray(estimate, float)
        self.cov = np.asarray(covariance, float)
        r = self.info.r
        if self.theta.shape != (r,) or self.cov.shape != (r, r):
            raise InputError(
                f"identified torques: expected {r} estimates and a ({r}, {r}) covariance, got "
                f"{self.theta.shape} and {self.cov.shape}"
            )
        if not (np.isfinite(k) and k >= 0):
            raise InputError(f"sigma (standard deviations of the torque) must be >= 0, got {k}")
        self.k = float(k)

    def mean_std(self, angles, dq, ddq) -> tuple[np.ndarray, np.ndarray]:
        """``(tau, s)`` [N m or N] at the samples, each of shape (n, nv)."""
        W = self.info.matrix(angles, dq, ddq)
        var = np.einsum("kjr,rs,kjs->kj", W, self.cov, W)
        return W @ self.theta, np.sqrt(np.clip(var, 0.0, None))

    def magnitude(self, angles, dq, ddq) -> np.ndarray:
        """``tau + sign(tau) k s``: the torque the limit is checked on, shape (n, nv)."""
        tau, s = self.mean_std(angles, dq, ddq)
        return tau + np.where(tau >= 0, 1.0, -1.0) * self.k * s

    def row_derivatives(self, angles, dq, ddq, joints, sign: float) -> np.ndarray:
        """``d(tau_j + sign k s_j) / d(q, dq, ddq)`` of the ``joints``, shape (3, n, nj, nv)."""
        W = self.info.matrix(angles, dq, ddq)
        s = np.sqrt(np.clip(np.einsum("kjr,rs,kjs->kj", W, self.cov, W), 1e-300, None))
        n, nv = W.shape[:2]
        out = np.zeros((3, n, len(joints), nv))
        for i, j in enumerate(joints):
            B = np.zeros_like(W)
            B[:, j, :] = self.theta + sign * self.k * (W[:, j, :] @ self.cov) / s[:, j, None]
            out[:, :, i, :] = self.info.pullback(B, angles, dq, ddq)
        return out


class UncertainTorqueConstraint(TorqueConstraint):
    """``(1 - m) e_j -+ (tau_j +- k s_j) >= 0`` of the identified model (module docstring)."""

    def __init__(self, robot, family: RestFourier, t, effort, model: IdentifiedTorques):
        super().__init__(robot, family, t, effort)
        self.model = model

    def _like(self, t, effort) -> UncertainTorqueConstraint:
        return UncertainTorqueConstraint(self.robot, self.family, t, effort, self.model)

    def __call__(self, z):
        tau, s = self.model.mean_std(*self.family.states(z, self.t))
        up = (tau + self.model.k * s)[:, self.joints]
        lo = (tau - self.model.k * s)[:, self.joints]
        return np.concatenate([(self.effort - up).ravel(), (self.effort + lo).ravel()])

    def jacobian(self, z):
        states = self.family.states(z, self.t)
        up = self.model.row_derivatives(*states, self.joints, +1.0)
        lo = self.model.row_derivatives(*states, self.joints, -1.0)
        Ju = chain_jacobian(self.family, self.t, up[0], up[1], up[2])
        Jl = chain_jacobian(self.family, self.t, lo[0], lo[1], lo[2])
        return np.vstack([-Ju, Jl])
