"""One schema for identification results: the JSON of ``--json`` and result.json.

:meth:`IdentificationResult.to_dict() <manip_id.identification.IdentificationResult.to_dict>`
builds the dictionary (:func:`result_to_dict`), :func:`manip_id.identification.load_result`
reads it back (through :func:`read_result_json`, the one reader of a saved result), and
:func:`~manip_id.identification.document_text.result_text` is the one text rendering of
a result (``table()``, the CLI, ``show``, reports). The keys::

    method, model, robot, n_samples, n_validation_samples, n_parameters, n_base,
    joints, joint_terms, outputs
    base_parameters     [{name, expression, value, std, std_percent, std_white, unit,
                          nominal, flags}]   (std: the honest one, see uncertainty)
    uncertainty         {method, requested, bandwidth, inflation, n_blocks, block_samples,
                         reason}: how std was made ("hac": holds for correlated residuals;
                         inflation: median std / std_white)
    relative_error      {train, train_per_joint, validation, per_joint_validation,
                         nominal_train, nominal_train_per_joint, nominal_validation,
                         nominal_per_joint_validation[, validation_per_file]
                         [, train_moving, validation_moving (with a velocity deadband)]}
    relative_error_raw  the same against the raw (unfiltered) torques, when they were read
    sigma2, noise_variance, condition_number, rank
    unidentifiable      the structural directions the base parameters regroup away
    unexcited           the base-parameter directions these data fail to excite
    convergence         online methods: how far the estimate moved over the last 10 %
    thresholds          the limits the flags and warnings used
    warnings            plain sentences
    covariance, solver, timings, base (the regrouping: independent, dependent, K, names),
    rank_analysis (what the data excite), per_file, files, standard_parameters,
    physically_consistent, ... (the keys of other parts, carried as they are)

A base parameter's flags are plain words:

- ``"non-physical"``: it is one standard parameter that must be positive (a mass, a
  diagonal inertia ``Ixx, Iyy, Izz`` about the joint frame, an armature, a viscous or
  Coulomb friction coefficient) and came out negative;
- ``"poorly identified"``: its std is above ``poorly_identified`` percent (default 10);
- ``"not excited by this data"``: it takes part in a direction the data fail to excite;
- ``"not determined by these data"``: its std is above 1000 % (or not finite), or its
  value comes from a minimum-norm solution; the text shows no number for it.

The relative errors are ``||tau - tau_hat|| / ||tau||`` (stacked samples and joints,
:func:`manip_id.metrics.relative_error`), for the identified model and for the nominal
one, ``tau_hat = Y_b theta_b_nominal`` with ``theta_b_nominal = base.to_base(nominal)``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .._io.reading import read_json
from ..errors import DataError, InputError, format_direction
from ..metrics import finite_list, finite_or_none
from ..physics.consistency import NONNEGATIVE_TERMS
from .nominal_check import result_worse_than_nominal

#: std above this [%] flags a base parameter "poorly identified".
POORLY_IDENTIFIED = 10.0
#: a condition number above this is a warning.
CONDITION_LIMIT = 100.0
#: an online estimate whose prediction moved by more than this fraction of the torque
#: norm over the last 10 % of the data has not converged.
CONVERGENCE_LIMIT = 0.01
#: standard parameters that a physical body or drive has positive.
MUST_BE_POSITIVE = ("m", "Ixx", "Iyy", "Izz", *NONNEGATIVE_TERMS)
NON_PHYSICAL, POORLY, UNEXCITED = "non-physical", "poorly identified", "not excited by this data"
#: a std above this [%], or a value that only a minimum-norm solution gives, is no number
#: a user can act on: such a parameter is "not determined by these data".
NOT_DETERMINED_PERCENT = 1000.0
NOT_DETERMINED = "not determined by these data"
#: schema version of the dictionary.
SCHEMA = 1

# keys :func:`result_to_dict` builds (everything else in a loaded document is carried)
OWN_KEYS = {
    "relative_error_raw",
    "schema",
    "method",
    "model",
    "robot",
    "n_samples",
    "n_parameters",
    "n_base",
    "joints",
    "outputs",
    "base_parameters",
    "sigma2",
    "noise_variance",
    "condition_number",
    "rank",
    "unidentifiable",
    "unexcited",
    "relative_error",
    "covariance",
    "timings",
    "solver",
    "convergence",
    "thresholds",
    "warnings",
    "base",
    "rank_analysis",
    "uncertainty",
}


def single_standard(base, i: int) -> str | None:
    """The standard parameter that base parameter ``i`` equals (nothing regrouped into it)."""
    name = base.names[int(base.independent[i])]
    if base.K.size and np.any(np.abs(base.K[i]) > 0):
        return None
    return name


def unexcited_mask(result) -> np.ndarray:
    """Per base parameter, whether it takes part in a direction these data fail to excite."""
    ra = result.rank_analysis
    r = len(result.names)
    mask = np.zeros(r, dtype=bool)
    ns = np.asarray(ra.null_space, dtype=float)
    if ns.ndim == 2 and ns.shape[0] == r and ns.shape[1]:
        mask |= (np.abs(ns) > 1e-6 * np.abs(ns).max(axis=0, keepdims=True)).any(axis=1)
    if ra.unexcited_vectors is not None and np.size(ra.unexcited_vectors):
        v = np.asarray(ra.unexcited_vectors, dtype=float)
        if v.shape[0] == r:
            mask |= (np.abs(v) > 1e-6 * np.abs(v).max(axis=0, keepdims=True)).any(axis=1)
    return mask


def parameter_flags(result, poorly_identified: float = POORLY_IDENTIFIED) -> list[list[str]]:
    """The flags of each base parameter (module docstring), a list of words per parameter."""
    out: list[list[str]] = []
    unexcited = unexcited_mask(result)
    minimum_norm = int(result.rank_analysis.rank) < len(result.names)
    for i, (x, sp) in enumerate(zip(result.estimate, result.std_percent, strict=True)):
        flags = []
        one = single_standard(result.base, i)
        if one is not None and one.rpartition(".")[2] in MUST_BE_POSITIVE and x < 0:
            flags.append(NON_PHYSICAL)
        if not (np.isfinite(sp) and sp <= poorly_identified):
            flags.append(POORLY)
        if unexcited[i]:
            flags.append(UNEXCITED)
        if not (np.isfinite(sp) and sp <= NOT_DETERMINED_PERCENT) or (
            unexcited[i] and minimum_norm
        ):
            flags.append(NOT_DETERMINED)
        out.append(flags)
    return out


#: Said of the non-physical values of a refined estimate (its own "Do:" in the advice).
REFINED_UNCONSTRAINED = "the output-error refinement is not constrained to physical values"


def result_warnings(
    result,
    flags: list[list[str]],
    condition_limit: float = CONDITION_LIMIT,
    convergence_limit: float = CONVERGENCE_LIMIT,
) -> list[str]:
    """Plain sentences: non-physical values by name, a large condition number, an online
    estimate still moving, joints predicted worse than by the nominal model (with a "Do:"
    line); then the result's own warnings (no repeats)."""
    out = []
    bad = [
        f"{n} = {x:.4g} {u}".rstrip()
        for n, x, u, fl in zip(
            result.names,
            result.estimate,
            result.units or [""] * len(result.names),
            flags,
            strict=True,
        )
        if NON_PHYSICAL in fl
    ]
    if bad:
        refined = "refinement" in (getattr(result, "context", None) or {})
        out.append(
            "non-physical values: "
            + ", ".join(bad)
            + " (each is one standard parameter that must be positive"
            + (f"; {REFINED_UNCONSTRAINED}" if refined else "")
            + ")"
        )
    undetermined = [n for n, fl in zip(result.names, flags, strict=True) if NOT_DETERMINED in fl]
    if undetermined:
        out.append(
            f"{len(undetermined)} base parameter(s) not determined by these data (std above "
            f"{NOT_DETERMINED_PERCENT:g} %, or a minimum-norm value): "
            + ", ".join(undetermined[:8])
            + (", ..." if len(undetermined) > 8 else "")
            + "; their values are not shown as numbers"
        )
    if np.isfinite(result.condition_number) and result.condition_number > condition_limit:
        out.append(
            f"the condition number {result.condition_number:.4g} is above {condition_limit:g}: "
            "the data excite some base parameters weakly; their estimates are sensitive to noise"
        )
    conv = result.convergence
    if conv is not None and conv.get("prediction_change") is not None:
        moved = float(conv["prediction_change"])
        if moved > convergence_limit:
            out.append(
                f"the {result.method} estimate has not converged: over the last "
                f"{100 * conv.get('window', 0.1):.0f} % of the data its predicted torque still "
                f"changed by {100 * moved:.3g} % of the torque (limit "
                f"{100 * convergence_limit:g} %)"
            )
    worse = result_worse_than_nominal(result)
    if worse is not None:
        out.append(worse)
    for w in result.warnings:
        if w not in out:
            out.append(w)
    return out


