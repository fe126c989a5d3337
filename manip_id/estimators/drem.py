"""Dynamic regressor extension and mixing (DREM): one scalar regression per parameter.

Aranovskiy, Bobtsov, Ortega & Pyrkin (2017). From the regression
``z = Y theta`` (``Y`` of shape (m, p), ``z`` of shape (m,); scalar case
``phi`` (p,)), the *extension* applies one stable linear filter to both sides
and makes a square system; here Kreisselmeier's, a filtered information
matrix (first-order filter of bandwidth ``alpha`` [1/s])::

    d Phi_e/dt = -alpha Phi_e + Y^T Y        (p, p), symmetric positive semi-definite
    d z_e/dt   = -alpha z_e   + Y^T z        (p,)
    =>  z_e = Phi_e theta                    at every instant (theta constant)

The *mixing* multiplies by the adjugate of ``Phi_e``: with
``Delta = det(Phi_e) >= 0`` and ``Z = adj(Phi_e) z_e``::

    Z_i = Delta theta_i,          i = 1..p   (p decoupled scalar regressions)

and each parameter follows its own scalar gradient law
``d theta_hat_i/dt = -gamma_i Delta (Delta theta_hat_i - Z_i)``, hence

    d theta_tilde_i/dt = -gamma_i Delta^2 theta_tilde_i

so every ``|theta_tilde_i(t)|`` is non-increasing, whatever the others do
(element-wise monotonicity, which no gradient or least-squares law on the
vector regression has), and converges to zero iff ``Delta`` is not square
integrable (weaker than persistent excitation).

Discrete time. The filters are integrated exactly for an input held over the
step (``Phi_e <- a Phi_e + (1 - a)/alpha Y^T Y``, ``a = exp(-alpha dt)``), which
keeps ``z_e = Phi_e theta`` exact for sampled data, and the scalar laws with
their exact solution for ``Delta`` held over the step::

    theta_hat_i <- Z_i/Delta + exp(-gamma_i Delta^2 dt) (theta_hat_i - Z_i/Delta)

written without dividing by a small ``Delta`` (``(1 - exp(-x))/Delta^2`` is
evaluated with ``expm1``). In discrete time too, ``|theta_tilde_i|`` never
increases. ``adj(Phi_e) = Delta Phi_e^-1`` comes from the eigendecomposition
of the symmetric ``Phi_e`` (products of eigenvalues, no inverse of a singular
matrix), so ``Delta = 0`` simply means no update.

Scale: ``Delta`` is a product of p eigenvalues, so its size varies like the
p-th power of the regressor's; ``gamma`` must be chosen for it (or the data
scaled). DREM is meant for a handful of parameters.
"""

from __future__ import annotations

import math

import numpy as np

from .._checks import positive_vector
from ..errors import InputError
from .online import OnlineEstimator


class DREMEstimator(OnlineEstimator):
    """DREM with Kreisselmeier's extension (module docstring), one scalar law per parameter.

    Parameters
    ----------
    theta0 : array_like
        initial estimate, shape (p,)
    gamma : array_like
        per-parameter gains gamma_i > 0, a scalar or shape (p,) [1/(s Delta^2)]
    alpha : float
        bandwidth of the extension filter [1/s], > 0 (memory about ``1/alpha`` s)
    bounds : array_like
        optional ``(lower, upper)`` box for the projection, shapes (p,)
    record_every : int
        keep every k-th estimate in :attr:`history` (0: none)
    t0 : float
        initial time [s]

    ``step(Y, z, dt)`` takes ``Y`` (m, p) and ``z`` (m,), or ``phi`` (p,) and scalar
    ``z``; ``last_error`` is the prediction error ``Y theta_hat - z`` before the update.
    """

    def __init__(
        self,
        theta0,
        gamma=1.0,
        *,
        alpha: float = 1.0,
        bounds=None,
        record_every: int = 1,
        t0: float = 0.0,
    ):
        super().__init__(theta0, bounds=bounds, record_every=record_every, t0=t0)
        self._gamma = positive_vector(gamma, "gamma", self.p, "1/s")
        alpha = float(alpha)
        if not (math.isfinite(alpha) and alpha > 0):
            raise InputError(f"alpha must be a positive bandwidth [1/s], got {alpha}")
        self.alpha = alpha
        self._Phi = np.zeros((self.p, self.p))
        self._ze = np.zeros(self.p)
        self.delta = 0.0

    @property
    def gamma(self) -> np.ndarray:
        """Per-parameter gains, shape (p,)."""
        return self._gamma.copy()

    @property
    def extended_regressor(self) -> np.ndarray:
        """The filtered information ``Phi_e``, shape (p, p) (a copy)."""
        return self._Phi.copy()

    def mixed(self) -> tuple[float, np.ndarray]:
        """``(Delta, Z)``: the determinant of ``Phi_e`` and ``adj(Phi_e) z_e``, shape (p,)."""
        w, V = np.linalg.eigh(self._Phi)
        w = np.maximum(w, 0.0)  # PSD up to round-off
        delta = float(np.prod(w))
        # adj = V diag(prod_{k != i} w_k) V^T
        cof = np.array([np.prod(np.delete(w, i)) for i in range(self.p)]) if self.p > 1 else [1.0]
        Z = V @ (np.asarray(cof) * (V.T @ self._ze))
        return delta, Z

    def step(self, Y, z, dt: float) -> np.ndarray:
        """One step of length ``dt`` [s]; returns the estimate (a view: do not modify)."""
        th = self._theta
        try:
            Ya, za, e = self._prediction_error(Y, z)
            if Ya.ndim == 1:
                YY, Yz = np.multiply.outer(Ya, Ya), Ya * float(za)
            else:
                YY, Yz = Ya.T @ Ya, za @ Ya
        except (ValueError, TypeError) as exc:
            raise self._bad(Y, z, exc) from exc
        if not math.isfinite(float(np.sum(e)) + float(YY.sum())):
            raise self._bad(Y, z)
        a = math.exp(-self.alpha * dt)
        g = -math.expm1(-self.alpha * dt) / self.alpha  # (1 - a)/alpha [s]
        self._Phi *= a
        self._Phi += g * YY
        self._ze *= a
        self._ze += g * Yz
        delta, Z = self.mixed()
        self.delta = delta
        if delta > 0.0:
            x = self._gamma * (delta * delta) * dt
            # theta_hat += (1 - e^-x)/Delta^2 * Delta (Z - Delta theta_hat)
            th += (-np.expm1(-x)) * (Z / delta - th)
        self._finish(e, dt)
        return th
