"""Excitation trajectories: finite Fourier series per joint (Swevers et al.).

For joint ``j`` with ``L`` harmonics and base pulsation ``wf`` [rad/s]::

    q_j(t)   = q0_j + sum_l [ a_jl/(l wf) sin(l wf t) - b_jl/(l wf) cos(l wf t) ]
    dq_j(t)  =        sum_l [ a_jl cos(l wf t) + b_jl sin(l wf t) ]
    ddq_j(t) =        sum_l [ -a_jl l wf sin(l wf t) + b_jl l wf cos(l wf t) ]

The trajectory is periodic with period ``2 pi / wf``; velocity and
acceleration are exact (analytic), never differentiated numerically.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._checks import as_float_array, check_finite
from .errors import InputError


@dataclass(frozen=True)
class FourierTrajectory:
    """A finite Fourier series per joint.

    Attributes
    ----------
    q0: offset per joint [rad or m], shape (nv,)
    a: sine coefficients [rad/s or m/s], shape (nv, L)
    b: cosine coefficients [rad/s or m/s], shape (nv, L)
    wf: base pulsation [rad/s]
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
