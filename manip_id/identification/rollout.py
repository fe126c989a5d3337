"""Rollout validation: the identified model integrated forward from the measured torques.

From each of many start points ``s`` of a log (uniform step ``dt`` [s]), the model of
:mod:`.forward` is integrated over a horizon of ``H`` steps with the measured torque as
input, by the semi-implicit (symplectic) Euler step at the log rate::

    dq_{k+1} = dq_k + dt ddq(q_k, dq_k, tau_k)
    q_{k+1}  = q_k + dt dq_{k+1}                    q_s, dq_s: the measured state

and compared with the log at the horizon: per joint the RMS over start points of
``q_sim(s + H) - q(s + H)`` [rad or m] and of the velocity error [rad/s or m/s], and the
share of start points whose position error stays within a tolerance. A rollout whose
state leaves the finite numbers (a model that is not positive definite along the path, or
unstable) is counted as diverged and left out of the RMS (the count is reported).
The identified and the nominal model are rolled out alike, side by side.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..datasets import Dataset, Layout, parse_file_spec
from ..errors import InputError
from ..robot.model import Robot
from .forward import DEFAULT_EPS, ForwardModel, coulomb_width, standard_with_base
from .options import PreprocessOptions
from .reading import iter_processed

#: Position error [rad or m] within which a horizon counts as followed.
DEFAULT_TOLERANCE = 0.01
#: Most start points per log.
DEFAULT_STARTS = 200
#: Start points whose traces a figure shows.
TRACES = 3
INTEGRATOR = "semi-implicit Euler at the log step, the measured torque as input"


@dataclass(frozen=True)
class RolloutOptions:
    """How a rollout validation runs.

    horizon: seconds integrated from each start point [s].
    starts: most start points per log (evenly spread over it).
    tolerance: position error [rad or m] within which a horizon counts as followed.
    eps: smallest width of the Coulomb regularization ``tanh(dq / eps)`` [rad/s or m/s].
    """

    horizon: float = 0.25
    starts: int = DEFAULT_STARTS
    tolerance: float = DEFAULT_TOLERANCE
    eps: float = DEFAULT_EPS

    def __post_init__(self):
        if not (np.isfinite(self.horizon) and self.horizon > 0):
            raise InputError(f"the rollout horizon must be > 0 seconds, got {self.horizon}")
        if int(self.starts) != self.starts or self.starts < 1:
            raise InputError(f"the number of start points must be >= 1, got {self.starts}")
        if not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise InputError(f"the rollout tolerance must be > 0, got {self.tolerance}")
        if not (np.isfinite(self.eps) and self.eps > 0):
            raise InputError(f"the Coulomb regularization width must be > 0, got {self.eps}")


@dataclass(frozen=True)
class Log:
    """One uniformly sampled log: ``t`` (N,) [s], ``q`` (N, nq), ``dq`` (N, nv), ``tau`` (N, nv)."""

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    name: str = ""

    @property
    def dt(self) -> float:
        """The log step [s] (the mean one)."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))


