"""Detection bounds from collision-free runs, with the false-alarm rate they imply.

For a false-alarm rate ``alpha`` per sample (any joint), each joint gets the level
``alpha_j = alpha / nv`` (Bonferroni: the joints' rates add up to at most ``alpha``), and
its bound is the sum of two parts [N m or N]::

    b_j = b_noise_j + b_model_j

``b_noise_j``, the residual distribution: the ``1 - alpha_j`` quantile of ``|r_j|`` over
the calibration samples when they hold at least :data:`MIN_TAIL_SAMPLES` beyond it
(``N alpha_j >= 10``). With fewer, the tail is extrapolated (peaks over a threshold with
an exponential tail, heavier than a normal one): above ``u``, the ``1 - P_u`` quantile
(``P_u =`` :data:`TAIL_FRACTION`), ``P(|r_j| > x) = P_u exp(-(x - u) / beta)`` with
``beta`` the mean excess over ``u``, so ``b = u + beta ln(P_u / alpha_j)``, never below
the largest ``|r_j|`` seen.

``b_model_j``, the model's uncertainty, when the model carries a covariance ``Sigma`` of
its base parameters: the residual is linear in them, ``r = F[tau] - W theta_b`` with
``W = F[Y_b(q, dq, ddq)]`` the base regressor through the observer's filter ``F`` (the
same discrete low-pass), so its model part has the variance ``s_j(t)^2 = w_j(t)^T Sigma
w_j(t)``, and ``b_model_j = z sqrt(mean_t s_j(t)^2)``. ``ddq`` is the log's when it has
one, else central differences of ``dq`` (the filter smooths them). The covariance is the
result's as given (today the white-noise one, too small on correlated residuals).

The implied rates are measured: the fraction of calibration samples above the bounds,
per joint and for any joint (at most ``alpha`` by construction on these samples; on
new data the rate is what it is, see ``manip-id monitor``).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.special import ndtri

from .._checks import as_real
from .._io.fields import Fields
from .._io.reading import read_json
from ..datasets import parse_file_spec
from ..errors import DataError, InputError, MonitorWarning
from ..robot.model import Robot
from ..robot.regressor import iter_regressor
from .logs import MonitorLog, ReadOptions, as_logs, check_temperatures
from .observer import (
    DEFAULT_FILTER_GAIN,
    DEFAULT_GAIN,
    CollisionMonitor,
    MonitorModel,
    check_parameters,
    model_from_result,
)

#: Calibration samples beyond a joint's quantile needed to use the empirical quantile.
MIN_TAIL_SAMPLES = 10
#: Fraction of the calibration samples above the threshold of the tail extrapolation.
TAIL_FRACTION = 0.05
#: Default false-alarm rate per sample (any joint).
DEFAULT_FALSE_ALARM = 1e-3


@dataclass(frozen=True)
class Thresholds:
    """Per-joint detection bounds and how they were obtained (module docstring).

    Attributes
    ----------
    dof_names: joint names, length nv
    bound: detection bounds ``b_j``, shape (nv,) [N m or N]
    noise_bound: the residual-distribution part, shape (nv,)
    model_bound: the model-uncertainty part, shape (nv,) (zeros without a covariance)
    gain: the observer gain they were calibrated with, shape (nv,) [1/s]
    false_alarm: the asked false-alarm rate per sample (any joint)
    filter_gain: the residual filter they were calibrated with, shape (nv,), or None
    methods: per joint ``"empirical quantile"`` or ``"exponential tail"``
    rate: measured rate on the calibration samples (any joint above its bound)
    rate_per_joint: the same per joint, shape (nv,)
    n_samples: calibration samples
    covariance_kind: the kind of covariance behind ``model_bound``, or None
    files: the calibration logs
    in_sample: the calibration logs the model was identified on (its own residuals are
        smaller than a new run's: the bounds are too tight, false alarms above the rate)
    """

    dof_names: list[str]
    bound: np.ndarray
    noise_bound: np.ndarray
    model_bound: np.ndarray
    gain: np.ndarray
    filter_gain: np.ndarray | None
    false_alarm: float
    methods: list[str]
    rate: float
    rate_per_joint: np.ndarray
    n_samples: int
    covariance_kind: str | None = None
    files: list[str] = field(default_factory=list)
    in_sample: list[str] = field(default_factory=list)

    @property
    def level(self) -> float:
        """The per-joint level ``alpha / nv``."""
        return self.false_alarm / len(self.dof_names)

    def to_dict(self) -> dict:
        """JSON-ready, per joint by name."""
        return {
            "false_alarm": self.false_alarm,
            "level_per_joint": self.level,
            "n_samples": int(self.n_samples),
            "rate": float(self.rate),
            "covariance_kind": self.covariance_kind,
            "files": list(self.files),
            "in_sample": list(self.in_sample),
            "joints": [
                {
                    "name": n,
                    "bound": float(self.bound[j]),
                    "noise_bound": float(self.noise_bound[j]),
                    "model_bound": float(self.model_bound[j]),
                    "gain": float(self.gain[j]),
                    "filter_gain": None if self.filter_gain is None else float(self.filter_gain[j]),
                    "method": self.methods[j],
                    "rate": float(self.rate_per_joint[j]),
                }
                for j, n in enumerate(self.dof_names)
            ],
        }

    @classmethod
    def from_dict(cls, doc: dict) -> Thresholds:
        """The thresholds of :meth:`to_dict` (``manip-id monitor --json``'s ``thresholds``),
        e.g. to monitor online with bounds calibrated once."""
        try:
            joints = doc["joints"]
            fg = [j.get("filter_gain") for j in joints]
            return cls(
                dof_names=[str(j["name"]) for j in joints],
                bound=np.array([j["bound"] for j in joints], dtype=float),
                noise_bound=np.array([j["noise_bound"] for j in joints], dtype=float),
                model_bound=np.array([j["model_bound"] for j in joints], dtype=float),
                gain=np.array([j["gain"] for j in joints], dtype=float),
                filter_gain=None if any(g is None for g in fg) else np.array(fg, dtype=float),
                false_alarm=float(doc["false_alarm"]),
                methods=[str(j["method"]) for j in joints],
                rate=float(doc["rate"]),
                rate_per_joint=np.array([j["rate"] for j in joints], dtype=float),
                n_samples=int(doc["n_samples"]),
                covariance_kind=doc.get("covariance_kind"),
                files=list(doc.get("files", [])),
                in_sample=list(doc.get("in_sample", [])),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(
                f"not monitor thresholds (manip-id monitor --json 'thresholds'): "
                f"{type(exc).__name__}: {exc}"
            ) from exc


def _check_fields(f: Fields, doc: dict) -> None:
    """The types and ranges of a thresholds document, before :meth:`Thresholds.from_dict`."""
    for k, row in enumerate(f.list(doc.get("joints"), "joints", nonempty=True)):
        row = f.object(row, f"joints[{k}]")
        f.text(row.get("name"), f"joints[{k}].name")
        f.text(row.get("method"), f"joints[{k}].method")
        for key in ("bound", "noise_bound", "model_bound", "gain", "rate"):
            f.number(row.get(key), f"joints[{k}].{key}", minimum=0.0)
        f.optional_number(row.get("filter_gain"), f"joints[{k}].filter_gain", minimum=0.0)
    f.number(doc.get("false_alarm"), "false_alarm", positive=True, maximum=1.0)
    f.number(doc.get("rate"), "rate", minimum=0.0)
    n = doc.get("n_samples")
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise f.fail("n_samples", "an integer >= 0", n)
    for key in ("files", "in_sample"):
        if doc.get(key) is not None:
            f.list(doc[key], key)


def load_thresholds(path) -> Thresholds:
    """The thresholds saved by ``manip-id monitor --json`` (its ``thresholds``) or by
    ``json.dump(thresholds.to_dict())``; :class:`~manip_id.errors.DataError` otherwise."""
    p = Path(path)
    doc = read_json(p, "thresholds file")
    if isinstance(doc, dict) and isinstance(doc.get("thresholds"), dict):
        doc = doc["thresholds"]
    if not isinstance(doc, dict):
        raise DataError(f"{p}: not monitor thresholds (a JSON object is expected)")
    _check_fields(Fields(f"{p}: not monitor thresholds"), doc)
    try:
        return Thresholds.from_dict(doc)
    except DataError as exc:
        raise DataError(f"{p}: {exc}") from exc


def _theta_and_model(robot: Robot, model) -> tuple[np.ndarray, MonitorModel | None]:
    if isinstance(model, MonitorModel):
        return check_parameters(robot, model.theta), model
    if hasattr(model, "base") and hasattr(model, "estimate"):  # an IdentificationResult
        m = model_from_result(robot, model)
        return m.theta, m
    return check_parameters(robot, model), None


def _noise_bound(a: np.ndarray, level: float) -> tuple[float, str]:
    """The residual part of one joint's bound from ``|r_j|`` samples (module docstring)."""
    if a.size * level >= MIN_TAIL_SAMPLES:
        return float(np.quantile(a, 1.0 - level, method="higher")), "empirical quantile"
    u = float(np.quantile(a, 1.0 - TAIL_FRACTION))
    excess = a[a > u] - u
    beta = float(excess.mean()) if excess.size else 0.0
    tail = u + beta * float(np.log(TAIL_FRACTION / level))
    return max(float(a.max()), tail), "exponential tail"


def filtered_variance(
    robot: Robot, log: MonitorLog, model: MonitorModel, gain, filter_gain=None
) -> np.ndarray:
    """``mean_t s_j(t)^2`` (module docstring), shape (nv,) [(N m)^2]: the base regressor
    through the observer's filter (and its second low-pass when ``filter_gain``)."""
    if model.covariance is None or model.base is None:
        raise InputError("the model carries no covariance of its base parameters")
    cov = np.asarray(model.covariance, dtype=float)
    ind = model.base.independent  # type: ignore[attr-defined]
    ddq = log.ddq if log.ddq is not None else np.gradient(log.dq, log.t, axis=0)
    w = np.zeros((robot.nv, len(ind)))
    wf = np.zeros_like(w)
    dts = np.diff(log.t, prepend=log.t[0])
    total = np.zeros(robot.nv)
    for chunk in iter_regressor(robot, log.q, log.dq, ddq, chunk=1024, temp=log.temp):
        Yb = chunk.Y[:, :, ind]
        for i in range(Yb.shape[0]):
            k = chunk.start + i
            if k:
                a = np.exp(-gain * dts[k])[:, None]
                w = a * w + (1.0 - a) * Yb[i]
                if filter_gain is None:
                    wf = w
                else:
                    b = np.exp(-filter_gain * dts[k])[:, None]
                    wf = b * wf + (1.0 - b) * w
            total += np.einsum("jr,rs,js->j", wf, cov, wf)
    return total / log.n_samples


def calibrate_thresholds(
    robot: Robot,
    model,
    data,
    *,
    false_alarm: float = DEFAULT_FALSE_ALARM,
    gain=DEFAULT_GAIN,
    filter_gain=DEFAULT_FILTER_GAIN,
    options: ReadOptions | None = None,
) -> Thresholds:
    """Per-joint detection bounds from collision-free runs (module docstring).

    Parameters
    ----------
    robot: the robot
    model: standard parameters (p,), a :class:`~manip_id.monitor.MonitorModel`, or an
        :class:`~manip_id.identification.IdentificationResult` (whose covariance then
        adds the model-uncertainty part)
    data: collision-free logs: files (any format the pipeline reads, ``FILE@START:STOP``),
        :class:`~manip_id.monitor.logs.MonitorLog` s, datasets or ``{"t", "q", "dq",
        "tau"}`` mappings
    false_alarm: false-alarm rate per sample, any joint, in (0, 1)
    gain: observer gain [1/s], scalar or (nv,)
    filter_gain: second low-pass of the residual [1/s] (see
        :class:`~manip_id.monitor.CollisionMonitor`), or None
    options: how files are read (:class:`~manip_id.monitor.logs.ReadOptions`)

    Returns
    -------
    :class:`Thresholds`, with the rates measured on the calibration samples.
    """
    alpha = as_real(false_alarm, "false_alarm")
    if not 0.0 < alpha < 1.0:
        raise InputError(f"false_alarm must be a rate in (0, 1), got {alpha}")
    theta, mmodel = _theta_and_model(robot, model)
    mon = CollisionMonitor(robot, theta, None, gain=gain, filter_gain=filter_gain)
    logs = as_logs(robot, data, options)
    check_temperatures(logs, mon.needs_temperature)
    runs = [mon.run(lg.t, lg.q, lg.dq, lg.tau, file=lg.file, temp=lg.temp) for lg in logs]
    r = np.vstack([run.residual for run in runs])
    n, nv = r.shape
    level = alpha / nv
    a = np.abs(r)
    parts = [_noise_bound(a[:, j], level) for j in range(nv)]
    noise = np.array([p[0] for p in parts])
    model_part = np.zeros(nv)
    kind = None
    if mmodel is not None and mmodel.covariance is not None:
        var = sum(
            filtered_variance(robot, lg, mmodel, mon.gain, mon.filter_gain) * lg.n_samples
            for lg in logs
        )
        model_part = float(-ndtri(level / 2.0)) * np.sqrt(np.asarray(var) / n)
        kind = mmodel.covariance_kind
    bound = noise + model_part
    if not np.all(bound > 0):
        bad = int(np.flatnonzero(~(bound > 0))[0])
        raise DataError(
            f"the calibration residual of {robot.dof_names[bad]} is identically zero: "
            "no bound can be set (noise-free data?)"
        )
    above = a > bound
    own = _in_sample(logs, mmodel)
    if own:
        warnings.warn(
            MonitorWarning(
                f"the calibration log(s) {', '.join(own)} are the model's training data: a "
                "fit's residuals on its own data are smaller than on a new run, so these bounds "
                "are too tight (false alarms above the asked rate); calibrate on collision-free "
                "runs the model was not identified on"
            ),
            stacklevel=2,
        )
    return Thresholds(
        dof_names=list(robot.dof_names),
        bound=bound,
        noise_bound=noise,
        model_bound=model_part,
        gain=mon.gain.copy(),
        filter_gain=None if mon.filter_gain is None else mon.filter_gain.copy(),
        false_alarm=alpha,
        methods=[p[1] for p in parts],
        rate=float(above.any(axis=1).mean()),
        rate_per_joint=above.mean(axis=0),
        n_samples=n,
        covariance_kind=kind,
        files=[lg.file for lg in logs],
        in_sample=own,
    )


def _in_sample(logs: list[MonitorLog], model: MonitorModel | None) -> list[str]:
    """Labels of the calibration logs that are files (and windows) ``model`` was identified
    on: the same file, and the same window or a whole file on either side."""
    if model is None or not model.training:
        return []
    trained = [(os.path.realpath(path), window) for path, window in model.training]
    out = []
    for lg in logs:
        try:
            spec = parse_file_spec(lg.file)
        except (InputError, DataError, ValueError):
            continue
        if not spec.path.exists():
            continue
        here = (os.path.realpath(spec.path), None if spec.window is None else str(spec.window))
        if any(here[0] == p and (w is None or here[1] is None or w == here[1]) for p, w in trained):
            out.append(lg.file)
    return out