def structural_directions(base) -> list[str]:
    """Each regrouped (dependent) column as the direction ``theta_dep - K theta_ind`` it
    adds to the null space, in the one format of :func:`manip_id.errors.format_direction`."""
    p = len(base.names)
    out = []
    for j, d in enumerate(base.dependent):
        v = np.zeros(p)
        v[int(d)] = 1.0
        v[np.asarray(base.independent, dtype=int)] = -np.asarray(base.K)[:, j]
        out.append(format_direction(v, base.names, lead=int(d)))
    return out


def errors_to_dict(re) -> dict:
    """The ``relative_error`` section of the schema from a
    :class:`~manip_id.identification.RelativeError` (the moving-rows errors only when
    known)."""
    out = {
        "train": finite_or_none(re.train),
        "train_per_joint": finite_list(re.train_per_joint),
        "validation": finite_or_none(re.validation),
        "per_joint_validation": finite_list(re.validation_per_joint),
        "nominal_train": finite_or_none(re.nominal_train),
        "nominal_train_per_joint": finite_list(re.nominal_train_per_joint),
        "nominal_validation": finite_or_none(re.nominal_validation),
        "nominal_per_joint_validation": finite_list(re.nominal_validation_per_joint),
    }
    if re.validation_per_file is not None:
        out["validation_per_file"] = list(re.validation_per_file)
    for key in ("train_moving", "validation_moving"):
        if getattr(re, key) is not None:
            out[key] = finite_or_none(getattr(re, key))
    return out


