"""Fourier series that start and end at rest in a given pose.

With the series of the package docstring (period ``T = 2 pi / wf``), rest at
``t = 0`` (and so at every multiple of ``T``) is three linear conditions per joint::

    dq_j(0)  = sum_l a_jl          = 0
    ddq_j(0) = sum_l l wf b_jl     = 0
    q_j(0)   = q0_j - sum_l b_jl / (l wf) = s_j        (the start pose)

The free coefficients ``z_j`` (``2L - 2`` per joint) span the null space ``N``
(shape (2L, 2L - 2), orthonormal) of the first two rows, ``[a_j, b_j] = N z_j``,
and ``q0_j = s_j + sum_l b_jl / (l wf)``. Position, velocity and acceleration
are then linear in ``z``::

    q_j(t) = s_j + Pr(t) N z_j,   dq_j(t) = V(t) N z_j,   ddq_j(t) = A(t) N z_j

with ``Pr(t) = P(t) + [0, 1/(l wf)]`` (``P, V, A`` of
:meth:`FourierTrajectory.basis`). Scaling ``z`` by ``c`` scales the motion
about the start pose and keeps the rest at both ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._checks import as_float_array
from ..errors import InputError
from .fourier import FourierTrajectory


def rest_null_space(harmonics: int, wf: float) -> np.ndarray:
    """Orthonormal basis of ``{(a, b): sum a = 0, sum l wf b = 0}``, shape (2L, 2L - 2)."""
    L = int(harmonics)
    lw = wf * np.arange(1, L + 1)
    C = np.zeros((2, 2 * L))
    C[0, :L] = 1.0
    C[1, L:] = lw
    _, _, vt = np.linalg.svd(C)
    return vt[2:].T


@dataclass(frozen=True)
class RestFourier:
    """The family of Fourier series at rest in ``start`` at ``t = k T``.

    Attributes
    ----------
    start : numpy.ndarray
        start (and end) pose, joint coordinates [rad or m], shape (nv,)
    harmonics : int
        number of harmonics L (at least 2)
    wf : float
        base pulsation [rad/s]
    """

    start: np.ndarray
    harmonics: int
    wf: float

    def __post_init__(self):
        start = as_float_array(self.start, "start", ndim=1)
        if int(self.harmonics) < 2:
            raise InputError(
                f"a motion at rest at both ends needs at least 2 harmonics, got {self.harmonics}"
            )
        if not (math.isfinite(self.wf) and self.wf > 0):
            raise InputError(f"wf must be a positive pulsation [rad/s], got {self.wf}")
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "harmonics", int(self.harmonics))
        object.__setattr__(self, "wf", float(self.wf))
        object.__setattr__(self, "_N", rest_null_space(self.harmonics, self.wf))

    @property
    def nv(self) -> int:
        return self.start.shape[0]

    @property
    def n_free(self) -> int:
        """Number of free coefficients ``nv (2L - 2)``."""
        return self.nv * (2 * self.harmonics - 2)

    @property
    def null_space(self) -> np.ndarray:
        return self._N  # type: ignore[attr-defined]

    def bases(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Pr N, V N, A N)`` at times ``t`` [s], each of shape (M, 2L - 2)."""
        proto = self.trajectory(np.zeros(self.n_free))
        P, V, A = proto.basis(t)
        L = self.harmonics
        Pr = P.copy()
        Pr[:, L:] += 1.0 / (self.wf * np.arange(1, L + 1))
        N = self.null_space
        return Pr @ N, V @ N, A @ N

    def states(self, z, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint coordinates, velocities, accelerations at ``t``, each of shape (M, nv)."""
        Z = self.reshape(z)
        P, V, A = self.bases(t)
        return self.start + P @ Z.T, V @ Z.T, A @ Z.T

    def reshape(self, z) -> np.ndarray:
        z = np.asarray(z, dtype=float)
        if z.shape != (self.n_free,):
            raise InputError(f"{z.shape=} but nv (2L - 2) = {self.n_free}")
        return z.reshape(self.nv, 2 * self.harmonics - 2)

    def trajectory(self, z) -> FourierTrajectory:
        """The :class:`FourierTrajectory` of the free coefficients ``z``, shape (nv (2L - 2),)."""
        Z = self.reshape(z)
        L = self.harmonics
        ab = Z @ self.null_space.T  # (nv, 2L)
        a, b = ab[:, :L], ab[:, L:]
        q0 = self.start + b @ (1.0 / (self.wf * np.arange(1, L + 1)))
        return FourierTrajectory(q0, a, b, self.wf)
