"""Forward dynamics of an identified model and its exact linearization.

The model ``tau = Y(q, dq, ddq) theta`` solved for the acceleration, with the measured
torque as input::

    M(q) ddq + h(q, dq) + f(q, dq) = tau
    ddq = aba(q, dq, tau - f(q, dq))           Pinocchio's ABA (armature ``Ia`` in M)

``f`` are the joint terms besides the armature (viscous ``fv dq``, Coulomb, offset,
spring, ...). The Coulomb column ``sign(dq_j)`` is discontinuous at rest; forward in time
it is regularized as ``tanh(dq_j / eps_j)`` [rad/s or m/s] (:func:`coulomb_width`), in the
regressor of the sensitivities too, so that model and sensitivities agree.

Linearization, exact (the model is linear in its parameters)::

    d ddq / d theta_b = -M(q)^-1 Y_b(q, dq, ddq)                  (nv, r)
    d ddq / d q  = ABA_q  - M^-1 diag(df_j / dq_j)                   (nv, nv)
    d ddq / d dq = ABA_dq - M^-1 diag(df_j / d dq_j)

with ``ABA_q``, ``ABA_dq`` from ``pinocchio.computeABADerivatives`` and the joint terms'
own derivatives (analytic for ``fv``, ``fc``, ``fo``, ``k``; a central difference for the
other smooth laws). Laws that need the measured load, temperature or path (``fl``,
``fvt``/``fct``, ``fh``) have no forward model here and are refused.

A standard vector with given base parameters is the nominal one corrected on the
independent columns, ``theta = theta_nom + from_base(theta_b - to_base(theta_nom))``
(exact: ``to_base(theta) == theta_b``; the regrouped columns keep their nominal values,
which keeps every body's inertia a valid Pinocchio one).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..identifiability import BaseParameters
from ..robot.model import Robot

#: Smallest Coulomb regularization width [rad/s or m/s] (:func:`coulomb_width`).
DEFAULT_EPS = 0.01
_ANALYTIC = {"Ia", "fv", "fc", "fo", "k"}


def standard_with_base(robot: Robot, theta_base, base: BaseParameters) -> np.ndarray:
    """The standard vector (p,) with base parameters ``theta_base`` (r,), nominal elsewhere."""
    nominal = robot.nominal_parameters
    return nominal + base.from_base(np.asarray(theta_base, float) - base.to_base(nominal))


def coulomb_width(robot: Robot, theta, q, dt: float, eps: float = DEFAULT_EPS) -> np.ndarray:
    """Per joint regularization width of ``sign(dq)`` [rad/s or m/s], shape (nv,).

    ``eps_j = max(eps, dt |fc_j| / min_q M_jj(q))``: at least ``eps``, and wide enough that
    one explicit step of length ``dt`` [s] through the friction's stiffest slope
    ``fc_j / eps_j`` does not overshoot (``dt fc_j / (eps_j M_jj) <= 1``); ``M_jj`` the
    smallest diagonal inertia over the configurations ``q`` (K, nq).
    """
    nv = robot.nv
    out = np.full(nv, float(eps))
    if "fc" not in robot.terms.enabled:
        return out
    model = robot.with_parameters(theta)
    data = model.createData()
    qs = np.atleast_2d(np.asarray(q, float))
    mjj = np.min([np.diag(pin.crba(model, data, qk)) for qk in qs], axis=0)
    fc = np.abs(np.asarray(theta, float)[robot.layout.joint_columns("fc")])
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(mjj > 0, dt * fc / mjj, 0.0)  # M_jj <= 0: no model to integrate
    return np.maximum(out, need)


class ForwardModel:
    """``ddq = aba(q, dq, tau - f(q, dq))`` of one standard vector, with its linearization.

    Parameters
    ----------
    robot: the robot (its joint terms and layout).
    theta: standard parameters, shape (p,).
    eps: Coulomb regularization width per joint (nv,) [rad/s or m/s] (module docstring).
    base: the base parametrization of the sensitivities (None: the standard parameters).
    """

    def __init__(self, robot: Robot, theta, eps, base: BaseParameters | None = None):
        ev = robot.evaluator
        ev.refuse_load("a forward rollout")
        ev.refuse_temperature("a forward rollout")
        if robot.nq != robot.nv:
            raise InputError(
                f"a forward rollout integrates q with dq: robot.nq={robot.nq} but "
                f"robot.nv={robot.nv} (continuous joints are not supported)"
            )
        self.robot = robot
        self.theta = np.asarray(theta, dtype=float)
        self.eps = np.broadcast_to(np.asarray(eps, dtype=float), (robot.nv,)).copy()
        if not np.all(self.eps > 0):
            raise InputError(f"the Coulomb regularization widths must be > 0, got {self.eps}")
        self.model = robot.with_parameters(self.theta)
        self.data = self.model.createData()
        self.columns = (
            np.arange(robot.n_parameters) if base is None else np.asarray(base.independent)
        )
        self._ev = ev
        self._terms = list(ev.terms)
        coef = robot.layout.joint_block(self.theta) if self._terms else np.zeros((robot.nv, 0))
        self._coef = np.array(coef, dtype=float)
        if "Ia" in self._terms:
            self._coef[:, self._terms.index("Ia")] = 0.0  # in M (with_parameters)
        self._fc = self._terms.index("fc") if "fc" in self._terms else None
        self._fc_cols = robot.layout.joint_columns("fc") if self._fc is not None else None
        self._zero = np.zeros(robot.nv)

    # ------------------------------------------------------------ joint terms
    def _values(self, q, dq) -> np.ndarray:
        """Joint-term columns (nv, nt) at (q, dq), sign regularized, no armature."""
        vals = np.array(self._ev.joint_values(q, dq, self._zero), dtype=float)
        if self._fc is not None:
            vals[:, self._fc] = np.tanh(dq / self.eps)
        return vals

    def joint_torque(self, q, dq) -> np.ndarray:
        """``f(q, dq)``, shape (nv,) [N m or N]."""
        if not self._terms:
            return self._zero.copy()
        return np.einsum("jt,jt->j", self._values(q, dq), self._coef)

    def _joint_slopes(self, q, dq) -> tuple[np.ndarray, np.ndarray]:
        """``df_j/dq_j`` and ``df_j/d dq_j``, shape (nv,) each."""
        nv = self.robot.nv
        dfq, dfv = np.zeros(nv), np.zeros(nv)
        for i, t in enumerate(self._terms):
            c = self._coef[:, i]
            if t == "fv":
                dfv += c
            elif t == "fc":
                dfv += c / (self.eps * np.cosh(dq / self.eps) ** 2)
            elif t == "k":
                dfq += c
            elif t not in _ANALYTIC:  # a smooth law of (angle, velocity): central differences
                # each joint's term depends on its own coordinate: shift all at once
                hq, hv = 1e-6 * (1.0 + np.abs(q)), 1e-6 * (1.0 + np.abs(dq))
                jv, z = self._ev.joint_values, self._zero
                dfq += c * (jv(q + hq, dq, z)[:, i] - jv(q - hq, dq, z)[:, i]) / (2 * hq)
                dfv += c * (jv(q, dq + hv, z)[:, i] - jv(q, dq - hv, z)[:, i]) / (2 * hv)
        return dfq, dfv

    # ------------------------------------------------------------ dynamics
    def acceleration(self, q, dq, tau) -> np.ndarray:
        """``ddq``, shape (nv,) [rad/s^2 or m/s^2], for torque ``tau`` (nv,) [N m or N]."""
        return np.array(pin.aba(self.model, self.data, q, dq, tau - self.joint_torque(q, dq)))

    def linearization(self, q, dq, tau):
        """``(ddq, A_q, A_dq, A_theta)``: the acceleration and its derivatives with respect
        to q (nv, nv), dq (nv, nv) and the parameters of :attr:`columns` (nv, r)."""
        pin.computeABADerivatives(self.model, self.data, q, dq, tau - self.joint_torque(q, dq))
        ddq = np.array(self.data.ddq)
        minv = np.triu(self.data.Minv)
        minv = minv + np.triu(minv, 1).T
        dfq, dfv = self._joint_slopes(q, dq)
        a_q = np.array(self.data.ddq_dq) - minv * dfq
        a_v = np.array(self.data.ddq_dv) - minv * dfv
        Y = self._ev.regressor(q, dq, ddq)
        if self._fc_cols is not None:
            Y[np.arange(self.robot.nv), self._fc_cols] = np.tanh(dq / self.eps)
        return ddq, a_q, a_v, -minv @ Y[:, self.columns]


__all__ = ["DEFAULT_EPS", "ForwardModel", "coulomb_width", "standard_with_base"]
