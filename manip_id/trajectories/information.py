"""Information of a motion about the base parameters, the design criteria, their exact gradients.

On times ``t_k`` (k < n), with per-joint noise variances ``sigma_j^2`` [(N m)^2]
and each sample standing for ``scale`` samples of the run (``scale = rate T / n``)::

    F(x) = F0 + scale sum_k Y_b(t_k)^T S^-1 Y_b(t_k)       (r, r),  S = diag(sigma^2)

``Y_b`` = the base columns of the regressor (rigid bodies and enabled joint
terms), ``F0`` the information already held (a previous result's inverse
covariance, else 0). The criteria, all minimized:

    d     -log det F                    (D-optimal, the default)
    cond  log(lambda_max / lambda_min)  (of F; half of it is log cond of W when F0 = 0)
    e     -log lambda_min(F)            (E-optimal)

``df = <dF, Gf>`` with ``Gf = -F^-1`` (d), ``v1 v1^T / l1 - vr vr^T / lr`` (cond),
``-vr vr^T / lr`` (e); ``dF = scale sum_k (dY_k^T S^-1 Y_k + Y_k^T S^-1 dY_k)``, so
``df = sum_k <B_k, dY_k>`` with ``B_k = 2 scale S^-1 Y_k Gf`` (nv, r).

``<B_k, dY_k>`` is differentiated exactly: row ``j`` of the rigid part is
``tau_j(q, dq, ddq; theta_j)`` with ``theta_j`` = row ``j`` of ``B_k`` on the rigid
base columns (zero elsewhere), and ``d tau / d(q, dq, ddq)`` comes from
``pinocchio.computeRNEADerivatives`` on a copy of the model whose inertias hold
``theta_j + alpha theta_ref`` (``alpha theta_ref`` keeps every mass non-zero, its own
derivative is subtracted: the map is linear in theta). Joint-term columns are
differentiated analytically. Eigenvalue criteria (cond, e) are exact where the
extreme eigenvalues are simple.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..robot.model import Robot
from ..robot.regressor import iter_regressor
from .fourier import trajectory_to_configuration

CRITERIA = ("d", "cond", "e")

#: Joint terms whose columns are differentiated analytically: (state 0 q, 1 dq, 2 ddq) or None
#: for a column with zero derivative almost everywhere (steps in dq).
_TERM_STATE = {
    "Ia": 2,
    "fv": 1,
    "k": 0,
    "fc": None,
    "fo": None,
    "fcp": None,
    "fcn": None,
    "fvp": 1,
    "fvn": 1,
}


def criterion_value(F: np.ndarray, kind: str) -> tuple[float, np.ndarray]:
    """``(f(F), df/dF)`` of a criterion (module docstring); ``+inf`` when F is singular."""
    lam, E = np.linalg.eigh(0.5 * (F + F.T))
    if not lam[0] > 1e-300:
        return math.inf, np.zeros_like(F)
    if kind == "d":
        return -float(np.sum(np.log(lam))), -(E / lam) @ E.T
    v1, vr = E[:, -1], E[:, 0]
    if kind == "cond":
        return math.log(lam[-1] / lam[0]), np.outer(v1, v1) / lam[-1] - np.outer(vr, vr) / lam[0]
    if kind == "e":
        return -math.log(lam[0]), -np.outer(vr, vr) / lam[0]
    raise InputError(f"criterion must be one of {', '.join(CRITERIA)}, got {kind!r}")


class InformationModel:
    """Base-regressor information of motions of one robot, with exact derivatives.

    Parameters
    ----------
    robot : Robot
        the robot (its joint terms enabled as the identification will use them).
    base : array_like
        base column indices, shape (r,).
    noise_std : array_like
        per-joint torque noise std [N m or N], shape (nv,).
    """

    def __init__(self, robot: Robot, base, noise_std):
        self.robot = robot
        self.base = np.asarray(base, dtype=int)
        self.nv = robot.nv
        self.inv_var = 1.0 / np.asarray(noise_std, float) ** 2
        rigid = self.base < robot.n_rigid
        self._rigid_pos = np.flatnonzero(rigid)
        self._rigid_cols = self.base[rigid]
        self._joint_derivs: list[tuple[int, int, int]] = []
        for pos in np.flatnonzero(~rigid):
            owner = robot.layout.owner(int(self.base[pos]))
            if owner.kind == "motor":  # columns of R^T: no analytic derivative here
                raise InputError(
                    "excitation design does not take motor terms (manip_id.robot.transmission): "
                    "design it on the robot without them (Robot.with_transmission(None))"
                )
            if owner.parameter not in _TERM_STATE:
                raise InputError(
                    f"excitation design differentiates the joint terms "
                    f"{', '.join(_TERM_STATE)}; got {owner.parameter!r} ({owner.joint})"
                )
            state = _TERM_STATE[owner.parameter]
            if state is not None:
                self._joint_derivs.append((int(pos), owner.index, state))
        # one model per row, armature zero (the regressor has no armature in its rigid part)
        self._models = []
        for _ in range(self.nv):
            m = robot.model.copy()
            m.armature = np.zeros(m.nv)
            self._models.append((m, m.createData()))
        ref = np.array(
            [robot.model.inertias[i].toDynamicParameters() for i in range(1, robot.model.njoints)]
        )
        self._theta_ref = ref.ravel()  # (n_rigid,)
        masses = self._theta_ref[0::10]
        self._least_mass = float(np.min(masses[masses > 0]))  # [kg]
        self._lower = np.tril_indices(self.nv, -1)
        self._ref_model = self._models[0][0].copy()
        self._ref_data = self._ref_model.createData()

    @property
    def r(self) -> int:
        return int(self.base.size)

    def matrix(self, angles, dq, ddq) -> np.ndarray:
        """``Y_b`` at the samples, shape (n, nv, r)."""
        q = trajectory_to_configuration(self.robot, angles)
        n = q.shape[0]
        W = np.empty((n, self.nv, self.r))
        for c in iter_regressor(self.robot, q, dq, ddq, chunk=max(n, 1)):
            W[c.start : c.stop] = c.Y[:, :, self.base]
        return W

    def information(self, W: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """``scale sum_k Y_k^T S^-1 Y_k``, shape (r, r)."""
        Ws = W * np.sqrt(self.inv_var)[None, :, None]
        flat = Ws.reshape(-1, self.r)
        return scale * (flat.T @ flat)

    def weights(self, W: np.ndarray, Gf: np.ndarray, scale: float) -> np.ndarray:
        """``B_k = 2 scale S^-1 Y_k Gf`` for a criterion gradient ``Gf``, shape (n, nv, r)."""
        return 2.0 * scale * self.inv_var[None, :, None] * (W @ Gf)

    def pullback(self, B: np.ndarray, angles, dq, ddq) -> np.ndarray:
        """``d/d(q_k, dq_k, ddq_k) sum_k <B_k, Y_b(q_k, dq_k, ddq_k)>``, shape (3, n, nv)."""
        n, nv = B.shape[0], self.nv
        g = np.zeros((3, n, nv))
        q = trajectory_to_configuration(self.robot, angles)
        if self._rigid_pos.size:
            theta = np.zeros((n, nv, self.robot.n_rigid))
            theta[:, :, self._rigid_cols] = B[:, :, self._rigid_pos]
            for k in range(n):
                g[:, k] = self._rigid_rows(theta[k], q[k], dq[k], ddq[k])
        for pos, dof, state in self._joint_derivs:
            g[state, :, dof] += B[:, dof, pos]
        return g

    def _rigid_rows(self, theta: np.ndarray, q, v, a) -> np.ndarray:
        """``sum_j d tau_j(theta_j) / d(q, v, a)``, shape (3, nv), exact (module docstring)."""
        nb = self.robot.model.njoints - 1
        out = np.zeros((3, self.nv))
        rows = np.flatnonzero(np.any(theta, axis=1))
        if rows.size == 0:
            return out
        rq, rv, ra = pin.computeRNEADerivatives(self._ref_model, self._ref_data, q, v, a)
        ra = ra.copy()
        ra[self._lower] = ra.T[self._lower]  # Pinocchio fills the upper triangle
        alpha = 1.0 + np.max(np.abs(theta[:, 0::10]), axis=1) / self._least_mass
        shifted = (theta + alpha[:, None] * self._theta_ref).reshape(self.nv, nb, 10)
        for j in rows:
            m, d = self._models[j]
            for i in range(nb):
                m.inertias[i + 1] = pin.Inertia.FromDynamicParameters(shifted[j, i])
            dtq, dtv, dta = pin.computeRNEADerivatives(m, d, q, v, a)
            out[0] += dtq[j] - alpha[j] * rq[j]
            out[1] += dtv[j] - alpha[j] * rv[j]
            out[2] += _full_mass_row(dta, int(j)) - alpha[j] * ra[j]
        return out


def _full_mass_row(M: np.ndarray, j: int) -> np.ndarray:
    """Row ``j`` of the symmetric mass matrix from Pinocchio's upper triangle."""
    return np.concatenate([M[:j, j], M[j, j:]])
