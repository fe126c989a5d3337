"""Online (adaptive) parameter estimators with one interface.

Every law estimates theta in ``z = Y theta`` from one sample at a time:
``step(Y, z, dt)`` with ``Y`` of shape (nv, p) and ``z`` of shape (nv,) (vector
output, e.g. joint torques) or ``phi`` of shape (p,) and scalar ``z``. The
prediction error is ``eps = Y theta_hat - z`` (DESIGN.md sign convention),
evaluated with the estimate *before* the update.

Gradient law (continuous time, explicit Euler at the step ``dt`` [s])::

    d theta_hat / dt = -Gamma Y^T eps / m^2
    m^2 = 1                                  plain gradient
    m^2 = 1 + trace(Y Gamma Y^T)             normalized (= 1 + phi^T Gamma phi)

``Gamma`` symmetric positive definite (a vector means a diagonal matrix). The
normalization bounds the update: the Euler map ``I - dt Gamma Y^T Y / m^2`` is
contracting for any regressor size when ``dt < 2``.

Recursive least squares with exponential forgetting ``lambda`` (discrete; ``dt``
only advances the time stamps)::

    S = lambda_k I + Y P Y^T,   K = P Y^T S^-1
    theta_hat <- theta_hat - K eps,   P <- (P - K Y P) / lambda_k

With ``lambda < 1`` the covariance would wind up when excitation vanishes;
the forgetting is bounded (Slotine & Li): ``lambda_k = 1 - (1 - lambda)(1 -
trace(P)/p_max)``, which keeps ``trace(P) <= p_max`` (default ``p_max =
trace(P0)``). ``p_min`` keeps ``trace(P) >= p_min`` by adding
``(p_min - trace(P))/p I`` (adaptation never switches off). With ``lambda = 1``
and ``P0 = p0 I`` the estimate is the regularized least-squares one
``(A + I/p0)^-1 (b + theta0/p0)``.

Projection: with ``bounds=(lower, upper)`` the estimate is clipped to the box
after every update (the Euclidean projection).

Checks of every step (written for hot loops): ``dt`` must be a finite number of seconds,
``> 0`` for the continuous-time laws (gradient, DREM, concurrent learning), ``>= 0`` for
RLS (a discrete law whose ``dt`` only advances the time stamps), else
:class:`~manip_id.errors.InputError`; ``Y`` and ``z`` of the wrong shape or dtype raise
:class:`~manip_id.errors.InputError` too. Together with the one scalar test that the
prediction error is finite, this costs about a microsecond a step.

Dropouts: a sample whose ``Y`` or ``z`` holds NaN or Inf (a sensor dropout) is skipped,
as :class:`~manip_id.monitor.CollisionMonitor` skips one: the estimate (and the RLS
covariance, the DREM and concurrent-learning memories) stay as they were, the time
advances by ``dt``, :attr:`~OnlineEstimator.skipped` is True until the next sample that is
used, and :attr:`~OnlineEstimator.dropouts` counts them. (A finite prediction error implies
finite ``Y`` and ``z``: every entry of ``Y`` enters ``Y theta_hat``.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dposv

from .._checks import as_float_array, as_int, as_real, check_finite, spd_gain, spd_matrix
from ..errors import InputError, NumericalError


def _real(x, name: str):
    """``x`` unchanged when a float64 array or a float (the hot path), else as a float64
    array; :class:`InputError` for complex, text or objects."""
    if type(x) is float or (type(x) is np.ndarray and x.dtype == np.float64):
        return x
    return as_float_array(x, name)


@dataclass(frozen=True)
class OnlineHistory:
    """Decimated record of an online estimator.

    Attributes
    ----------
    t
        time stamps [s], shape (K,) (the first is the initial estimate)
    theta
        estimates, shape (K, p)
    error
        norm of the prediction error before the update, shape (K,) (NaN at the start)
    """

    t: np.ndarray
    theta: np.ndarray
    error: np.ndarray


class OnlineEstimator:
    """Shared bookkeeping: estimate, bounds, time, history."""

    def __init__(self, theta0, *, bounds=None, record_every: int = 1, t0: float = 0.0):
        theta = as_float_array(theta0, "theta0", ndim=1)
        check_finite(theta, "theta0")
        self.p = theta.shape[0]
        self._theta = theta.copy()
        self._lo = self._hi = None
        if bounds is not None:
            try:
                lo, hi = bounds
            except (TypeError, ValueError) as exc:
                raise InputError(
                    "bounds must be a pair (lower, upper) of arrays of shape (p,)"
                ) from exc
            lo, hi = as_float_array(lo, "lower bound"), as_float_array(hi, "upper bound")
            if lo.shape not in ((), (1,), (self.p,)) or hi.shape not in ((), (1,), (self.p,)):
                raise InputError(
                    f"bounds must be scalars or shape ({self.p},), got {lo.shape} and {hi.shape}"
                )
            lo = np.broadcast_to(lo, (self.p,)).copy()
            hi = np.broadcast_to(hi, (self.p,)).copy()
            if np.isnan(lo).any() or np.isnan(hi).any():
                raise InputError("bounds must not hold NaN (use -inf or inf for no bound)")
            if np.any(lo > hi):
                i = int(np.argmax(lo > hi))
                raise InputError(f"lower bound {lo[i]} > upper bound {hi[i]} for parameter {i}")
            self._lo, self._hi = lo, hi
            np.clip(self._theta, lo, hi, out=self._theta)
        self.record_every = as_int(record_every, "record_every (0: no history)", minimum=0)
        self.t = as_real(t0, "t0", unit="s")
        self.steps = 0
        self.dropouts = 0  # samples skipped for NaN/Inf (module docstring)
        self.skipped = False  # whether the last sample was skipped
        self.last_error: np.ndarray | float = float("nan")
        self._t: list[float] = [self.t]
        self._th: list[np.ndarray] = [self._theta.copy()]
        self._err: list[float] = [float("nan")]

    @property
    def theta(self) -> np.ndarray:
        """Current estimate, shape (p,) (a copy)."""
        return self._theta.copy()

    @property
    def history(self) -> OnlineHistory:
        """Recorded times, estimates and prediction-error norms (every ``record_every`` steps)."""
        return OnlineHistory(np.array(self._t), np.array(self._th), np.array(self._err))

    def _prediction_error(self, Y, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Y, z, e)``: ``Y`` and ``z`` as float arrays and the prediction error
        ``e = Y theta_hat - z``, shape (m,) (scalar for ``phi`` (p,)). Mismatched shapes raise
        ValueError or TypeError, which ``step`` turns into :meth:`_bad`."""
        Ya, za = np.asarray(_real(Y, "Y")), np.asarray(_real(z, "z"))
        if Ya.ndim not in (1, 2):
            raise ValueError("regressor dimensions")
        e = Ya @ self._theta - za
        if np.shape(e) != za.shape:
            raise ValueError("output shape")
        return Ya, za, e

    def _dt(self, dt, zero: bool = False) -> float:
        """``dt`` [s] checked (module docstring): finite and > 0 (``>= 0`` when ``zero``)."""
        if type(dt) is not float:
            if isinstance(dt, bool) or not isinstance(dt, (int, np.integer, np.floating)):
                raise InputError(f"dt must be a number of seconds, got {type(dt).__name__}")
            dt = float(dt)
        if not (math.isfinite(dt) and (dt > 0.0 or (zero and dt == 0.0))):
            need = "finite time step >= 0" if zero else "finite positive time step"
            raise InputError(f"dt must be a {need} [s], got {dt} (step {self.steps})")
        return dt

    def _dropout(self, Y, z, dt: float) -> np.ndarray:
        """A sample whose prediction error is not finite: skipped when ``Y`` or ``z`` hold
        NaN/Inf (module docstring); otherwise the error :meth:`_bad` names."""
        Ya, za = np.asarray(_real(Y, "Y")), np.asarray(_real(z, "z"))
        if self._shape_problem(Ya, za) is not None or (
            np.isfinite(Ya).all() and np.isfinite(za).all()
        ):
            raise self._bad(Y, z)
        self.dropouts += 1
        self.skipped = True
        self.t += dt
        return self._theta

    def _shape_problem(self, Ya: np.ndarray, za: np.ndarray) -> str | None:
        """What is wrong with the shapes of ``Y`` and ``z``, or None."""
        if Ya.ndim not in (1, 2) or Ya.shape[-1] != self.p:
            return (
                f"Y.shape={Ya.shape} but the estimator has p={self.p} parameters: give Y of "
                f"shape (nv, {self.p}) or phi of shape ({self.p},)"
            )
        if za.shape != Ya.shape[:-1]:
            return f"Y.shape={Ya.shape} but z.shape={za.shape}; expected z.shape={Ya.shape[:-1]}"
        return None

    def _bad(self, Y, z, exc: Exception | None = None) -> InputError | NumericalError:
        try:
            Ya, za = np.asarray(_real(Y, "Y")), np.asarray(_real(z, "z"))
        except InputError as bad:
            return bad
        problem = self._shape_problem(Ya, za)
        if problem is not None:
            msg = problem
        elif not (np.isfinite(Ya).all() and np.isfinite(za).all()):
            msg = f"Y or z holds NaN or Inf at step {self.steps}"
        else:  # valid inputs: the update itself broke down
            reason = f"step {self.steps} failed" + (f": {exc}" if exc is not None else "")
            failure = NumericalError(
                f"{type(self).__name__} update",
                reason + " (the innovation covariance is not positive definite or not finite)",
                hint="check the forgetting factor and the covariance bounds",
            )
            if exc is not None:
                failure.__cause__ = exc
            return failure
        err = InputError(msg)
        if exc is not None:
            err.__cause__ = exc
        return err

    def _finish(self, e, dt: float) -> None:
        if self._lo is not None:
            np.clip(self._theta, self._lo, self._hi, out=self._theta)
        self.last_error = e
        self.skipped = False
        self.steps += 1
        self.t += dt
        if self.record_every and self.steps % self.record_every == 0:
            self._t.append(self.t)
            self._th.append(self._theta.copy())
            self._err.append(float(np.sqrt(np.dot(e, e))) if np.ndim(e) else abs(float(e)))


