"""Finite Fourier series per joint and the map from joint angles to configurations.

    q_j(t) = q0_j + sum_l [ a_jl/(l wf) sin(l wf t) - b_jl/(l wf) cos(l wf t) ]

(velocity and acceleration analytic; see the package docstring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._checks import as_float_array, check_finite
from ..errors import InputError
from ..robot.model import Robot

#: Default base pulsation [rad/s]: a period of 10 s.
DEFAULT_WF = 2.0 * math.pi / 10.0


@dataclass(frozen=True)
class FourierTrajectory:
    """A finite Fourier series per joint.

    Attributes
    ----------
    q0 : numpy.ndarray
        offset per joint [rad or m], shape (nv,)
    a : numpy.ndarray
        sine coefficients [rad/s or m/s], shape (nv, L)
    b : numpy.ndarray
        cosine coefficients [rad/s or m/s], shape (nv, L)
    wf : float
        base pulsation [rad/s]
    """

    q0: np.ndarray
    a: np.ndarray
    b: np.ndarray
    wf: float

    def __post_init__(self):
        q0 = as_float_array(self.q0, "q0", ndim=1)
        a = as_float_array(self.a, "a", ndim=2)
        b = as_float_array(self.b, "b", ndim=2)
        if a.shape != b.shape or a.shape[0] != q0.shape[0]:
            raise InputError(
                f"expected a and b of shape (nv, L) with nv = q0.shape[0]; "
                f"got {q0.shape=}, {a.shape=}, {b.shape=}"
            )
        for name, arr in (("q0", q0), ("a", a), ("b", b)):
            check_finite(arr, name)
        if not np.isfinite(self.wf) or self.wf <= 0:
            raise InputError(f"wf must be a positive pulsation [rad/s], got {self.wf}")
        object.__setattr__(self, "q0", q0)
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "wf", float(self.wf))

    @property
    def nv(self) -> int:
        """Number of joints."""
        return self.q0.shape[0]

    @property
    def harmonics(self) -> int:
        """Number of harmonics L."""
        return self.a.shape[1]

    @property
    def period(self) -> float:
        """Period 2 pi / wf [s]."""
        return 2.0 * np.pi / self.wf

    def sample(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at times ``t`` [s].

        ``t`` scalar gives arrays of shape (nv,); ``t`` of shape (N,) gives (N, nv).
        Positions are joint coordinates (angles for continuous joints, see
        :func:`trajectory_to_configuration`).
        """
        t_arr = as_float_array(t, "t", ndim=(0, 1))
        tt = np.atleast_1d(t_arr)
        l_wf = self.wf * np.arange(1, self.harmonics + 1)  # (L,)
        phase = np.multiply.outer(tt, l_wf)  # (N, L)
        s, c = np.sin(phase), np.cos(phase)
        q = self.q0 + (s / l_wf) @ self.a.T - (c / l_wf) @ self.b.T
        dq = c @ self.a.T + s @ self.b.T
        ddq = (-s * l_wf) @ self.a.T + (c * l_wf) @ self.b.T
        if t_arr.ndim == 0:
            return q[0], dq[0], ddq[0]
        return q, dq, ddq

    def __call__(self, t):
        """Same as :meth:`sample`."""
        return self.sample(t)

    def scaled(self, factor: float) -> FourierTrajectory:
        """The same motion about ``q0`` with every coefficient times ``factor``.

        Position excursion, velocity and acceleration all scale by ``factor``.
        """
        return FourierTrajectory(self.q0, self.a * factor, self.b * factor, self.wf)

    def to_vector(self) -> np.ndarray:
        """The coefficients as one vector ``x = [q0 (nv), a_1, b_1, ..., a_nv, b_nv]``.

        Shape (nv + 2 nv L,): ``q0`` first, then per joint its ``L`` sine and
        ``L`` cosine coefficients (the variables of
        :func:`~manip_id.trajectories.design_excitation`).
        """
        return np.concatenate([self.q0, np.hstack([self.a, self.b]).ravel()])

    @classmethod
    def from_vector(cls, x, nv: int, harmonics: int, wf: float) -> FourierTrajectory:
        """Inverse of :meth:`to_vector`."""
        x = as_float_array(x, "x", ndim=1)
        if x.shape[0] != nv * (1 + 2 * harmonics):
            raise InputError(
                f"{x.shape=} but nv (1 + 2 L) = {nv * (1 + 2 * harmonics)} for {nv=}, L={harmonics}"
            )
        ab = x[nv:].reshape(nv, 2 * harmonics)
        return cls(x[:nv], ab[:, :harmonics], ab[:, harmonics:], wf)

    def basis(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Time functions multiplying ``(a, b)``, each of shape (N, 2L).

        ``q_j(t) = q0_j + P(t) @ [a_j, b_j]``, ``dq_j(t) = V(t) @ [a_j, b_j]``,
        ``ddq_j(t) = A(t) @ [a_j, b_j]``; returns ``(P, V, A)``.
        """
        tt = np.atleast_1d(as_float_array(t, "t", ndim=(0, 1)))
        l_wf = self.wf * np.arange(1, self.harmonics + 1)
        phase = np.multiply.outer(tt, l_wf)
        s, c = np.sin(phase), np.cos(phase)
        P = np.hstack([s / l_wf, -c / l_wf])
        V = np.hstack([c, s])
        A = np.hstack([-s * l_wf, c * l_wf])
        return P, V, A


def dof_layout(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Per velocity coordinate: its index in q, and whether it is a continuous joint.

    Raises :class:`InputError` for joints that are neither one coordinate per
    DoF nor a continuous (cos, sin) joint.
    """
    dofs = robot.dofs
    dofs.require_coordinates("Fourier trajectories")
    return dofs.q_index, dofs.continuous


def trajectory_to_configuration(robot: Robot, angles) -> np.ndarray:
    """Joint coordinates (one per DoF) to Pinocchio configurations.

    Parameters
    ----------
    angles : array_like
        joint coordinates [rad or m], shape (nv,) or (N, nv); for a
        continuous joint the angle, stored as ``(cos, sin)`` in ``q``.

    Returns
    -------
    numpy.ndarray
        q of shape (nq,) or (N, nq).
    """
    x = as_float_array(angles, "angles", ndim=(1, 2))
    if x.shape[-1] != robot.nv:
        raise InputError(f"angles.shape={x.shape} but robot.nv={robot.nv}")
    idx, cont = dof_layout(robot)
    q = np.empty((*x.shape[:-1], robot.nq))
    lin = ~cont
    q[..., idx[lin]] = x[..., lin]
    if cont.any():
        q[..., idx[cont]] = np.cos(x[..., cont])
        q[..., idx[cont] + 1] = np.sin(x[..., cont])
    return q
