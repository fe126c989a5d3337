"""The generalized-momentum observer on an identified model (De Luca's residual).

With the identified dynamics ``M(q) ddq + C(q, dq) dq + g(q) + f(q, dq) = tau + tau_ext``
(``f``: viscous, Coulomb, offset and spring terms; the armature belongs to ``M``), the
generalized momentum ``p = M(q) dq`` obeys ``dp/dt = tau + C^T(q, dq) dq - g - f + tau_ext``
(because ``dM/dt = C + C^T``). The residual::

    r(t) = K (p(t) - p(0) - int_0^t (tau + C^T dq - g - f + r) ds)

satisfies ``dr/dt = K (tau_ext - r)``: each joint's ``r_j`` is the external torque
through a first-order low-pass of bandwidth ``K_j`` [1/s], and needs no acceleration.

Discrete form (what :meth:`CollisionMonitor.step` computes). Let ``u = tau + C^T dq - g - f``
and, between samples ``k-1`` and ``k`` (step ``dt``), ``ds = (p_k - p_{k-1}) - dt (u_k +
u_{k-1}) / 2``, the increment of ``int tau_ext`` (momentum exactly, the rest by the
trapezoidal rule). Holding ``tau_ext`` constant over the step, the filter
``dr/dt = K (ds/dt - r)`` is solved exactly::

    r_k = a r_{k-1} + (1 - a) ds / dt,        a = exp(-K dt)

so the discrete observer is stable for every gain and step (the Euler form ``r_k = K (p_k -
p_0 - I_k)`` is not for ``K dt > 2``) and tends to the continuous one as ``dt -> 0``.

Velocity noise. ``p = M dq`` enters ``r`` unfiltered: a velocity error ``e`` shows as
``K M e`` at once. With ``filter_gain=K2`` the residual is low-passed once more,
``dr_f/dt = K2 (r - r_f)`` (same exact discretization), so that ``r_f`` follows ``tau_ext``
through ``K K2 / ((s + K)(s + K2))``: unit gain at rest, noise above ``K2`` attenuated, a
longer delay (default ``K2 = K = 25`` [1/s], which on the real Panda log at 1 kHz keeps the
velocity glitches under the bounds); ``filter_gain=None`` is the first-order observer above.

Friction laws. ``f`` is every enabled joint term with the robot's friction shapes (Stribeck
velocities, sigmoid slopes, the temperature law's reference ``T0``); the ``temperature`` law
uses the measured temperature of each sample (``temp`` of :meth:`CollisionMonitor.step`, the
logs' ``temp`` field, as identify reads it). The ``load`` law (the nominal rigid-body torque,
which needs the acceleration the observer avoids) and the ``hysteresis`` law (a state of the
whole path) are refused when the monitor is built, in one line.

The model is the robot's Pinocchio model with the identified inertias and armature
(:meth:`~manip_id.robot.model.Robot.with_parameters`) and the identified joint terms. A standard
vector that has the identified base parameters gives the same ``M``, ``C^T dq``, ``g`` and
``f`` whatever its values on the regrouped directions (a direction with ``Y theta = 0`` for
every ``q, dq, ddq`` has ``M = 0`` and ``g = 0``, hence ``C^T dq = dM/dt dq - C dq = 0``), so
:func:`model_from_result` builds it from any result's base parameters, plain or consistent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from .._checks import as_float_array, check_finite, positive_vector
from ..errors import InputError, MissingTemperatureError, ModelMismatchError
from ..identification import load_result
from ..robot.model import Robot, available_robots
from .detections import MonitorRun

#: Default observer gain [1/s]: a 25 rad/s bandwidth (time constant 40 ms).
DEFAULT_GAIN = 25.0
#: Default bandwidth of the residual's second low-pass [1/s] (None: the first-order observer).
DEFAULT_FILTER_GAIN = 25.0


@dataclass(frozen=True)
class MonitorModel:
    """The identified model the observer runs on.

    Attributes
    ----------
    robot_name: the robot the parameters were identified for.
    theta: standard parameters, shape (p,) [units of ``robot.parameter_units``].
    covariance: covariance of the base parameters, shape (r, r), or None.
    covariance_kind: what that covariance is (``"white-noise"``: ``sigma2 (Y_b^T Y_b)^-1``,
        too small on correlated residuals; the result's own name when it gives one), or None.
    base: the base parametrization the covariance refers to, or None.
    source: where the model came from (a result file, ``"robot"`` for its own parameters).
    training: the logs the model was identified on, ``(path, window or None)`` each (a file
        run's result; empty when unknown, e.g. arrays).
    """

    robot_name: str
    theta: np.ndarray
    covariance: np.ndarray | None = None
    covariance_kind: str | None = None
    base: object | None = None
    source: str = ""
    training: tuple[tuple[str, str | None], ...] = ()


def check_parameters(robot: Robot, theta: ArrayLike) -> np.ndarray:
    """``theta`` as a finite (p,) vector of ``robot``, or :class:`ModelMismatchError`."""
    arr = as_float_array(theta, "theta", ndim=1)
    if arr.shape[0] != robot.n_parameters:
        raise ModelMismatchError(
            "the model's parameters",
            f"{robot.n_parameters} standard parameters of {robot.name!r} (terms "
            f"{','.join(robot.terms.enabled) or 'none'})",
            f"{arr.shape[0]}",
        )
    check_finite(arr, "theta")
    return arr


def covariance_kind(result) -> str:
    """What a result's ``covariance`` is: its ``covariance_kind`` (attribute, or key of the
    saved JSON) when it says, else ``"white-noise"`` (``sigma2 (Y_b^T Y_b)^-1``, what
    results hold before they carry an honest one)."""
    kind = getattr(result, "covariance_kind", None)
    if kind is None:
        kind = (getattr(result, "context", None) or {}).get("covariance_kind")
    if kind is None and isinstance(getattr(result, "uncertainty", None), dict):
        method = result.uncertainty.get("method")  # "hac": honest std, white correlations
        kind = {"hac": "honest (hac std, white-noise correlations)"}.get(method, kind)
    return str(kind) if kind else "white-noise"


def model_from_result(robot: Robot, result, source: str = "") -> MonitorModel:
    """The :class:`MonitorModel` of an identification result (plain, consistent, fleet).

    The standard vector is :func:`standard_from_base` of the result's base parameters
    (exact for the observer, module docstring). The covariance is the result's ``covariance`` as
    given: today the white-noise one ``sigma2 (Y_b^T Y_b)^-1`` (OLS; WLS its weighted form),
    which is too small when the residuals are correlated; a result that says which kind it
    carries (``context["covariance_kind"]``) is taken at its word.

    Raises :class:`ModelMismatchError` when the result was identified for another robot
    (two different robots known by name, e.g. ``ur10`` for ``ur5``; a robot loaded from a
    URDF file is checked by its parameter names only) or other joint terms (its base
    parameters name other standard parameters).
    """
    base = result.base
    known = set(available_robots())
    if result.robot_name != robot.name and {result.robot_name, robot.name} <= known:
        raise ModelMismatchError(
            "the model", f"a model of {robot.name!r}", f"a model of {result.robot_name!r}"
        )
    if list(base.names) != list(robot.parameter_names):
        theirs = sorted(set(base.names) - set(robot.parameter_names))
        raise ModelMismatchError(
            "the model's parameters",
            f"the {robot.n_parameters} parameters of {robot.name!r} "
            f"({robot.parameter_names[0]}, ...)",
            f"{len(base.names)} parameters of {result.robot_name!r}"
            + (f" (e.g. {theirs[0]})" if theirs else ""),
        )
    theta = standard_from_base(robot, result.estimate, base)
    test = getattr(result, "test_covariance", None)
    cov = np.asarray(test() if callable(test) else result.covariance, dtype=float)
    ok = cov.shape == (len(result.estimate),) * 2 and bool(np.isfinite(cov).all())
    kind = covariance_kind(result) if ok else None
    return MonitorModel(
        robot_name=str(result.robot_name),
        theta=check_parameters(robot, theta),
        covariance=cov if ok else None,
        covariance_kind=kind,
        base=base,
        source=source,
        training=training_logs(result),
    )


def training_logs(result) -> tuple[tuple[str, str | None], ...]:
    """``(path, window or None)`` of each file a result was identified on: the file run's
    accumulations in memory, the ``files`` of a saved result; empty when it does not say."""
    files = getattr(result, "files", None)
    if isinstance(files, dict):
        specs = [getattr(f, "spec", None) for f in files.get("train") or []]
        return tuple(
            (str(s.path), None if s.window is None else str(s.window))
            for s in specs
            if s is not None
        )
    saved = (getattr(result, "context", None) or {}).get("files")
    if not isinstance(saved, list):
        return ()
    return tuple(
        (str(f["file"]), None if f.get("window") is None else str(f["window"]))
        for f in saved
        if isinstance(f, dict) and isinstance(f.get("file"), str)
    )


def standard_from_base(robot: Robot, theta_base: ArrayLike, base) -> np.ndarray:
    """A standard vector with base parameters ``theta_base``: the robot's nominal values on
    the regrouped (dependent) columns, ``theta[I] = theta_b - K theta_nom[D]`` on the others.

    (Zero on the dependent columns would leave bodies of zero mass, which a Pinocchio
    inertia cannot hold.) Exact: ``base.to_base(theta) == theta_base``.
    """
    nominal = robot.nominal_parameters
    theta = nominal.copy()
    dep, ind = base.dependent, base.independent
    theta[ind] = np.asarray(theta_base, dtype=float) - base.K @ nominal[dep]
    return theta


def load_model(robot: Robot, path) -> MonitorModel:
    """The :class:`MonitorModel` of a saved result (``manip-id identify --json``, a report's
    result.json); :class:`~manip_id.errors.DataError` for a file that is not one."""
    return model_from_result(robot, load_result(path), source=str(path))


def model_from_robot(robot: Robot) -> MonitorModel:
    """The robot's own parameters as the model (an exported URDF loaded with its sidecar,
    ``load_robot(URDF, identified=True)``); no covariance."""
    return MonitorModel(robot.name, robot.nominal_parameters.copy(), source="robot")


@dataclass(frozen=True)
class MonitorStep:
    """One observer step: ``residual`` [N m or N] and ``detected`` per joint, shape (nv,);
    ``skipped``: the sample was not finite and was left out (:meth:`CollisionMonitor.step`)."""

    residual: np.ndarray
    detected: np.ndarray
    skipped: bool = False


class CollisionMonitor:
    """The momentum observer (module docstring) with per-joint detection bounds.

    Parameters
    ----------
    robot: the robot (its joint terms decide which friction terms ``theta`` holds).
    theta: standard parameters, shape (p,), or a :class:`MonitorModel`.
    thresholds: detection bounds [N m or N]: a scalar or shape (nv,), a
        :class:`~manip_id.monitor.Thresholds` (its joints must be the robot's), or None
        (no detection: every flag False).
    gain: observer gain ``K`` [1/s], a scalar or one per joint (nv,).
    filter_gain: bandwidth ``K2`` [1/s] of a second low-pass of the residual (module
        docstring), scalar or (nv,); None: none (the first-order observer).

    Use :meth:`step` once per sample (the first call only initializes, ``r = 0``) and
    :meth:`reset` between runs; :meth:`run` runs a whole log.

    **Dropouts**: a sample holding NaN or Inf (a sensor dropout; the temperature too, for
    the ``temperature`` law) is skipped: the observer's state is left as it was, its ``dt``
    is added to the next sample's (the integral spans the gap), the returned
    :class:`MonitorStep` has ``skipped=True`` and the last residual, and :attr:`dropouts`
    counts them. One dropout therefore never blinds the monitor. The check costs three
    ``isfinite`` calls of nv values a step (about a microsecond).

    **Friction laws** (module docstring): with the ``temperature`` law every :meth:`step`
    needs ``temp`` (and :meth:`run` a ``temp`` per sample); the ``load`` and ``hysteresis``
    laws are refused with :class:`~manip_id.errors.InputError`.
    """

    def __init__(
        self,
        robot: Robot,
        theta,
        thresholds=None,
        *,
        gain: ArrayLike = DEFAULT_GAIN,
        filter_gain: ArrayLike | None = DEFAULT_FILTER_GAIN,
    ):
        if isinstance(theta, MonitorModel):
            theta = theta.theta
        tr = robot.transmission
        if tr is not None and tr.n_parameters:
            raise InputError(
                f"the monitor does not model motor terms (the drive train of {robot.name!r} "
                f"has {', '.join(tr.motor_terms)}): identify the model for the monitor with a "
                "transmission without motor_terms (the logs are still converted)"
            )
        self.robot = robot
        self.theta = check_parameters(robot, theta)
        self.thresholds = _bounds(robot, thresholds)  # before the gains: they may be theirs
        self.gain = positive_vector(gain, "gain", robot.nv, "1/s")
        self.filter_gain = (
            None
            if filter_gain is None
            else positive_vector(filter_gain, "filter_gain", robot.nv, "1/s")
        )
        _check_gains(thresholds, self.gain, self.filter_gain)
        self.model = robot.with_parameters(self.theta)
        self.data = self.model.createData()
        self._model0 = self.model.copy()  # gravity-free: rnea(q, 0, dq) = M(q) dq
        self._model0.gravity = pin.Motion.Zero()
        self._data0 = self._model0.createData()
        self.nq, self.nv = robot.nq, robot.nv
        self._zero = np.zeros(self.nv)
        self._terms = _friction_terms(robot, self.theta)
        self._shapes = robot.layout.shapes
        self.needs_temperature = any(t.needs == "temp" for t, _ in self._terms)
        self._spring = robot.layout.has_term("k")
        self._dt = -1.0  # the step of the cached decay factors [s]
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next :meth:`step` starts a new run."""
        self.dropouts = 0  # samples skipped as not finite since the last reset
        self._gap = 0.0  # [s] the steps of skipped samples, added to the next one
        self._p: np.ndarray | None = None
        self._u = np.zeros(self.nv)
        self._r = np.zeros(self.nv)  # the first-order residual [N m or N]
        self.residual = np.zeros(self.nv)  # the output (filtered when filter_gain) [N m or N]

    # ------------------------------------------------------------- the model
    def momentum_and_input(
        self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, temp: np.ndarray | None = None
    ):
        """``p = M(q) dq`` and ``u = tau + C^T(q, dq) dq - g(q) - f(q, dq)``, shape (nv,) each
        (``temp`` (nv,) [degC or K]: the temperature law's, else None)."""
        model, data = self.model, self.data
        p = pin.rnea(self._model0, self._data0, q, self._zero, dq)  # M(q) dq, armature too
        C = pin.computeCoriolisMatrix(model, data, q, dq)
        g = pin.computeGeneralizedGravity(model, data, q)
        u = tau + C.T @ dq - g
        if self._terms:
            angles = self.robot.dofs.angles(q) if self._spring else None
            for term, coef in self._terms:
                u -= term.torque(coef, angles, dq, None, self._shapes, temp=temp)
        return p.copy(), u

    # ------------------------------------------------------------------ steps
    def step(
        self, q: ArrayLike, dq: ArrayLike, tau: ArrayLike, dt: float, temp: ArrayLike | None = None
    ) -> MonitorStep:
        """Advance the observer by one sample (module docstring, discrete form).

        Parameters
        ----------
        q: joint positions, shape (nq,) [rad or m]
        dq: joint velocities, shape (nv,) [rad/s or m/s]
        tau: measured joint torques, shape (nv,) [N m or N]
        dt: time since the previous sample [s], a finite number > 0 (checked on every
            call; its value is not used on the first)
        temp: the joints' temperature [degC or K], a scalar, (1,) or (nv,): needed by the
            ``temperature`` friction law (else ignored)

        Returns
        -------
        :class:`MonitorStep`: the residual (the estimated external torque) and
        ``|r_j| > bound_j`` per joint; a sample with NaN or Inf is skipped (class docstring).
        """
        if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating, np.integer)):
            raise InputError(f"dt must be a number of seconds, got {type(dt).__name__}")
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be a finite positive time step [s], got {dt}")
        q, dq, tau = _sample(q, "q"), _sample(dq, "dq"), _sample(tau, "tau")
        if q.shape != (self.nq,) or dq.shape != (self.nv,) or tau.shape != (self.nv,):
            raise InputError(
                f"step takes one sample: {q.shape=}, {dq.shape=}, {tau.shape=} but "
                f"robot.nq={self.nq}, robot.nv={self.nv}"
            )
        temp = self._temperature(temp)
        finite = np.isfinite(q).all() and np.isfinite(dq).all() and np.isfinite(tau).all()
        if not finite or (temp is not None and not np.isfinite(temp).all()):
            self.dropouts += 1
            if self._p is not None:
                self._gap += float(dt)
            last = self.residual.copy()
            return MonitorStep(last, np.abs(last) > self.thresholds, skipped=True)
        p, u = self.momentum_and_input(q, dq, tau, temp)
        if self._p is not None:
            dt, self._gap = float(dt) + self._gap, 0.0
            if dt != self._dt:  # decay factors, recomputed when the step changes
                self._dt = dt
                self._a = np.exp(-self.gain * dt)
                if self.filter_gain is not None:
                    self._b = np.exp(-self.filter_gain * dt)
            a = self._a
            ds = (p - self._p) - 0.5 * dt * (u + self._u)  # [N m s]
            self._r = a * self._r + (1.0 - a) * (ds / dt)
            if self.filter_gain is None:
                self.residual = self._r
            else:
                b = self._b
                self.residual = b * self.residual + (1.0 - b) * self._r
        self._p, self._u = p, u
        return MonitorStep(self.residual.copy(), np.abs(self.residual) > self.thresholds)

    def _temperature(self, temp) -> np.ndarray | None:
        """One sample's temperature as (nv,), or None when the law does not need it."""
        if not self.needs_temperature:
            return None
        if temp is None:
            raise MissingTemperatureError("the sample", "arrays", ("q", "dq", "tau"))
        arr = as_float_array(temp, "temp", ndim=(0, 1))
        if arr.ndim and arr.shape not in ((1,), (self.nv,)):
            raise InputError(
                f"temp.shape={arr.shape} but robot.nv={self.nv}: give one temperature per "
                "joint or one for every joint"
            )
        return np.broadcast_to(arr, (self.nv,))

    def run(
        self,
        t: ArrayLike,
        q: ArrayLike,
        dq: ArrayLike,
        tau: ArrayLike,
        file: str = "",
        temp: ArrayLike | None = None,
    ) -> MonitorRun:
        """The observer over one log (it is :meth:`reset` first).

        ``t`` (N,) [s], increasing; ``q`` (N, nq); ``dq``, ``tau`` (N, nv); ``file`` the
        log's label; ``temp`` (N, nv) or (N, 1) [degC or K], the ``temperature`` law's
        (else ignored). Returns the :class:`~manip_id.monitor.MonitorRun` (residuals, flags,
        detection intervals).
        """
        ts, qs, dqs, taus = _check_log(self.robot, t, q, dq, tau)
        temps = self._log_temperature(temp, dqs, file)
        self.reset()
        r = np.empty((ts.size, self.nv))
        dts = np.diff(ts, prepend=ts[0])
        for k in range(ts.size):
            tk = None if temps is None else temps[k]
            r[k] = self.step(qs[k], dqs[k], taus[k], float(dts[k]) if k else 1.0, tk).residual
        return MonitorRun(
            t=ts,
            residual=r,
            bounds=self.thresholds.copy(),
            dof_names=list(self.robot.dof_names),
            file=file,
        )

    def _log_temperature(self, temp, dq: np.ndarray, file: str) -> np.ndarray | None:
        """A log's temperature broadcast to ``dq``'s shape, or None when not needed."""
        if not self.needs_temperature:
            return None
        if temp is None:
            raise MissingTemperatureError(file or "the log", "arrays", ("t", "q", "dq", "tau"))
        arr = as_float_array(temp, "temp", ndim=2)
        if arr.shape[0] != dq.shape[0] or arr.shape[1] not in (1, self.nv):
            raise InputError(
                f"temp.shape={arr.shape} but dq.shape={dq.shape}: give one temperature column "
                f"per joint ({self.nv}) or one for every joint, one row per sample"
            )
        check_finite(arr, "temp")
        return np.broadcast_to(arr, dq.shape)