class GradientEstimator(OnlineEstimator):
    """Gradient (optionally normalized) adaptation law, integrated with explicit Euler.

    Parameters
    ----------
    theta0
        initial estimate, shape (p,)
    gamma
        adaptation gain Gamma, shape (p,) (diagonal, positive) or (p, p) (SPD)
    normalized
        divide by ``m^2 = 1 + trace(Y Gamma Y^T)`` (see module docstring)
    bounds
        optional ``(lower, upper)`` box for the projection, shapes (p,)
    record_every
        keep every k-th estimate in :attr:`history` (0: none)
    """

    def __init__(
        self,
        theta0,
        gamma,
        *,
        normalized: bool = False,
        bounds=None,
        record_every: int = 1,
        t0: float = 0.0,
    ):
        super().__init__(theta0, bounds=bounds, record_every=record_every, t0=t0)
        g = spd_gain(gamma, "gamma", self.p)
        self._gdiag: np.ndarray = g if g.ndim == 1 else np.diag(g)  # used when _G is None
        self._G: np.ndarray | None = None if g.ndim == 1 else g
        self.normalized = bool(normalized)
        self._g = np.empty(self.p)

    @property
    def gamma(self) -> np.ndarray:
        """The gain matrix Gamma, shape (p, p)."""
        return np.diag(self._gdiag) if self._G is None else self._G.copy()

    def step(self, Y, z, dt: float) -> np.ndarray:
        """One Euler step of length ``dt`` [s] (> 0); returns the estimate (a view: do not
        modify). A sample holding NaN/Inf is skipped (module docstring)."""
        dt = self._dt(dt)
        Y, z = _real(Y, "Y"), _real(z, "z")
        th, g = self._theta, self._g
        try:
            e = Y @ th - z
            if type(e) is np.ndarray and e.shape != np.shape(z):
                raise ValueError("output shape")
            if Y.ndim == 1:
                np.multiply(Y, e, out=g)
            else:
                np.dot(e, Y, out=g)
        except (ValueError, TypeError, AttributeError) as exc:
            raise self._bad(Y, z, exc) from exc
        if not math.isfinite(float(np.sum(e))):
            return self._dropout(Y, z, dt)
        h = dt
        if self._G is None:
            g *= self._gdiag
            if self.normalized:
                h = dt / (1.0 + float(np.dot(Y * Y, self._gdiag).sum()))
        else:
            g = self._G @ g
            if self.normalized:
                h = dt / (1.0 + float(np.sum((Y @ self._G) * Y)))
        g *= h
        th -= g
        self._finish(e, dt)
        return th