def as_log(data, name: str = "") -> Log:
    """A :class:`Log` of a :class:`~manip_id.datasets.Dataset` (or anything with ``t, q,
    dq, tau``); the steps must be uniform (preprocessed data are)."""
    t = np.asarray(data.t, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise InputError(f"a rollout needs at least 3 samples, got t.shape={t.shape}")
    steps = np.diff(t)
    if not np.all(steps > 0) or np.ptp(steps) > 1e-3 * steps.mean():
        raise InputError(
            "a rollout integrates at the log step: the time stamps must be uniform "
            f"(steps from {steps.min():.4g} to {steps.max():.4g} s); preprocess (resample) "
            "the data first"
        )
    return Log(
        t, np.asarray(data.q, float), np.asarray(data.dq, float), np.asarray(data.tau, float), name
    )


def read_logs(robot: Robot, files, options: PreprocessOptions | None = None) -> list[Dataset]:
    """Each file (a path, ``PATH@START:STOP`` or a :class:`~manip_id.datasets.FileSpec`)
    read and preprocessed as identification reads it (:func:`.reading.iter_processed`),
    whole, as one :class:`~manip_id.datasets.Dataset` with ``ddq``."""
    out = []
    for f in files:
        spec = parse_file_spec(f)
        _, blocks = iter_processed(robot, spec, options)
        parts = list(blocks)
        if not parts:
            raise InputError(f"{spec.label}: no samples left after preprocessing")
        rows = np.concatenate(parts)
        sl = Layout.processed(robot.nq, robot.nv, rows.shape[1]).slices
        if "ddq" not in sl:
            raise InputError(f"{spec.label}: no accelerations after preprocessing")
        out.append(
            Dataset(
                t=rows[:, 0],
                q=rows[:, sl["q"]],
                dq=rows[:, sl["dq"]],
                tau=rows[:, sl["tau"]],
                ddq=rows[:, sl["ddq"]],
                meta={"file": spec.label},
            )
        )
    return out


def start_points(n: int, steps: int, most: int) -> np.ndarray:
    """At most ``most`` start indices, evenly spread, each with ``steps`` samples after it."""
    last = n - 1 - steps
    if last < 0:
        raise InputError(
            f"the horizon of {float(steps):.4g} steps is longer than the log ({n} samples): "
            "use a shorter horizon or a longer log"
        )
    return np.unique(np.linspace(0, last, min(int(most), last + 1)).round().astype(int))


def simulate(fm: ForwardModel, log: Log, start: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The states ``q`` and ``dq`` of a rollout from sample ``start``, shape (steps + 1, nv)
    each (row 0 the measured state; NaN from the first non-finite state on)."""
    nv = log.dq.shape[1]
    q = np.full((steps + 1, nv), np.nan)
    v = np.full((steps + 1, nv), np.nan)
    q[0], v[0] = log.q[start], log.dq[start]
    dt = log.dt
    with np.errstate(all="ignore"):
        for k in range(steps):
            a = fm.acceleration(q[k], v[k], log.tau[start + k])
            v[k + 1] = v[k] + dt * a
            q[k + 1] = q[k] + dt * v[k + 1]
            if not (np.all(np.isfinite(q[k + 1])) and np.abs(v[k + 1]).max() < 1e6):
                q[k + 1 :], v[k + 1 :] = np.nan, np.nan
                break
    return q, v


@dataclass(frozen=True)
class RolloutErrors:
    """Errors of one model's rollouts at the horizon, per joint (nv,)."""

    position_rms: np.ndarray
    velocity_rms: np.ndarray
    within: np.ndarray
    n_starts: int
    diverged: int

    def to_dict(self) -> dict:
        return {
            "position_rms": self.position_rms.tolist(),
            "velocity_rms": self.velocity_rms.tolist(),
            "within_tolerance": self.within.tolist(),
            "n_starts": self.n_starts,
            "diverged": self.diverged,
        }


@dataclass(frozen=True)
class Trace:
    """One rollout for a figure: ``t`` (H+1,) [s], measured and simulated ``q`` (H+1, nv)."""

    t: np.ndarray
    measured: np.ndarray
    identified: np.ndarray
    nominal: np.ndarray | None


@dataclass(frozen=True)
class RolloutReport:
    """Rollout errors of the identified model and the nominal one at one horizon.

    ``to_dict()`` is the JSON ``rollout`` section: ``{"horizon": s, "identified":
    {"position_rms": [per joint], "velocity_rms": [...], ...}, "nominal": {same}, ...}``.
    """

    horizon: float
    dt: float
    tolerance: float
    eps: np.ndarray
    joints: list[str]
    identified: RolloutErrors
    nominal: RolloutErrors | None
    traces: list[Trace] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "horizon": self.horizon,
            "step": self.dt,
            "joints": list(self.joints),
            "identified": self.identified.to_dict(),
            "nominal": None if self.nominal is None else self.nominal.to_dict(),
            "tolerance": self.tolerance,
            "integrator": INTEGRATOR,
            "regularization": "Coulomb sign(dq) integrated as tanh(dq / eps), eps per joint "
            f"{[round(float(e), 6) for e in self.eps]} [rad/s or m/s]",
        }

    def table(self) -> str:
        """Per joint position / velocity RMS at the horizon, identified vs nominal."""
        head = f"rollout over {self.horizon:g} s ({self.identified.n_starts} start points)"
        lines = [head, f"  {'joint':<16} {'identified q [rad]':>19} {'nominal q [rad]':>16}"]
        nom = self.nominal
        for j, name in enumerate(self.joints):
            n = "" if nom is None else f"{nom.position_rms[j]:16.4g}"
            lines.append(f"  {name:<16} {self.identified.position_rms[j]:19.4g} {n}")
        for label, e in (("identified", self.identified), ("nominal", nom)):
            if e is not None and e.diverged:
                lines.append(f"  {label}: {e.diverged} of {e.n_starts} rollouts diverged")
        return "\n".join(lines)


def _errors(finals: list, meas: list, tol: float) -> RolloutErrors:
    q = np.array([f[0] for f in finals])
    v = np.array([f[1] for f in finals])
    mq = np.array([m[0] for m in meas])
    mv = np.array([m[1] for m in meas])
    ok = np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(v), axis=1)
    eq, ev = q[ok] - mq[ok], v[ok] - mv[ok]
    nv = mq.shape[1]
    if not ok.any():
        nan = np.full(nv, np.nan)
        return RolloutErrors(nan, nan.copy(), np.zeros(nv), len(finals), len(finals))
    within = (np.abs(eq) <= tol).sum(axis=0) / len(finals)
    return RolloutErrors(
        np.sqrt(np.mean(eq**2, axis=0)),
        np.sqrt(np.mean(ev**2, axis=0)),
        within,
        len(finals),
        int((~ok).sum()),
    )