def _sample(x, name: str) -> np.ndarray:
    """One sample's array: a float64 array passes as it is (the hot path), anything else
    through :func:`~manip_id._checks.as_float_array` (our error for text, complex, objects)."""
    if type(x) is np.ndarray and x.dtype == np.float64:
        return x
    return as_float_array(x, name)


#: Joint terms the observer cannot evaluate from one sample, and why.
_UNSUPPORTED = {
    "load": "the load law needs the nominal rigid-body torque, hence the acceleration the "
    "observer avoids",
    "history": "the hysteresis law's state depends on the whole path, not on one sample",
}


def _friction_terms(robot: Robot, theta: np.ndarray) -> list:
    """(term, coefficients (nv,)) of the enabled joint terms except the armature (in M);
    :class:`InputError` for a law the observer cannot evaluate (module docstring)."""
    lay = robot.layout
    for t in lay.term_table:
        if t.needs in _UNSUPPORTED:
            raise InputError(
                f"the collision monitor cannot run the {t.flag} friction law ({t.name} term): "
                f"{_UNSUPPORTED[t.needs]}; identify a model without it for the monitor"
            )
    return [(t, theta[lay.joint_columns(t.name)].copy()) for t in lay.term_table if t.name != "Ia"]


def _bounds(robot: Robot, thresholds) -> np.ndarray:
    """Detection bounds (nv,) [N m or N] from None, a scalar, an array or a Thresholds."""
    if thresholds is None:
        return np.full(robot.nv, np.inf)
    names = getattr(thresholds, "dof_names", None)
    if names is not None:
        if list(names) != list(robot.dof_names):
            raise ModelMismatchError(
                f"the thresholds' joints (robot {robot.name} moves other joints)",
                f"{list(robot.dof_names)}",
                f"{list(names)}",
            )
        thresholds = thresholds.bound
    arr = as_float_array(thresholds, "thresholds", ndim=(0, 1))
    if arr.ndim == 1 and arr.shape != (robot.nv,):
        raise ModelMismatchError(
            "the thresholds", f"one per joint ({robot.nv})", f"shape {arr.shape}"
        )
    arr = np.broadcast_to(arr, (robot.nv,)).copy()
    if np.isnan(arr).any() or np.any(arr <= 0):
        raise InputError(f"thresholds must be positive [N m], got {arr.tolist()}")
    return arr