class RLSEstimator(OnlineEstimator):
    """Recursive least squares with exponential, bounded forgetting.

    Parameters
    ----------
    theta0
        initial estimate, shape (p,)
    P0
        initial covariance: scalar (times I), shape (p,) (diagonal) or (p, p) (SPD)
    forgetting
        lambda in (0, 1]; 1 means no forgetting
    p_min, p_max
        bounds on trace(P) (see module docstring); ``p_max`` defaults to
        trace(P0) when ``forgetting < 1``, otherwise none
    bounds
        optional ``(lower, upper)`` box for the projection, shapes (p,)
    record_every
        keep every k-th estimate in :attr:`history` (0: none)
    """

    _SYMMETRIZE_EVERY = 64

    def __init__(
        self,
        theta0,
        P0,
        *,
        forgetting: float = 1.0,
        p_min: float | None = None,
        p_max: float | None = None,
        bounds=None,
        record_every: int = 1,
        t0: float = 0.0,
    ):
        super().__init__(theta0, bounds=bounds, record_every=record_every, t0=t0)
        P = spd_matrix(P0, "P0", self.p)
        lam = as_real(forgetting, "forgetting")
        p_min = None if p_min is None else as_real(p_min, "p_min")
        p_max = None if p_max is None else as_real(p_max, "p_max")
        if not 0.0 < lam <= 1.0:
            raise InputError(f"forgetting must be in (0, 1], got {forgetting}")
        if p_max is None and lam < 1.0:
            p_max = float(np.trace(P))
        if p_max is not None and p_max <= 0:
            raise InputError(f"p_max must be positive, got {p_max}")
        if p_min is not None and (p_min < 0 or (p_max is not None and p_min > p_max)):
            raise InputError(f"need 0 <= p_min <= p_max, got p_min={p_min}, p_max={p_max}")
        self.forgetting = lam
        self.p_min = p_min
        self.p_max = p_max
        self._P = np.array(P, order="C")
        self._tmp = np.empty((self.p, self.p))

    @property
    def P(self) -> np.ndarray:
        """Current covariance matrix, shape (p, p) (a copy)."""
        return self._P.copy()

    def step(self, Y, z, dt: float = 0.0) -> np.ndarray:
        """One update with sample (Y, z); ``dt`` [s] (>= 0) only advances the time stamps.
        A sample holding NaN/Inf is skipped (module docstring)."""
        dt = self._dt(dt, zero=True)
        Y, z = _real(Y, "Y"), _real(z, "z")
        th, P = self._theta, self._P
        lam = self.forgetting
        if lam < 1.0 and self.p_max is not None:
            x = min(P.trace() / self.p_max, 1.0)
            lam = 1.0 - (1.0 - lam) * (1.0 - x)
        try:
            e = Y @ th - z
            if not math.isfinite(float(np.sum(e))):
                return self._dropout(Y, z, dt)
            if Y.ndim == 1:
                Pphi = P @ Y
                den = lam + float(Y @ Pphi)
                if not math.isfinite(den + float(e)):
                    raise self._bad(Y, z)
                th -= (float(e) / den) * Pphi
                P -= np.multiply.outer(Pphi, Pphi / den, out=self._tmp)
            else:
                if e.shape != np.shape(z):
                    raise ValueError("output shape")
                PYt = P @ Y.T
                S = Y @ PYt
                S.reshape(-1)[:: S.shape[0] + 1] += lam
                _, X, info = dposv(S, PYt.T, lower=1)
                if info != 0 or not math.isfinite(float(np.sum(e))):
                    raise self._bad(Y, z)
                th -= e @ X
                P -= np.dot(PYt, X, out=self._tmp)
        except InputError:
            raise
        except (ValueError, TypeError, AttributeError) as exc:
            raise self._bad(Y, z, exc) from exc
        if lam != 1.0:
            P *= 1.0 / lam
        if self.p_min is not None:
            tr = P.trace()
            if tr < self.p_min:
                P.flat[:: self.p + 1] += (self.p_min - tr) / self.p
        if self.steps % self._SYMMETRIZE_EVERY == 0:
            np.add(P, P.T, out=self._tmp)
            np.multiply(self._tmp, 0.5, out=P)
        self._finish(e, dt)
        return th
