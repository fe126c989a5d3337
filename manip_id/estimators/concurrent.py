"""Concurrent learning: a gradient law that also adapts on a recorded history stack.

Chowdhary & Johnson (2010). The gradient law on the current sample
(``eps = Y theta_hat - z``, DESIGN.md signs) is completed by the prediction
errors of ``n`` recorded samples ``(Y_j, z_j)``::

    d theta_hat/dt = -Gamma ( Y^T eps  +  sum_j Y_j^T eps_j ),   eps_j = Y_j theta_hat - z_j

With ``theta`` constant, ``eps_j = Y_j theta_tilde`` and

    d theta_tilde/dt = -Gamma (Y^T Y + S) theta_tilde,     S = sum_j Y_j^T Y_j

so ``V = theta_tilde^T Gamma^-1 theta_tilde / 2`` decreases at least at the rate
``2 lambda_min(S) / lambda_max(Gamma^-1)``: once the stack has rank p the
estimate converges exponentially *without* persistent excitation of the
current regressor (e.g. when the input is held constant).

History stack. A sample enters when it differs enough from the last one
recorded (``||phi - phi_last||^2 / ||phi|| >= novelty``). While the stack has
fewer than ``stack_size`` samples it is appended; once full, the new sample
replaces the recorded one whose replacement maximizes the minimum singular
value of the stacked regressor ``[Y_1; ...; Y_n]`` (``sqrt(lambda_min(S))``),
and only if that beats the current value (Chowdhary & Johnson's
singular-value-maximizing stack). ``lambda_min(S)`` therefore never decreases.

Discrete time: explicit Euler at ``dt``; stable when
``dt lambda_max(Gamma (Y^T Y + S)) < 2``. With ``normalized=True`` the current
term is divided by ``1 + trace(Y Gamma Y^T)`` as in
:class:`~manip_id.estimators.GradientEstimator`.
"""

from __future__ import annotations

import math

import numpy as np

from .._checks import as_int, as_real, spd_gain
from ..errors import InputError
from .online import OnlineEstimator


class ConcurrentLearningEstimator(OnlineEstimator):
    """Gradient law plus a singular-value-maximizing history stack (module docstring).

    Parameters
    ----------
    theta0 : array_like
        initial estimate, shape (p,)
    gamma : array_like
        adaptation gain Gamma, shape (p,) (diagonal, positive) or (p, p) (SPD)
    stack_size : int, optional
        number of recorded samples kept (>= 1; rank p needs ``m n >= p``)
    novelty : float
        minimum ``||phi - phi_last||^2 / ||phi||`` for a sample to be
        considered for the stack (``phi`` the flattened ``Y``) [units of Y]
    normalized : bool
        normalize the current-sample term (module docstring)
    bounds : array_like
        optional ``(lower, upper)`` box for the projection, shapes (p,)
    record_every : int
        keep every k-th estimate in :attr:`history` (0: none)
    t0 : float
        initial time [s]
    """

    def __init__(
        self,
        theta0,
        gamma=1.0,
        *,
        stack_size: int | None = None,
        novelty: float = 0.05,
        normalized: bool = False,
        bounds=None,
        record_every: int = 1,
        t0: float = 0.0,
    ):
        super().__init__(theta0, bounds=bounds, record_every=record_every, t0=t0)
        g = spd_gain(gamma, "gamma", self.p)
        self._G = np.diag(g) if g.ndim == 1 else g
        n = 2 * self.p if stack_size is None else as_int(stack_size, "stack_size")
        if n < 1:
            raise InputError(f"stack_size must be a positive number of samples, got {stack_size}")
        novelty = as_real(novelty, "novelty")
        if not (math.isfinite(novelty) and novelty >= 0):
            raise InputError(f"novelty must be >= 0, got {novelty}")
        self.stack_size = n
        self.novelty = novelty
        self.normalized = bool(normalized)
        self._Ys: list[np.ndarray] = []  # recorded regressors, each (m, p)
        self._zs: list[np.ndarray] = []  # recorded outputs, each (m,)
        self._S = np.zeros((self.p, self.p))  # sum_j Y_j^T Y_j
        self._b = np.zeros(self.p)  # sum_j Y_j^T z_j
        self._last: np.ndarray | None = None
        self.sigma_min = 0.0

    @property
    def gamma(self) -> np.ndarray:
        """The gain matrix Gamma, shape (p, p)."""
        return self._G.copy()

    @property
    def stack(self) -> tuple[np.ndarray, np.ndarray]:
        """The recorded samples: regressors (n, m, p) and outputs (n, m)."""
        if not self._Ys:
            return np.zeros((0, 0, self.p)), np.zeros((0, 0))
        return np.array(self._Ys), np.array(self._zs)

    @property
    def stack_rank(self) -> int:
        """Rank of the stacked recorded regressor."""
        if not self._Ys:
            return 0
        w = np.linalg.eigvalsh(self._S)
        return int(np.sum(w > max(w.max(), 0.0) * 1e-12))

    def _sigma_min(self, S: np.ndarray) -> float:
        return float(math.sqrt(max(np.linalg.eigvalsh(S)[0], 0.0)))

    def _consider(self, Y: np.ndarray, z: np.ndarray) -> None:
        """Record (Y, z) if it is new enough and, once full, raises sigma_min of the stack."""
        flat = Y.ravel()
        nrm = float(np.linalg.norm(flat))
        if nrm == 0.0:
            return
        if self._last is not None and float(np.sum((flat - self._last) ** 2)) / nrm < self.novelty:
            return
        YY = Y.T @ Y
        if len(self._Ys) < self.stack_size:
            self._Ys.append(Y.copy())
            self._zs.append(z.copy())
            self._S += YY
            self._b += Y.T @ z
            self._last = flat.copy()
            self.sigma_min = self._sigma_min(self._S)
            return
        best, best_k = self.sigma_min, -1
        for k, Yk in enumerate(self._Ys):
            s = self._sigma_min(self._S - Yk.T @ Yk + YY)
            if s > best:
                best, best_k = s, k
        if best_k < 0:
            return
        Yk, zk = self._Ys[best_k], self._zs[best_k]
        self._S += YY - Yk.T @ Yk
        self._b += Y.T @ z - Yk.T @ zk
        self._Ys[best_k], self._zs[best_k] = Y.copy(), z.copy()
        self._last = flat.copy()
        self.sigma_min = best

    def step(self, Y, z, dt: float) -> np.ndarray:
        """One Euler step of length ``dt`` [s] (> 0); returns the estimate (a view: do not
        modify). A sample holding NaN/Inf is skipped (:mod:`~manip_id.estimators.online`)."""
        dt = self._dt(dt)
        th = self._theta
        try:
            Ya, za, e = self._prediction_error(Y, z)
            g = Ya * float(e) if Ya.ndim == 1 else e @ Ya
        except (ValueError, TypeError) as exc:
            raise self._bad(Y, z, exc) from exc
        if not math.isfinite(float(np.sum(e))):
            return self._dropout(Y, z, dt)
        if self.normalized:
            Y2 = Ya[None] if Ya.ndim == 1 else Ya
            g = g / (1.0 + float(np.sum((Y2 @ self._G) * Y2)))
        Y2 = Ya[None] if Ya.ndim == 1 else Ya
        try:
            self._consider(Y2, np.atleast_1d(za))
        except np.linalg.LinAlgError as exc:  # finite but absurd values (an overflow)
            raise self._bad(Y, z, exc) from exc
        g = g + (self._S @ th - self._b)  # sum_j Y_j^T eps_j
        th -= dt * (self._G @ g)
        self._finish(e, dt)
        return th
