"""The document of an identification run: the result's one schema plus what the run knows.

:func:`result_document` is the JSON that ``manip-id identify --json`` writes and a report
folder's ``result.json`` holds: :meth:`~manip_id.identification.IdentificationResult.to_dict`
with the run's context (source, preprocessing, which torques the errors compare with,
validation samples, a simulation's truth, the run's own warnings). :func:`add_raw_reference`
adds the errors against the raw torques when the reference torques were filtered;
:func:`add_file_info` the per-file records of log files.

Relative errors are ``||tau - tau_hat|| / ||tau||`` over all stacked samples and joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np


def _finite(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class RunContext:
    """What a run knows besides its result.

    Attributes
    ----------
    method : str
        The estimator asked for (``ols``, ``wls``, ``rls``, ``gradient``).
    source : dict
        Where the data came from (``data``, ``simulated``, ``split``, ``validate`` ...).
    n_validation : int
        Validation samples (0 without validation).
    settings : object or None
        The preprocessing settings of the training data (a dataclass), None for raw data.
    theta_true : numpy.ndarray or None
        A simulation's true standard parameters, shape (p,).
    timings : dict
        Seconds per stage [s].
    poorly_identified : float or None
        Flag threshold on the std [%] (None: the result's default).
    condition_limit : float or None
        Warning threshold on the condition number (None: the result's default).
    """

    method: str
    source: dict
    n_validation: int = 0
    settings: Any = None
    theta_true: np.ndarray | None = None
    timings: dict = field(default_factory=dict)
    poorly_identified: float | None = None
    condition_limit: float | None = None


@dataclass(frozen=True)
class ReportSamples:
    """The samples a report draws: ``t``, ``q``, ``dq``, ``ddq``, ``tau`` of each part.

    Attributes
    ----------
    train : object
        The (preprocessed) training samples.
    valid : object or None
        The (preprocessed) validation samples.
    full : object or None
        The whole record before the split (animated in the scene; a simulation's
        trajectory is drawn against the limits).
    """

    train: Any
    valid: Any = None
    full: Any = None


@dataclass(frozen=True)
class ReportOptions:
    """How a report is drawn.

    Attributes
    ----------
    source : str
        The data in words (file names, ``simulated``, ``3 files``).
    simulated : bool
        A simulation: its trajectory is drawn against the position limits.
    chunk : int
        Samples per regressor chunk of the predictions.
    scene_assets : str
        ``inline`` (scene.html stands alone) or ``external``.
    force : bool
        Replace a report folder manip_id wrote.
    rollout : RolloutReport or None
        The rollout validation (``identify --rollout``) whose traces are drawn
        (:class:`~manip_id.identification.rollout.RolloutReport`).
    """

    source: str
    simulated: bool = False
    chunk: int = 1024
    scene_assets: str = "inline"
    force: bool = False
    rollout: Any = None


def reference_torques(settings) -> str:
    """Which torques the errors are measured against, in words."""
    if settings is None or not settings.filter_torque:
        return "raw (as measured, not filtered)"
    return f"filtered at {settings.cutoff:g} Hz (zero-phase Butterworth, order {settings.order})"


def run_warnings(settings, source) -> list[str]:
    """The run's own warnings: filtered reference torques, validation repeating training."""
    out = []
    if settings is not None and settings.filter_torque:
        out.append(
            f"the reference torques were low-pass filtered at {settings.cutoff:g} Hz "
            f"(zero-phase Butterworth, order {settings.order}): the errors and figures "
            "compare the models with the filtered torques, not the raw ones"
        )
    sim = source.get("simulated") if isinstance(source, dict) else None
    if sim and source.get("split") is not None and sim.get("period"):
        trained = float(source["split"]) * float(sim["duration"])  # [s]
        if trained >= float(sim["period"]):
            out.append(
                f"the validation data repeat the training motion: the excitation is periodic "
                f"({sim['period']:g} s) and --split {source['split']:g} trains on "
                f"{trained:g} s, more than one period; the validation error then measures "
                "noise, not prediction on new motion (use --validate with another trajectory)"
            )
    return out


def _truth(result, theta_true) -> dict:
    """A simulation's base-parameter error against its truth."""
    estimate = np.asarray(result.estimate, dtype=float)
    std = np.asarray(result.std, dtype=float)
    beta_true = np.asarray(result.base.to_base(theta_true), dtype=float)
    err = estimate - beta_true
    return {
        "parameter_error": _finite(np.linalg.norm(err) / np.linalg.norm(beta_true)),
        "parameter_error_in_std": _finite(np.max(np.abs(err) / np.where(std > 0, std, np.inf))),
        "true_base_parameters": beta_true.tolist(),
    }


def result_document(robot, result, run: RunContext) -> dict:
    """The run's JSON: the result's one schema (:meth:`IdentificationResult.to_dict`)
    with what only the run knows (:class:`RunContext`)."""
    settings = run.settings
    ctx: dict = {
        "n_validation_samples": int(run.n_validation),
        "joint_terms": list(robot.terms.enabled),
        "source": run.source,
        "preprocess": None
        if settings is None
        else {k: getattr(settings, k) for k in settings.__dataclass_fields__},
        "reference_torques": reference_torques(settings),
        "warnings": run_warnings(settings, run.source),
    }
    if run.theta_true is not None:
        ctx.update(_truth(result, run.theta_true))
    result = replace(
        result,
        method=run.method,
        timings={k: float(v) for k, v in run.timings.items()},
        context={**result.context, **ctx},
    )
    return result.to_dict(
        poorly_identified=run.poorly_identified, condition_limit=run.condition_limit
    )


def add_raw_reference(report: dict, robot, result, parts, chunk: int) -> None:
    """When the reference torques were filtered, the errors against the raw ones too.

    parts: ``(name, processed, t_raw, tau_raw)`` with name "train" or "validation",
    ``processed`` holding t, q, dq, ddq, tau (the filtered samples) and the raw torques
    of the same record [N m] (scaled as the processed ones) at times ``t_raw`` [s]; the raw
    torques are interpolated linearly at the processed times (the processed samples
    are the raw ones, trimmed, or resampled on a uniform grid).
    Adds ``relative_error_raw`` {train, validation, nominal_train, nominal_validation}
    and states both references in ``reference_torques``, unless the identification
    measured them itself (its raw pass over the files).
    """
    pre = report.get("preprocess") or {}
    if not pre.get("filter_torque") or report.get("relative_error_raw"):
        return  # raw torques as the reference, or the identification's own raw pass
    nominal = replace(result, estimate=result.nominal)
    out: dict = {}
    for name, proc, t_raw, tau_raw in parts:
        t_raw = np.asarray(t_raw, dtype=float)
        if proc is None or proc.t[0] < t_raw[0] - 1e-9 or proc.t[-1] > t_raw[-1] + 1e-9:
            return  # the processed times are not on the raw record's clock: not comparable
        raw = np.column_stack(
            [np.interp(proc.t, t_raw, np.asarray(tau_raw)[:, j]) for j in range(robot.nv)]
        )
        for key, model in (("", result), ("nominal_", nominal)):
            temp = getattr(proc, "temp", None)  # the temperature law's
            pred = model.predict(robot, proc.q, proc.dq, proc.ddq, chunk=chunk, temp=temp)
            out[f"{key}{name}"] = _finite(np.linalg.norm(raw - pred) / np.linalg.norm(raw))
    if not out:
        return
    report["relative_error_raw"] = out
    pct = {k: "n/a" if v is None else f"{100 * v:.3g} %" for k, v in out.items()}
    report["reference_torques"] += (
        f"; against the raw torques at the same samples: identified model train "
        f"{pct.get('train', 'n/a')}"
        + (f", validation {pct['validation']}" if "validation" in pct else "")
        + f" (nominal model train {pct.get('nominal_train', 'n/a')}"
        + (f", validation {pct['nominal_validation']}" if "nominal_validation" in pct else "")
        + ")"
    )


def add_file_info(report, robot, specs, vspecs, scans, files, options, result) -> None:
    """The per-file records of log files: data quality, torque scale, files, deadband.

    specs, vspecs: the training and validation file specs; scans: spec -> its scan (with a
    ``quality`` summary); files: ``{"train": [...], "validation": [...] or None}`` of the
    accumulated files, or None (the online laws); options: the preprocessing options.
    """
    joints = list(robot.dof_names)
    report["data_quality"] = [scans[s].quality.to_dict() for s in specs]
    if vspecs is not None:
        report["validation_data_quality"] = [scans[s].quality.to_dict() for s in vspecs]
    report["torque_scale"] = None if options.torque_scale is None else list(options.torque_scale)
    if files is not None:
        report["files"] = [f.summary(joints) for f in files["train"]]
        if files["validation"] is not None:
            report["validation_files"] = [f.summary(joints) for f in files["validation"]]
        if options.velocity_deadband is not None:
            report["velocity_deadband"] = _deadband(joints, files, options.velocity_deadband)
    vpf = result.relative_error.validation_per_file
    if vpf is not None:
        report["relative_error"]["validation_per_file"] = vpf
    warnings_ = [w for s in list(specs) + list(vspecs or []) for w in scans[s].quality.warnings]
    report["data_warnings"] = warnings_


def _deadband(joints, files, eps: float) -> dict:
    """Rows left out per joint by a velocity deadband of ``eps`` [rad/s]."""
    left = np.sum([f.excluded for f in files["train"]], axis=0)
    vleft = (
        None
        if files["validation"] is None
        else np.sum([f.excluded for f in files["validation"]], axis=0)
    )
    return {
        "eps": eps,
        "excluded_rows": dict(zip(joints, map(int, left), strict=True)),
        "excluded_rows_validation": None
        if vleft is None
        else dict(zip(joints, map(int, vleft), strict=True)),
    }
