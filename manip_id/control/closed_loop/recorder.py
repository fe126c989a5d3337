"""What a closed-loop run logs, at which stride, and its running sums."""

from __future__ import annotations

import math

import numpy as np

from ...resources import FLOAT, MAX_STEPS, check_count, check_memory
from ...robot.model import Robot
from ..adaptive import SlotineLiController


class Recorder:
    """What a run logs, and at which stride.

    Control step ``k`` is recorded in full when ``k`` is a multiple of ``record_every`` and
    at the last step (:attr:`indices`): t, q, q_d, dq, tau, s, theta_hat and the composite
    law's ``|eps|``. At every step it sums the tracking error ``q_tilde^2`` (whole run and
    tail) and the dissipation ``dt (s^T D s + share kappa |eps|^2 / m^2)`` with the damping
    ``D = K_D + diag(f_v)`` and ``share = 1/2`` for the RLS gain, 1 otherwise.

    Parameters
    ----------
    robot : Robot
        the robot (sizes nq, nv, p).
    n_steps : int
        control steps of the run.
    dt : float
        control period [s].
    record_every : int
        stride of the full records.
    tail : float
        fraction of the run at its end for :meth:`rms_tail`, in (0, 1].
    damping : numpy.ndarray
        ``D`` [N m s/rad], shape (nv, nv).
    """

    def __init__(
        self,
        robot: Robot,
        n_steps: int,
        dt: float,
        *,
        record_every: int = 1,
        tail: float = 0.25,
        damping: np.ndarray,
    ) -> None:
        nq, nv, p = robot.nq, robot.nv, robot.n_parameters
        check_count(n_steps, MAX_STEPS, "the closed-loop run's time steps (duration x rate)")
        n_kept = n_steps // max(int(record_every), 1) + 2  # the samples recorded
        check_memory(  # t, q, q_d, dq, tau, s, theta_hat, eps and the indices
            FLOAT * n_kept * (3 + 2 * nq + 3 * nv + p),
            f"a record of {n_kept:.3g} samples of {nv} joints and {p} parameters needs",
            "shorten the duration or lower the rate",
        )
        idx = np.arange(0, n_steps, record_every)
        if idx[-1] != n_steps - 1:
            idx = np.append(idx, n_steps - 1)
        self.indices = idx
        K = idx.shape[0]
        self.n_steps, self.nv, self.dt = n_steps, nv, dt
        self.t = np.empty(K)  # [s]
        self.q = np.empty((K, nq))
        self.q_d = np.empty((K, nq))
        self.dq = np.empty((K, nv))
        self.tau = np.empty((K, nv))
        self.s = np.empty((K, nv))
        self.theta_hat = np.empty((K, p))
        self.eps = np.zeros(K)  # [N m]
        self._next, self._r = idx[0], 0
        self.sq_sum = np.zeros(nv)  # [rad^2]
        self.tail_start = n_steps - max(int(round(tail * n_steps)), 1)
        self.tail_sum = 0.0  # [rad^2]
        self.damping = damping
        self.dissipation = 0.0  # [J]
        self.first_error = self.last_error = 0.0  # [rad]

    def observe(
        self,
        k: int,
        q: np.ndarray,
        q_d: np.ndarray,
        dq: np.ndarray,
        tau: np.ndarray,
        ctrl: SlotineLiController,
    ) -> None:
        """Log control step ``k`` after the controller's torque, before its adaptation."""
        dt = self.dt
        e = ctrl.q_tilde
        e2 = e * e
        self.sq_sum += e2
        if k >= self.tail_start:
            self.tail_sum += e2.sum()
        s = ctrl.s
        self.dissipation += dt * float(s @ (self.damping @ s))
        kappa = ctrl.kappa
        if kappa > 0:
            share = 0.5 if ctrl.rls else 1.0
            self.dissipation += dt * share * kappa * float(ctrl.eps @ ctrl.eps) / ctrl.norm2
        if k == 0:
            self.first_error = math.sqrt(e2.sum())
        if k == self._next:
            r = self._r
            self.t[r] = k * dt
            self.q[r] = q
            self.q_d[r] = q_d
            self.dq[r] = dq
            self.tau[r] = tau
            self.s[r] = s
            self.theta_hat[r] = ctrl.theta_hat
            if ctrl.kappa > 0:
                self.eps[r] = math.sqrt(float(ctrl.eps @ ctrl.eps))
            self._r = r + 1
            self._next = self.indices[r + 1] if r + 1 < self.indices.shape[0] else -1
        if k == self.n_steps - 1:
            self.last_error = math.sqrt(e2.sum())

    def rms_per_joint(self) -> np.ndarray:
        """RMS tracking error per joint over all control steps [rad], shape (nv,)."""
        return np.sqrt(self.sq_sum / self.n_steps)

    def rms(self) -> float:
        """RMS tracking error over all control steps and joints [rad]."""
        return float(np.sqrt(self.sq_sum.sum() / (self.n_steps * self.nv)))

    def rms_tail(self) -> float:
        """RMS tracking error over the tail of the run [rad]."""
        return float(np.sqrt(self.tail_sum / ((self.n_steps - self.tail_start) * self.nv)))