def rollout_validation(
    robot: Robot, result, logs, *, options: RolloutOptions | None = None
) -> RolloutReport:
    """Rollout errors of ``result`` (an :class:`~.IdentificationResult`) and of the
    robot's nominal model on ``logs`` (datasets with uniform ``t, q, dq, tau``).

    The identified standard vector is :func:`~.forward.standard_with_base` of the
    result's base parameters; the Coulomb width (:func:`~.forward.coulomb_width`) is the
    one of the identified model, and the nominal model is integrated with the same.
    """
    options = options or RolloutOptions()
    logs = [lg if isinstance(lg, Log) else as_log(lg) for lg in logs]
    if not logs:
        raise InputError("a rollout validation needs at least one log")
    if len(result.base.names) != robot.n_parameters or list(result.base.names) != list(
        robot.parameter_names
    ):
        raise InputError(
            f"the result was identified for {len(result.base.names)} parameters "
            f"({result.robot_name}) but the robot has {robot.n_parameters}"
        )
    dt = logs[0].dt
    theta = standard_with_base(robot, result.estimate, result.base)
    eps = coulomb_width(robot, theta, np.concatenate([lg.q[::50] for lg in logs]), dt, options.eps)
    fm_id = ForwardModel(robot, theta, eps)
    fm_nom = ForwardModel(robot, robot.nominal_parameters, eps)
    finals: dict = {"id": [], "nom": []}
    meas: list = []
    traces: list[Trace] = []
    for lg in logs:
        steps = max(1, int(round(options.horizon / lg.dt)))
        starts = start_points(len(lg.t), steps, options.starts)
        shown = set(starts[np.linspace(0, len(starts) - 1, min(TRACES, len(starts))).astype(int)])
        for s in starts:
            qi, vi = simulate(fm_id, lg, s, steps)
            qn, vn = simulate(fm_nom, lg, s, steps)
            finals["id"].append((qi[-1], vi[-1]))
            finals["nom"].append((qn[-1], vn[-1]))
            meas.append((lg.q[s + steps], lg.dq[s + steps]))
            if s in shown and len(traces) < TRACES:
                sl = slice(s, s + steps + 1)
                traces.append(Trace(lg.t[sl].copy(), lg.q[sl].copy(), qi, qn))
    return RolloutReport(
        horizon=float(options.horizon),
        dt=dt,
        tolerance=float(options.tolerance),
        eps=eps,
        joints=list(robot.model.names[1:]) if not result.dof_names else list(result.dof_names),
        identified=_errors(finals["id"], meas, options.tolerance),
        nominal=_errors(finals["nom"], meas, options.tolerance),
        traces=traces,
    )


__all__ = [
    "DEFAULT_TOLERANCE",
    "Log",
    "RolloutErrors",
    "RolloutOptions",
    "RolloutReport",
    "Trace",
    "as_log",
    "read_logs",
    "rollout_validation",
    "simulate",
    "start_points",
]