def result_to_dict(
    result,
    *,
    poorly_identified: float | None = None,
    condition_limit: float | None = None,
    convergence_limit: float | None = None,
) -> dict:
    """The JSON-ready dictionary of an :class:`~manip_id.identification.IdentificationResult`
    (module docstring; lists and floats, inf/NaN as None)."""
    ctx = dict(result.context)
    poorly, cond, conv_lim = _limits(
        dict(ctx.pop("thresholds", None) or {}),
        poorly_identified,
        condition_limit,
        convergence_limit,
    )
    flags = parameter_flags(result, poorly)
    outputs = list(result.output_names or result.dof_names)
    ra = result.rank_analysis
    base = result.base
    doc = {
        "schema": SCHEMA,
        "method": result.method,
        "model": result.model,
        "robot": result.robot_name,
        "n_samples": int(result.n_samples),
        "n_parameters": len(base.names),
        "n_base": len(result.names),
        "joints": list(result.dof_names),
        "outputs": outputs,
        "base_parameters": _parameter_rows(result, flags),
        "sigma2": finite_or_none(result.sigma2),
        "noise_variance": dict(
            zip(outputs, map(finite_or_none, result.noise_variance), strict=True)
        ),
        "condition_number": finite_or_none(result.condition_number),
        "rank": int(ra.rank),
        "unidentifiable": structural_directions(base),
        "unexcited": list(ra.unidentifiable) + list(ra.unexcited),
        "relative_error": errors_to_dict(result.relative_error),
        "covariance": [[finite_or_none(v) for v in row] for row in np.asarray(result.covariance)],
        **_white_covariance(result),
        "uncertainty": result.uncertainty,
        "timings": {k: round(float(v), 6) for k, v in result.timings.items()},
        "solver": result.solver,
        "convergence": result.convergence,
        "thresholds": {
            "poorly_identified": poorly,
            "condition_number": cond,
            "convergence": conv_lim,
        },
        "base": {
            "names": list(base.names),
            "independent": [int(i) for i in base.independent],
            "dependent": [int(i) for i in base.dependent],
            "K": np.asarray(base.K, dtype=float).tolist(),
        },
        "rank_analysis": _rank_dict(ra),
    }
    _add_parts(doc, result, ctx)
    extra = list(ctx.get("warnings", []))
    warnings_ = result_warnings(result, flags, cond, conv_lim)
    doc["warnings"] = warnings_ + [w for w in extra if w not in warnings_]
    return doc


