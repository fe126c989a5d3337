"""Slotine-Li adaptive tracking control, with an optional composite (prediction-error) term.

Given a reference ``q_d(t)`` with ``dq_d``, ``ddq_d`` and the estimate ``theta_hat``
(signs of DESIGN.md: ``theta_tilde = theta_hat - theta``)::

    q_tilde = q - q_d                    (pinocchio.difference for continuous joints)
    dq_r    = dq_d - Lambda q_tilde      reference velocity
    ddq_r   = ddq_d - Lambda dq_tilde    reference acceleration
    s       = dq - dq_r                  sliding variable
    tau     = Y(q, dq, dq_r, ddq_r) theta_hat - K_D s
    d theta_hat/dt = -Gamma (Y^T s_D + kappa Y_f^T eps / m^2),  m^2 = 1 + tr(Y_f Gamma Y_f^T)

with the Slotine-Li regressor ``Y(q, dq, v, w) theta = M v + C(q, dq) w + g + joint
terms`` (:meth:`manip_id.robot.regressor.RegressorEvaluator.slotine_li`). ``Lambda`` is positive
diagonal, ``K_D`` and ``Gamma`` symmetric positive definite.

Why it works. With the closed loop ``M ds/dt + C s + F_v s = -K_D s + Y theta_tilde``
(``F_v`` the viscous friction, part of ``theta``) and ``dM/dt - 2C`` skew-symmetric,
the Lyapunov function

    V = 1/2 s^T M(q) s + 1/2 theta_tilde^T Gamma^-1 theta_tilde

has ``dV/dt = -s^T (K_D + F_v) s - kappa |eps|^2 / m^2 <= 0`` (:func:`lyapunov_function`).
Coulomb friction breaks the exact cancellation (``sign(dq) != sign(dq_r)``).

Robustness options. Dead zone: ``s_D = s - clip(s, -delta, delta)`` replaces ``s`` in
the adaptation (no adaptation while every ``|s_j| <= delta``). Projection: after each
step ``theta_hat`` is clipped to ``[lower, upper]``; for a diagonal ``Gamma`` this is
the Gamma-weighted projection, so V still does not increase.

Composite adaptation (``kappa > 0``). Inverse dynamics is written without the
acceleration, through the generalized momentum ``p = M(q) dq = Y_p(q, dq) theta``::

    tau = d/dt [Y_p theta] + Y_h(q, dq) theta,
    Y_p = Y^{g=0}(q, 0, dq) (armature column: dq_j)
    Y_h = Y(q, dq, 0) - d/de Y^{g=0}(q + e dq, 0, dq)|_{e=0}   (= -C^T dq + g + friction)

(``dM/dt dq`` by a forward difference along ``dq``). Filtering both sides with
``W(s) = lambda_f / (s + lambda_f)`` gives, exactly and without measured accelerations::

    tau_f = Y_f theta,   Y_f = lambda_f (Y_p - W[Y_p]) + W[Y_h],   tau_f = W[tau]

(starting from ``W[Y_p](0) = Y_p(0)``, ``W[Y_h](0) = 0``, ``tau_f(0) = 0``, the
identity holds at every instant). The prediction error is
``eps = Y_f theta_hat - tau_f = Y_f theta_tilde``. The normalization ``m^2`` makes
``kappa`` a rate [1/s] and keeps the explicit Euler step of the composite term stable
(``kappa dt < 2``) whatever the scale of ``Y_f``. The filters are discretized exactly
for the zero-order-held torque and with a first-order hold (linear interpolation
between control instants) for the regressors.

Time-varying gain (``gain="rls"``, Slotine & Li's composite law with an RLS-type
gain). ``Gamma`` becomes ``P(t)``, started at ``Gamma`` and driven like a
recursive least-squares covariance by the filtered regressor, with bounded-gain
forgetting::

    d theta_hat/dt = -P (Y^T s_D + kappa Y_f^T eps / m^2),   m^2 = 1 + tr(Y_f P Y_f^T)
    d P^-1/dt      = -beta(t) P^-1 + kappa Y_f^T Y_f / m^2,  beta = beta_0 (1 - tr(P)/tr(Gamma))

so the directions the filtered regressor has excited get a gain that shrinks like
``1/information`` (the parameter error converges direction by direction like
least squares instead of at the gradient law's fixed rate), ``tr(P) <= tr(Gamma)``
and, with ``V = 1/2 s^T M s + 1/2 theta_tilde^T P^-1 theta_tilde``,
``dV/dt = -s^T (K_D + F_v) s - kappa |eps|^2 / (2 m^2) - beta/2 theta_tilde^T P^-1
theta_tilde <= 0``. Discretely, ``P^-1 += dt kappa Y_f^T Y_f / m^2`` is applied
with the matrix inversion lemma (``P`` stays symmetric positive definite), then
``P /= 1 - beta dt``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .._checks import as_float_array, check_finite, positive_vector, spd_matrix
from ..errors import InputError
from ..robot.model import Robot
from ..robot.regressor import RegressorEvaluator


@dataclass(frozen=True)
class AdaptiveGains:
    """Gains of the Slotine-Li controller (validated against a robot by the controller).

    Attributes
    ----------
    lam : float or numpy.ndarray
        Lambda, diagonal [1/s], a scalar or shape (nv,), positive.
    kd : float or numpy.ndarray
        K_D [N m s/rad], a positive scalar, a positive diagonal (nv,) or a symmetric
        positive definite matrix (nv, nv).
    gamma : float or numpy.ndarray
        Gamma, adaptation gain, a scalar, its diagonal (p,) or a symmetric
        positive definite matrix (p, p).
    composite : float
        kappa >= 0 [1/s], weight of the normalized prediction-error term
        (see the module docstring); 0 gives the plain Slotine-Li law.
    filter_bandwidth : float
        lambda_f > 0 of the composite filter lambda_f/(s + lambda_f) [rad/s].
    dead_zone : float
        delta >= 0 on each s_j [rad/s].
    lower, upper : numpy.ndarray, optional
        optional bounds on theta_hat, shape (p,) (+-inf for none).
    gain : str
        "constant" (Gamma) or "rls" (the time-varying P(t) of the module
        docstring; needs ``composite > 0``). With bounds, the box clip is not the
        P-weighted projection once P is not diagonal: V may then increase at a clip.
    forgetting : float
        beta_0 >= 0 of the bounded-gain forgetting with ``gain="rls"`` [1/s].
    """

    lam: float | np.ndarray = 10.0
    kd: float | np.ndarray = 10.0
    gamma: float | np.ndarray = 1.0
    composite: float = 0.0
    filter_bandwidth: float = 20.0
    dead_zone: float = 0.0
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    gain: str = "constant"
    forgetting: float = 0.0


@dataclass(frozen=True)
class CompositeLaw:
    """The composite adaptation of :func:`default_gains` (fields as in :class:`AdaptiveGains`).

    Attributes
    ----------
    kappa : float
        Weight kappa >= 0 [1/s] of the normalized prediction-error term; 0 gives the plain
        Slotine-Li law.
    filter_bandwidth : float
        lambda_f > 0 of the composite filter lambda_f/(s + lambda_f) [rad/s].
    gain : str
        ``"constant"`` (Gamma) or ``"rls"`` (the time-varying P(t); needs ``kappa > 0``).
    forgetting : float
        beta_0 >= 0 of the bounded-gain forgetting with ``gain="rls"`` [1/s].
    """

    kappa: float = 0.0
    filter_bandwidth: float = 20.0
    gain: str = "constant"
    forgetting: float = 0.0


def default_gains(
    robot: Robot,
    theta: np.ndarray | None = None,
    q: np.ndarray | None = None,
    *,
    lam: float = 20.0,
    kd_rate: float = 50.0,
    gamma: float = 1.0,
    dead_zone: float = 0.0,
    composite: float | CompositeLaw = 0.0,
) -> AdaptiveGains:
    """Gains scaled to the robot.

    ``Lambda = lam I``; ``K_D = kd_rate M(q)`` with M of ``theta`` (default nominal)
    at ``q`` (default :meth:`Robot.neutral`), so that near ``q`` every mode of
    ``M ds/dt = -K_D s`` decays at ``kd_rate`` [1/s] (a diagonal K_D is either too
    stiff for the light modes or too soft for the heavy ones of a coupled arm);
    ``Gamma = gamma diag(scale^2)`` with ``scale_i = |theta_i| + floor(unit_i)``
    (floors 1 kg, 0.1 kg m, 0.01 kg m^2, 1 for joint terms, the sizes of an arm's
    links): each parameter adapts in proportion to its size. ``dead_zone`` as in
    :class:`AdaptiveGains`. ``composite`` is kappa [1/s] of the composite law with its
    default filter, or a :class:`CompositeLaw` (filter bandwidth, ``gain="rls"``,
    forgetting; with ``gain="rls"``, Gamma is P(0)).
    """
    law = composite if isinstance(composite, CompositeLaw) else CompositeLaw(kappa=composite)
    theta = robot.nominal_parameters if theta is None else as_float_array(theta, "theta", 1)
    q = robot.neutral() if q is None else as_float_array(q, "q", 1)
    model = robot.with_parameters(theta)
    M = pin.crba(model, model.createData(), q)
    M = np.triu(M) + np.triu(M, 1).T
    floors = {"kg": 1.0, "kg m": 0.1, "kg m^2": 0.01}
    floor = np.array(
        [floors.get(u, 1.0) for u in robot.parameter_units[: robot.n_rigid]]
        + [1.0] * (robot.n_parameters - robot.n_rigid)
    )
    scale = np.abs(theta) + floor
    return AdaptiveGains(
        lam=lam,
        kd=kd_rate * M,
        gamma=gamma * scale**2,
        composite=law.kappa,
        filter_bandwidth=law.filter_bandwidth,
        dead_zone=dead_zone,
        gain=law.gain,
        forgetting=law.forgetting,
    )


def _nonnegative(x, name: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number, got {x!r}") from exc
    if not math.isfinite(v) or v < 0:
        raise InputError(f"{name} must be finite and >= 0, got {v}")
    return v


class SlotineLiController:
    """The Slotine-Li adaptive controller of one robot (see the module docstring).

    Call :meth:`torque` at each control instant, then :meth:`adapt` with the time
    to the next instant. The constructor checks everything; the hot methods check what
    changes per call at a cost of about three microseconds (the closed-loop simulation calls
    them 1000 times per simulated second, next to a Pinocchio regressor of tens of
    microseconds): the shapes and dtype of :meth:`torque`'s arrays, that ``dt`` of
    :meth:`adapt` is a finite number > 0, and that the reference is finite
    (:class:`~manip_id.errors.InputError` otherwise, before any state changes).

    **Dropouts**: a measured ``q`` or ``dq`` holding NaN or Inf (a sensor dropout) is
    skipped: :meth:`torque` returns the last torque again (held) and :meth:`adapt` goes on
    integrating with the last used instant's quantities (with the constant gain, exactly
    the run of a controller that never saw the instant; the composite filters span the
    gap with the held torque); :attr:`skipped` says so and :attr:`dropouts` counts them.
    A dropout at the first instant has no torque to hold: zeros.

    Parameters
    ----------
    robot : Robot
        the robot (its joint terms define the parameter layout).
    theta0 : array_like
        initial estimate, shape (p,).
    gains : AdaptiveGains, optional
        :class:`AdaptiveGains`.
    adapt : bool
        False holds ``theta_hat`` fixed at ``theta0`` (computed-torque-like
        tracking with wrong parameters, the comparison baseline).
    """

    def __init__(
        self, robot: Robot, theta0, gains: AdaptiveGains | None = None, *, adapt: bool = True
    ):
        gains = AdaptiveGains() if gains is None else gains
        p, nv = robot.n_parameters, robot.nv
        theta0 = as_float_array(theta0, "theta0", ndim=1)
        if theta0.shape != (p,):
            raise InputError(f"{theta0.shape=} but robot.n_parameters={p}")
        check_finite(theta0, "theta0")
        self.robot = robot
        self.lam = positive_vector(gains.lam, "lam (Lambda)", nv, "1/s")
        self.kd = spd_matrix(gains.kd, "kd (K_D)", nv, "N m s/rad")
        self.gamma = spd_matrix(gains.gamma, "gamma (Gamma)", p, "theta unit^2 / s")
        self.kappa = _nonnegative(gains.composite, "composite (kappa)")
        self.lam_f = _nonnegative(gains.filter_bandwidth, "filter_bandwidth")
        if self.kappa > 0 and self.lam_f <= 0:
            raise InputError("filter_bandwidth must be positive [rad/s] for composite adaptation")
        self.dead_zone = _nonnegative(gains.dead_zone, "dead_zone")
        if gains.gain not in ("constant", "rls"):
            raise InputError(f"gain must be 'constant' or 'rls', got {gains.gain!r}")
        if gains.gain == "rls" and self.kappa <= 0:
            raise InputError("gain='rls' is driven by the composite term: give composite > 0")
        self.rls = gains.gain == "rls"
        self.beta0 = _nonnegative(gains.forgetting, "forgetting")
        self.lower, self.upper = self._bounds(gains, theta0)
        self.adapting = bool(adapt)
        self.gains = gains
        self.ev = RegressorEvaluator(robot)
        self._lie = robot.nq != robot.nv
        self._diag_gamma = np.count_nonzero(self.gamma - np.diag(np.diag(self.gamma))) == 0
        self._gdiag = np.diag(self.gamma).copy()
        # state and preallocated work arrays
        self.theta_hat = theta0.copy()
        self.Y = np.zeros((nv, p))
        self.s = np.zeros(nv)
        self.tau = np.zeros(nv)
        self.q_tilde = np.zeros(nv)
        self.eps = np.zeros(nv)
        self.norm2 = 1.0
        self._grad = np.zeros(p)
        self.skipped = False  # the last torque call was a dropout (class docstring)
        self.dropouts = 0
        if self.rls:  # the time-varying gain P(t), from Gamma
            self.P = self.gamma.copy()
            self._trace0 = float(np.trace(self.gamma))
            self._steps = 0
        if self.kappa > 0:
            self._init_composite()

    # --------------------------------------------------------------- checks
    def _bounds(self, gains: AdaptiveGains, theta0: np.ndarray):
        p = theta0.shape[0]
        if gains.lower is None and gains.upper is None:
            return None, None
        lo = np.full(p, -np.inf) if gains.lower is None else as_float_array(gains.lower, "lower", 1)
        hi = np.full(p, np.inf) if gains.upper is None else as_float_array(gains.upper, "upper", 1)
        if lo.shape != (p,) or hi.shape != (p,):
            raise InputError(f"bounds must have shape ({p},), got {lo.shape=} and {hi.shape=}")
        if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
            i = int(np.argmax(np.isnan(lo) | np.isnan(hi) | (lo > hi)))
            raise InputError(
                f"bounds must satisfy lower <= upper; parameter "
                f"{self.robot.parameter_names[i]}: [{lo[i]}, {hi[i]}]"
            )
        out = (theta0 < lo) | (theta0 > hi)
        if out.any():
            i = int(np.argmax(out))
            raise InputError(
                f"theta0 lies outside the bounds: {self.robot.parameter_names[i]} = "
                f"{theta0[i]:g} not in [{lo[i]:g}, {hi[i]:g}]"
            )
        return lo, hi

    # ------------------------------------------------------------ composite
    def _init_composite(self) -> None:
        nv, p, nr = self.robot.nv, self.robot.n_parameters, self.robot.n_rigid
        self._Yp = np.zeros((nv, p))
        self._Yh = np.zeros((nv, p))
        self._Yp_prev = np.zeros((nv, p))
        self._Yh_prev = np.zeros((nv, p))
        self._Pf = np.zeros((nv, p))
        self._Hf = np.zeros((nv, p))
        self._tauf = np.zeros(nv)
        self._tau_prev = np.zeros(nv)
        self.Yf = np.zeros((nv, p))
        self._h = 0.0  # time since the previous control instant (0: first call)
        self._started = False
        terms = self.robot.terms.enabled
        self._ia_cols = None
        if self.robot.layout.has_term("Ia"):
            self._ia_cols = self.robot.layout.joint_columns("Ia")
        self._zero = np.zeros(nv)
        self._rows = np.arange(nv)
        self._nr = nr
        self._has_terms = bool(terms)

    def _composite_regressors(self, q, dq) -> None:
        """Fill Y_p(q, dq) and Y_h(q, dq) (see the module docstring)."""
        ev, nr = self.ev, self._nr
        shape = (self.robot.nv, nr)

        def f(model, data, q, v, a) -> np.ndarray:
            # (nv, nr) always: eigenpy returns a 1-DoF model's 1 x nr regressor as (nr,)
            return np.reshape(pin.computeJointTorqueRegressor(model, data, q, v, a), shape)

        zero = self._zero
        Yp, Yh = self._Yp, self._Yh
        Yp[:, :nr] = f(ev.model0, ev.data0, q, zero, dq)
        if self._ia_cols is not None:
            Yp[self._rows, self._ia_cols] = dq
        Yh[:, :nr] = f(ev.model, ev.data, q, dq, zero)
        norm = math.sqrt(float(dq @ dq))
        if norm > 0:
            # dM/dt dq by a forward difference along dq (step 1e-8 rad: error ~1e-8 relative)
            e = 1e-8 / norm
            qp = pin.integrate(ev.model, q, e * dq) if self._lie else q + e * dq
            dM = f(ev.model0, ev.data0, qp, zero, dq)
            dM -= Yp[:, :nr]
            dM *= 1.0 / e
            Yh[:, :nr] -= dM
        if self._has_terms:
            ev.fill_joint_terms(Yh, q, dq, zero)

    def _advance_filters(self) -> None:
        """Move the filter states from the previous control instant to this one."""
        h, lf = self._h, self.lam_f
        a = math.exp(-lf * h)
        # first-order hold for the continuous regressors, exact ZOH for the held torque
        c = (1.0 - a - a * lf * h) / (lf * h)
        b1 = 1.0 - a - c
        for state, prev, cur in (
            (self._Pf, self._Yp_prev, self._Yp),
            (self._Hf, self._Yh_prev, self._Yh),
        ):
            state *= a
            state += c * prev
            state += b1 * cur
        self._tauf *= a
        self._tauf += (1.0 - a) * self._tau_prev

    # ------------------------------------------------------------ hot path
    def torque(self, q, dq, q_d, dq_d, ddq_d) -> np.ndarray:
        """Control torque at one instant, shape (nv,) [N m or N].

        ``q``, ``q_d`` shape (nq,); the others (nv,) (checked, class docstring; a measured
        ``q`` or ``dq`` with NaN/Inf is a dropout: the last torque is held).
        The returned array is reused at the next call: copy it to keep it.
        """
        q, dq, q_d, dq_d, ddq_d = self._check_instant(q, dq, q_d, dq_d, ddq_d)
        total = sum(q.tolist()) + sum(dq.tolist()) + sum(q_d.tolist()) + sum(dq_d.tolist())
        if not math.isfinite(total + sum(ddq_d.tolist())):  # one NaN/Inf (or an overflow)
            self._check_reference(q_d, dq_d, ddq_d)
            if not (np.isfinite(q).all() and np.isfinite(dq).all()):
                self.skipped = True
                self.dropouts += 1
                return self.tau
        self.skipped = False
        ev = self.ev
        if self._lie:
            qt = pin.difference(ev.model, q_d, q)
        else:
            qt = q - q_d
        self.q_tilde[:] = qt
        dqt = dq - dq_d
        dq_r = dq_d - self.lam * qt
        ddq_r = ddq_d - self.lam * dqt
        np.subtract(dq, dq_r, out=self.s)
        Y = ev.slotine_li(q, dq, ddq_r, dq_r, self.Y)
        np.dot(Y, self.theta_hat, out=self.tau)
        self.tau -= self.kd @ self.s
        if self.kappa > 0:
            self._composite_regressors(q, dq)
            if not self._started:
                self._Pf[:] = self._Yp
                self._started = True
            elif self._h > 0:
                self._advance_filters()
            Yf = self.Yf
            np.subtract(self._Yp, self._Pf, out=Yf)
            Yf *= self.lam_f
            Yf += self._Hf
            np.dot(Yf, self.theta_hat, out=self.eps)
            self.eps -= self._tauf
            if self.rls:
                self._PYt = self.P @ Yf.T  # (p, nv)
                gy = float(np.einsum("ij,ji->", Yf, self._PYt))
            elif self._diag_gamma:
                gy = float(np.einsum("ij,ij,j->", Yf, Yf, self._gdiag))
            else:
                gy = float(np.einsum("ij,jk,ik->", Yf, self.gamma, Yf))
            self.norm2 = 1.0 + gy
        return self.tau

    def adapt(self, dt: float) -> None:
        """Integrate the adaptation law over ``dt`` [s] (a finite number > 0; explicit Euler,
        quantities of the last :meth:`torque` call held), then project onto the bounds.
        After a dropout (:attr:`skipped`) the quantities of the last used instant stay held,
        as its torque is."""
        if type(dt) is not float:
            if isinstance(dt, bool) or not isinstance(dt, (int, np.integer, np.floating)):
                raise InputError(f"dt must be a number of seconds, got {type(dt).__name__}")
            dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise InputError(f"dt must be a finite positive time step [s], got {dt}")
        if self.kappa > 0:
            if self.skipped:  # the filters span the gap from the last used instant
                self._h += dt
            else:
                self._h = dt
                self._Yp_prev, self._Yp = self._Yp, self._Yp_prev
                self._Yh_prev, self._Yh = self._Yh, self._Yh_prev
                self._tau_prev[:] = self.tau
        if not self.adapting:
            return
        s = self.s
        if self.dead_zone > 0:
            s = s - np.clip(s, -self.dead_zone, self.dead_zone)
        g = self._grad
        np.dot(s, self.Y, out=g)
        if self.kappa > 0:
            g += (self.kappa / self.norm2) * (self.eps @ self.Yf)
        if self.rls:
            self.theta_hat -= dt * (self.P @ g)
            self._update_gain(dt)
        elif self._diag_gamma:
            g *= self._gdiag
            g *= dt
            self.theta_hat -= g
        else:
            self.theta_hat -= dt * (self.gamma @ g)
        if self.lower is not None:
            np.clip(self.theta_hat, self.lower, self.upper, out=self.theta_hat)

    def _check_instant(self, q, dq, q_d, dq_d, ddq_d) -> tuple[np.ndarray, ...]:
        """The arrays of one :meth:`torque` call as float64, shapes checked (the float64
        arrays of the hot loop pass untouched)."""
        nq, nv = self.robot.nq, self.robot.nv
        f = np.float64
        if (  # the hot loop's float64 arrays of the right shapes
            type(q) is np.ndarray and q.dtype == f and q.shape == (nq,)
            and type(dq) is np.ndarray and dq.dtype == f and dq.shape == (nv,)
            and type(q_d) is np.ndarray and q_d.dtype == f and q_d.shape == (nq,)
            and type(dq_d) is np.ndarray and dq_d.dtype == f and dq_d.shape == (nv,)
            and type(ddq_d) is np.ndarray and ddq_d.dtype == f and ddq_d.shape == (nv,)
        ):  # fmt: skip
            return q, dq, q_d, dq_d, ddq_d
        out = []
        for x, name, n in (
            (q, "q", nq), (dq, "dq", nv), (q_d, "q_d", nq), (dq_d, "dq_d", nv), (ddq_d, "ddq_d", nv)
        ):  # fmt: skip
            a = x if type(x) is np.ndarray and x.dtype == np.float64 else as_float_array(x, name)
            if a.shape != (n,):
                raise InputError(f"{name}.shape={a.shape} but the robot needs ({n},)")
            out.append(a)
        return tuple(out)

    @staticmethod
    def _check_reference(q_d, dq_d, ddq_d) -> None:
        """:class:`InputError` naming a reference array that holds NaN or Inf."""
        for a, name in ((q_d, "q_d"), (dq_d, "dq_d"), (ddq_d, "ddq_d")):
            if not np.isfinite(a).all():
                raise InputError(f"the reference {name} holds NaN or Inf: {a.tolist()}")

    def _update_gain(self, dt: float) -> None:
        """``P^-1 += dt kappa Y_f^T Y_f / m^2`` (inversion lemma), then bounded forgetting."""
        P, PYt = self.P, self._PYt
        c = dt * self.kappa / self.norm2
        if c > 0:
            S = self.Yf @ PYt  # (nv, nv)
            S.flat[:: S.shape[0] + 1] += 1.0 / c
            P -= PYt @ np.linalg.solve(S, PYt.T)
        if self.beta0 > 0:
            beta = self.beta0 * max(1.0 - float(np.trace(P)) / self._trace0, 0.0)
            P *= 1.0 / (1.0 - min(beta * dt, 0.5))
        self._steps += 1
        if self._steps % 64 == 0:
            P += P.T
            P *= 0.5


def lyapunov_function(robot: Robot, theta, gamma: np.ndarray, q, s, theta_hat) -> np.ndarray:
    """``V = 1/2 s^T M(q) s + 1/2 theta_tilde^T Gamma^-1 theta_tilde`` along a run.

    Parameters
    ----------
    theta : array_like
        true parameters, shape (p,) (M includes their armature).
    gamma : numpy.ndarray
        Gamma, shape (p, p) (e.g. ``controller.gamma``).
    q : array_like
        positions, shape (N, nq).
    s : array_like
        sliding variable [rad/s], shape (N, nv).
    theta_hat : array_like
        estimates, shape (N, p).

    Returns
    -------
    numpy.ndarray
        V [J], shape (N,).
    """
    theta = as_float_array(theta, "theta", 1)
    q = as_float_array(q, "q", 2)
    s = as_float_array(s, "s", 2)
    theta_hat = as_float_array(theta_hat, "theta_hat", 2)
    if not (q.shape[0] == s.shape[0] == theta_hat.shape[0]):
        raise InputError(f"{q.shape=}, {s.shape=}, {theta_hat.shape=}: need the same N")
    model = robot.with_parameters(theta)
    data = model.createData()
    kinetic = np.empty(q.shape[0])
    for k in range(q.shape[0]):
        M = pin.crba(model, data, q[k])
        M = np.triu(M) + np.triu(M, 1).T
        kinetic[k] = 0.5 * s[k] @ M @ s[k]
    tilde = theta_hat - theta
    sol = np.linalg.solve(np.asarray(gamma, dtype=float), tilde.T).T
    return kinetic + 0.5 * np.einsum("ij,ij->i", tilde, sol)
