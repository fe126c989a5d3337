"""What a run knows besides its sums: the keys a result's ``context`` adds to its JSON.

The one schema is :meth:`~manip_id.identification.IdentificationResult.to_dict`; its
``context`` carries what only the run knows: where the data came from (``source``), the
preprocessing and which torques the errors compare with (``reference_torques``), the
validation samples, the joint terms, per-file records (data quality, torque scale, rows
left out by a velocity deadband), a simulation's truth, the run's own warnings. Relative
errors are ``||tau - tau_hat|| / ||tau||`` over all stacked samples and joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..datasets.stream import torque_scale_vector
from ..robot.model import Robot


def _finite(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class RunContext:
    """What a run knows besides its result.

    Attributes
    ----------
    source : dict
        Where the data came from (``data``, ``simulated``, ``split``, ``validate`` ...).
    n_validation : int
        Validation samples (0 without validation).
    settings : object or None
        The preprocessing settings of the training data (a dataclass), None for raw data.
    theta_true : numpy.ndarray or None
        A simulation's true standard parameters, shape (p,).
    """

    source: dict
    n_validation: int = 0
    settings: Any = None
    theta_true: np.ndarray | None = None


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
    for valid, train in (
        source.get("validation_in_training", []) if isinstance(source, dict) else ()
    ):
        out.append(
            f"the validation file {valid} is also --data {train}: its validation error is "
            "measured on the training data, not on new data"
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


def run_keys(robot: Robot, result, run: RunContext) -> dict:
    """The context keys of a run: validation samples, joint terms, source, preprocessing,
    reference torques, the run's warnings (and a simulation's truth)."""
    settings = run.settings
    keys: dict = {
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
        keys.update(_truth(result, run.theta_true))
    return keys


def with_context(result, keys: dict):
    """``result`` with ``keys`` added to its ``context`` (the JSON's extra keys)."""
    return replace(result, context={**result.context, **keys})


def raw_reference(robot: Robot, result, parts, chunk: int) -> dict:
    """When the reference torques were filtered, the errors against the raw ones too.

    parts: ``(name, processed, t_raw, tau_raw)`` with name "train" or "validation",
    ``processed`` holding t, q, dq, ddq, tau (the filtered samples) and the raw torques
    of the same record [N m] (scaled as the processed ones) at times ``t_raw`` [s]; the raw
    torques are interpolated linearly at the processed times (the processed samples
    are the raw ones, trimmed, or resampled on a uniform grid).
    Returns the keys ``relative_error_raw`` {train, validation, nominal_train,
    nominal_validation} and ``reference_torques`` stating both references, or {} when the
    torques were not filtered, the identification measured them itself (its raw pass over
    the files) or the records are not on one clock.
    """
    pre = result.context.get("preprocess") or {}
    if not pre.get("filter_torque") or result.raw_error is not None:
        return {}
    nominal = replace(result, estimate=result.nominal)
    out: dict = {}
    for name, proc, t_raw, tau_raw in parts:
        t_raw = np.asarray(t_raw, dtype=float)
        if proc is None or proc.t[0] < t_raw[0] - 1e-9 or proc.t[-1] > t_raw[-1] + 1e-9:
            return {}  # the processed times are not on the raw record's clock
        raw = np.column_stack(
            [np.interp(proc.t, t_raw, np.asarray(tau_raw)[:, j]) for j in range(robot.nv)]
        )
        for key, model in (("", result), ("nominal_", nominal)):
            temp = getattr(proc, "temp", None)  # the temperature law's
            pred = model.predict(robot, proc.q, proc.dq, proc.ddq, chunk=chunk, temp=temp)
            out[f"{key}{name}"] = _finite(np.linalg.norm(raw - pred) / np.linalg.norm(raw))
    if not out:
        return {}
    pct = {k: "n/a" if v is None else f"{100 * v:.3g} %" for k, v in out.items()}
    text = (
        f"; against the raw torques at the same samples: identified model train "
        f"{pct.get('train', 'n/a')}"
        + (f", validation {pct['validation']}" if "validation" in pct else "")
        + f" (nominal model train {pct.get('nominal_train', 'n/a')}"
        + (f", validation {pct['nominal_validation']}" if "nominal_validation" in pct else "")
        + ")"
    )
    return {
        "relative_error_raw": out,
        "reference_torques": str(result.context.get("reference_torques", "")) + text,
    }


def file_keys(robot: Robot, specs, vspecs, qualities: dict, files, options) -> dict:
    """The per-file records of log files: data quality, torque scale, files, deadband.

    specs, vspecs: the training and validation file specs; qualities: spec -> its
    data-quality summary; files: ``{"train": [...], "validation": [...] or None}`` of the
    accumulated files, or None (the online laws); options: the preprocessing options.
    """
    joints = list(robot.dof_names)
    keys: dict = {"data_quality": [qualities[s].to_dict() for s in specs]}
    if vspecs is not None:
        keys["validation_data_quality"] = [qualities[s].to_dict() for s in vspecs]
    scale = torque_scale_vector(options.torque_scale, robot.nv)  # one gain, or one per joint
    keys["torque_scale"] = None if scale is None else scale.tolist()
    if files is not None:
        keys["files"] = [f.summary(joints) for f in files["train"]]
        if files["validation"] is not None:
            keys["validation_files"] = [f.summary(joints) for f in files["validation"]]
        if options.velocity_deadband is not None:
            keys["velocity_deadband"] = _deadband(joints, files, options.velocity_deadband)
    keys["data_warnings"] = [
        w for s in list(specs) + list(vspecs or []) for w in qualities[s].warnings
    ]
    return keys


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


__all__ = [
    "RunContext",
    "file_keys",
    "raw_reference",
    "reference_torques",
    "run_keys",
    "run_warnings",
    "with_context",
]