def _check_gains(thresholds, gain: np.ndarray, filter_gain: np.ndarray | None) -> None:
    """Bounds calibrated with other gains do not hold for this observer."""
    if not hasattr(thresholds, "gain"):
        return
    theirs = thresholds.filter_gain
    same = np.allclose(thresholds.gain, gain) and (
        (theirs is None and filter_gain is None)
        or (theirs is not None and filter_gain is not None and np.allclose(theirs, filter_gain))
    )
    if not same:

        def text(g, f):
            return f"gain {np.asarray(g).tolist()}, filter_gain " + (
                "None" if f is None else f"{np.asarray(f).tolist()}"
            )

        raise InputError(
            f"the thresholds were calibrated with {text(thresholds.gain, theirs)}, but this "
            f"monitor has {text(gain, filter_gain)}: calibrate with the monitor's gains"
        )


def _check_log(robot: Robot, t, q, dq, tau) -> tuple[np.ndarray, ...]:
    t = as_float_array(t, "t", ndim=1)
    q = as_float_array(q, "q", ndim=2)
    dq = as_float_array(dq, "dq", ndim=2)
    tau = as_float_array(tau, "tau", ndim=2)
    n = t.size
    if q.shape != (n, robot.nq) or dq.shape != (n, robot.nv) or tau.shape != (n, robot.nv):
        raise InputError(
            f"{t.shape=}, {q.shape=}, {dq.shape=}, {tau.shape=} but robot.nq={robot.nq}, "
            f"robot.nv={robot.nv}"
        )
    if n < 2:
        raise InputError(f"a log needs at least 2 samples, got {n}")
    for arr, name in ((t, "t"), (q, "q"), (dq, "dq"), (tau, "tau")):
        check_finite(arr, name)
    steps = np.diff(t)
    if not np.all(steps > 0):
        k = int(np.flatnonzero(~(steps > 0))[0])
        raise InputError(f"t must increase, but t[{k + 1}]={t[k + 1]} after t[{k}]={t[k]}")
    return t, q, dq, tau