def _limits(saved: dict, poorly, cond, conv) -> tuple[float, float, float]:
    """The flag and warning limits: those asked for, else those saved, else the defaults."""
    out = (
        float(saved.get("poorly_identified", POORLY_IDENTIFIED) if poorly is None else poorly),
        float(saved.get("condition_number", CONDITION_LIMIT) if cond is None else cond),
        float(saved.get("convergence", CONVERGENCE_LIMIT) if conv is None else conv),
    )
    for name, value in zip(
        ("poorly_identified", "condition_limit", "convergence_limit"), out, strict=True
    ):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number, got {value}")
    return out


def _parameter_rows(result, flags) -> list[dict]:
    nominal = result.nominal if result.nominal is not None else [None] * len(result.names)
    units = result.units or [""] * len(result.names)
    std_white = result.std_white if result.std_white is not None else [None] * len(result.names)
    return [
        {
            "name": n,
            "expression": e,
            "value": finite_or_none(x),
            "std": finite_or_none(s),
            "std_percent": finite_or_none(sp),
            "std_white": finite_or_none(sw),
            "unit": u,
            "nominal": finite_or_none(x0),
            "flags": fl,
        }
        for n, e, x, s, sp, sw, u, x0, fl in zip(
            result.names,
            result.expressions,
            result.estimate,
            result.std,
            result.std_percent,
            std_white,
            units,
            nominal,
            flags,
            strict=True,
        )
    ]


def _rank_dict(ra) -> dict:
    return {
        "n_rows": int(ra.n_rows),
        "tolerance": float(ra.tolerance),
        "singular_values": finite_list(ra.singular_values),
        "singular_values_scaled": finite_list(ra.singular_values_scaled),
        "condition_number_scaled": finite_or_none(ra.condition_number_scaled),
        "null_space": np.asarray(ra.null_space, dtype=float).tolist(),
        "unidentifiable": list(ra.unidentifiable),
        "unexcited": list(ra.unexcited),
        "notes": list(ra.notes),
        "source": ra.source,
    }


def _add_parts(doc: dict, result, ctx: dict) -> None:
    """The keys of other parts: raw-torque errors, per-file results, files, standard
    parameters, and the caller's keys (source, preprocessing, quality, ...)."""
    raw = result.raw_error
    if raw is not None:
        doc["relative_error_raw"] = errors_to_dict(raw)
    elif "relative_error_raw" in ctx:
        doc["relative_error_raw"] = ctx["relative_error_raw"]
    if result.per_file is not None:
        doc["per_file"] = [f.to_dict() for f in result.per_file]
    if result.files is not None and "files" not in ctx:
        doc["files"] = [
            f.summary(list(result.dof_names))
            for f in result.files.get("train") or []
            if hasattr(f, "summary")
        ]
    if result.standard is not None:
        doc.update(result.standard.to_dict())
    for k, v in ctx.items():  # the caller's keys (source, preprocessing, quality, ...)
        if k not in OWN_KEYS:
            doc[k] = v


def read_result_json(path, what: str = "result") -> dict:
    """The JSON object of a saved result file (identification, payload, drive gains).

    Raises :class:`~manip_id.errors.DataError` for a missing or unreadable file, or one
    that holds no JSON object; ``what`` names the file in the messages.
    """
    path = Path(path)
    if not path.exists():
        raise DataError(f"no such {what} file: {path}")
    doc = read_json(path, f"{what} file")
    if not isinstance(doc, dict):
        raise DataError(f"{path}: a {what} is a JSON object, got {type(doc).__name__}")
    return doc


def _white_covariance(result) -> dict:
    """``{"covariance_white": rows}`` when the result carries the white-noise covariance."""
    cov = getattr(result, "covariance_white", None)
    if cov is None:
        return {}
    return {"covariance_white": [[finite_or_none(v) for v in row] for row in np.asarray(cov)]}


__all__ = [
    "CONDITION_LIMIT",
    "CONVERGENCE_LIMIT",
    "NOT_DETERMINED",
    "NOT_DETERMINED_PERCENT",
    "POORLY_IDENTIFIED",
    "parameter_flags",
    "read_result_json",
    "result_to_dict",
    "errors_to_dict",
    "result_warnings",
    "structural_directions",
]
