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

Normalized form (the default). ``Delta`` is a product of p eigenvalues, so its size
varies like the p-th power of the regressor's and a gain in ``1/(s Delta^2)`` must be
chosen for each plant. The normalized law divides the extension by its running scale
``s = tr(Phi_e)/p`` (the mean eigenvalue) before mixing::

    Phi_n = Phi_e / s,   z_n = z_e / s,   Delta_n = det(Phi_n),   Z_n = adj(Phi_n) z_n
    =>  Z_n,i = Delta_n theta_i,    0 <= Delta_n <= 1   (AM-GM on the eigenvalues)

and uses a normalized scalar gradient law::

    d theta_hat_i/dt = -gamma_i Delta_n (Delta_n theta_hat_i - Z_n,i) / (mu + Delta_n^2)
    =>  d theta_tilde_i/dt = -gamma_i Delta_n^2 / (mu + Delta_n^2) theta_tilde_i

``Delta_n`` does not change when the regressor is scaled (it depends only on the
shape of the excitation), so ``gamma`` [1/s] is a rate: each error decays at about
``gamma`` once ``Delta_n^2 >> mu`` (``mu`` = :data:`DEFAULT_MU`, dimensionless).
The rate factor is non-negative, so every ``|theta_tilde_i|`` is still non-increasing,
in continuous and (exact step below) in discrete time. ``normalized=False`` gives the
plain law above (``gamma`` in ``1/(s Delta^2)``). DREM is meant for a handful of
parameters.
"""

from __future__ import annotations

import math

import numpy as np

from .._checks import as_real, positive_vector
from ..errors import InputError
from .online import OnlineEstimator

#: Default rate of the normalized law [1/s]: each parameter error decays like exp(-t).
DEFAULT_GAMMA = 1.0
#: Default ``mu`` of the normalized law (dimensionless; ``Delta_n`` below ``sqrt(mu)``
#: counts as little excitation).
DEFAULT_MU = 1e-6


class DREMEstimator(OnlineEstimator):
    """DREM with Kreisselmeier's extension (module docstring), one scalar law per parameter.

    Parameters
    ----------
    theta0 : array_like
        Initial estimate, shape (p,).
    gamma : float or array_like
        Per-parameter gains gamma_i > 0, a scalar or shape (p,): rates [1/s] of the
        normalized law (default :data:`DEFAULT_GAMMA`), [1/(s Delta^2)] of the plain one.
    alpha : float
        Bandwidth of the extension filter [1/s], > 0 (memory about ``1/alpha`` s).
    normalized : bool
        The normalized law (module docstring, default) or the plain one.
    mu : float
        ``mu`` of the normalized law (dimensionless, > 0).
    bounds : tuple or None
        Optional ``(lower, upper)`` box for the projection, shapes (p,).
    record_every : int
        Keep every k-th estimate in :attr:`history` (0: none).
    t0 : float
        Initial time [s].

    ``step(Y, z, dt)`` takes ``Y`` (m, p) and ``z`` (m,), or ``phi`` (p,) and scalar
    ``z``; ``last_error`` is the prediction error ``Y theta_hat - z`` before the update.
    :attr:`delta` is the last ``Delta`` (``Delta_n`` when normalized).
    """

    def __init__(
        self,
        theta0,
        gamma=DEFAULT_GAMMA,
        *,
        alpha: float = 1.0,
        normalized: bool = True,
        mu: float = DEFAULT_MU,
        bounds=None,
        record_every: int = 1,
        t0: float = 0.0,
    ):
        super().__init__(theta0, bounds=bounds, record_every=record_every, t0=t0)
        unit = "1/s" if normalized else "1/(s Delta^2)"
        self._gamma = positive_vector(gamma, "gamma", self.p, unit)
        alpha = as_real(alpha, "alpha", unit="1/s")
        if not (math.isfinite(alpha) and alpha > 0):
            raise InputError(f"alpha must be a positive bandwidth [1/s], got {alpha}")
        mu = as_real(mu, "mu")
        if not (math.isfinite(mu) and mu > 0):
            raise InputError(f"mu must be positive (dimensionless), got {mu}")
        self.alpha = alpha
        self.normalized = bool(normalized)
        self.mu = mu
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
        """``(Delta, Z)``: the determinant of ``Phi_e`` and ``adj(Phi_e) z_e``, shape (p,)
        (``Delta_n`` and ``Z_n`` of ``Phi_e / s``, ``z_e / s`` when normalized)."""
        Phi, ze = self._Phi, self._ze
        if self.normalized:
            scale = float(np.trace(Phi)) / self.p
            if not scale > 0.0:
                return 0.0, np.zeros(self.p)
            Phi, ze = Phi / scale, ze / scale
        w, V = np.linalg.eigh(Phi)
        w = np.maximum(w, 0.0)  # PSD up to round-off
        delta = float(np.prod(w))
        # adj = V diag(prod_{k != i} w_k) V^T
        cof = np.array([np.prod(np.delete(w, i)) for i in range(self.p)]) if self.p > 1 else [1.0]
        Z = V @ (np.asarray(cof) * (V.T @ ze))
        return delta, Z

    def step(self, Y, z, dt: float) -> np.ndarray:
        """One step of length ``dt`` [s] (> 0); returns the estimate (a view: do not
        modify). A sample holding NaN/Inf is skipped (:mod:`~manip_id.estimators.online`)."""
        dt = self._dt(dt)
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
            return self._dropout(Y, z, dt)
        a = math.exp(-self.alpha * dt)
        g = -math.expm1(-self.alpha * dt) / self.alpha  # (1 - a)/alpha [s]
        self._Phi *= a
        self._Phi += g * YY
        self._ze *= a
        self._ze += g * Yz
        delta, Z = self.mixed()
        self.delta = delta
        if delta > 0.0:
            d2 = delta * delta
            x = self._gamma * (d2 / (self.mu + d2) if self.normalized else d2) * dt
            # theta_hat += (1 - e^-x)/Delta^2 * Delta (Z - Delta theta_hat)
            th += (-np.expm1(-x)) * (Z / delta - th)
        self._finish(e, dt)
        return th
