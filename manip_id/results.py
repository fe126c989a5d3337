"""One schema for identification results: the JSON of ``--json``, result.json, ``show``.

:meth:`IdentificationResult.to_dict() <manip_id.identification.IdentificationResult.to_dict>`
builds the dictionary (:func:`result_to_dict`), :func:`load_result` reads it back into an
:class:`~manip_id.identification.IdentificationResult`, and :func:`result_text` prints a
saved one (``manip-id show RESULT.json``). The keys::

    method, model, robot, n_samples, n_validation_samples, n_parameters, n_base,
    joints, joint_terms, outputs
    base_parameters     [{name, expression, value, std, std_percent, unit, nominal, flags}]
    relative_error      {train, train_per_joint, validation, per_joint_validation,
                         nominal_train, nominal_train_per_joint, nominal_validation,
                         nominal_per_joint_validation[, validation_per_file]}
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
- ``"not excited by this data"``: it takes part in a direction the data fail to excite.

The relative errors are ``||tau - tau_hat|| / ||tau||`` (stacked samples and joints), for
the identified model and for the nominal one, ``tau_hat = Y_b theta_b_nominal`` with
``theta_b_nominal = base.to_base(robot.nominal_parameters)``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import DataError, InputError

if TYPE_CHECKING:
    from .identification import IdentificationResult

#: std above this [%] flags a base parameter "poorly identified".
POORLY_IDENTIFIED = 10.0
#: a condition number above this is a warning.
CONDITION_LIMIT = 100.0
#: an online estimate whose prediction moved by more than this fraction of the torque
#: norm over the last 10 % of the data has not converged.
CONVERGENCE_LIMIT = 0.01
#: standard parameters that a physical body or drive has positive.
MUST_BE_POSITIVE = ("m", "Ixx", "Iyy", "Izz", "Ia", "fv", "fc")
NON_PHYSICAL, POORLY, UNEXCITED = "non-physical", "poorly identified", "not excited by this data"
#: schema version of the dictionary.
SCHEMA = 1

# keys :func:`result_to_dict` builds (everything else in a loaded document is carried)
_OWN = {
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
}


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _list(x):
    return None if x is None else [_f(v) for v in np.atleast_1d(np.asarray(x, dtype=float))]


def _array(x, dtype=float):
    return np.asarray([np.nan if v is None else v for v in x], dtype=dtype)


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
    for i, (x, sp) in enumerate(zip(result.estimate, result.std_percent, strict=True)):
        flags = []
        one = single_standard(result.base, i)
        if one is not None and one.rpartition(".")[2] in MUST_BE_POSITIVE and x < 0:
            flags.append(NON_PHYSICAL)
        if not (np.isfinite(sp) and sp <= poorly_identified):
            flags.append(POORLY)
        if unexcited[i]:
            flags.append(UNEXCITED)
        out.append(flags)
    return out


def result_warnings(
    result,
    flags: list[list[str]],
    condition_limit: float = CONDITION_LIMIT,
    convergence_limit: float = CONVERGENCE_LIMIT,
) -> list[str]:
    """Plain sentences: non-physical values by name, a large condition number, an online
    estimate still moving; then the result's own warnings (no repeats)."""
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
        out.append(
            "non-physical values: "
            + ", ".join(bad)
            + " (each is one standard parameter that must be positive)"
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
    for w in result.warnings:
        if w not in out:
            out.append(w)
    return out


def structural_directions(base) -> list[str]:
    """Each regrouped (dependent) column as the direction ``theta_dep - K theta_ind`` it
    adds to the null space, in the one format of :func:`manip_id.errors.format_direction`."""
    from .errors import format_direction

    p = len(base.names)
    out = []
    for j, d in enumerate(base.dependent):
        v = np.zeros(p)
        v[int(d)] = 1.0
        v[np.asarray(base.independent, dtype=int)] = -np.asarray(base.K)[:, j]
        out.append(format_direction(v, base.names, lead=int(d)))
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
    th = dict(ctx.pop("thresholds", None) or {})
    poorly = float(
        th.get("poorly_identified", POORLY_IDENTIFIED)
        if poorly_identified is None
        else poorly_identified
    )
    cond = float(
        th.get("condition_number", CONDITION_LIMIT) if condition_limit is None else condition_limit
    )
    conv_lim = float(
        th.get("convergence", CONVERGENCE_LIMIT) if convergence_limit is None else convergence_limit
    )
    for name, value in (
        ("poorly_identified", poorly),
        ("condition_limit", cond),
        ("convergence_limit", conv_lim),
    ):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number, got {value}")
    flags = parameter_flags(result, poorly)
    re = result.relative_error
    outputs = list(result.output_names or result.dof_names)
    nominal = result.nominal if result.nominal is not None else [None] * len(result.names)
    units = result.units or [""] * len(result.names)
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
        "base_parameters": [
            {
                "name": n,
                "expression": e,
                "value": _f(x),
                "std": _f(s),
                "std_percent": _f(sp),
                "unit": u,
                "nominal": _f(x0),
                "flags": fl,
            }
            for n, e, x, s, sp, u, x0, fl in zip(
                result.names,
                result.expressions,
                result.estimate,
                result.std,
                result.std_percent,
                units,
                nominal,
                flags,
                strict=True,
            )
        ],
        "sigma2": _f(result.sigma2),
        "noise_variance": dict(zip(outputs, map(_f, result.noise_variance), strict=True)),
        "condition_number": _f(result.condition_number),
        "rank": int(ra.rank),
        "unidentifiable": structural_directions(base),
        "unexcited": list(ra.unidentifiable) + list(ra.unexcited),
        "relative_error": {
            "train": _f(re.train),
            "train_per_joint": _list(re.train_per_joint),
            "validation": _f(re.validation),
            "per_joint_validation": _list(re.validation_per_joint),
            "nominal_train": _f(re.nominal_train),
            "nominal_train_per_joint": _list(re.nominal_train_per_joint),
            "nominal_validation": _f(re.nominal_validation),
            "nominal_per_joint_validation": _list(re.nominal_validation_per_joint),
            **(
                {}
                if re.validation_per_file is None
                else {"validation_per_file": list(re.validation_per_file)}
            ),
        },
        "covariance": [[_f(v) for v in row] for row in np.asarray(result.covariance)],
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
        "rank_analysis": {
            "n_rows": int(ra.n_rows),
            "tolerance": float(ra.tolerance),
            "singular_values": _list(ra.singular_values),
            "singular_values_scaled": _list(ra.singular_values_scaled),
            "condition_number_scaled": _f(ra.condition_number_scaled),
            "null_space": np.asarray(ra.null_space, dtype=float).tolist(),
            "unidentifiable": list(ra.unidentifiable),
            "unexcited": list(ra.unexcited),
            "notes": list(ra.notes),
            "source": ra.source,
        },
    }
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
        if k not in _OWN:
            doc[k] = v
    extra = list(ctx.get("warnings", []))
    warnings_ = result_warnings(result, flags, cond, conv_lim)
    doc["warnings"] = warnings_ + [w for w in extra if w not in warnings_]
    return doc


def result_from_dict(doc: dict) -> IdentificationResult:
    """An :class:`~manip_id.identification.IdentificationResult` from :func:`result_to_dict`'s
    dictionary. What the schema does not model (standard parameters, files, per-file
    results, the caller's keys) is kept in ``context`` and written back by ``to_dict``."""
    from .identifiability import BaseParameters, RankAnalysis
    from .identification import IdentificationResult, RelativeError

    if not isinstance(doc, dict):
        raise DataError(f"an identification result is a JSON object, got {type(doc).__name__}")
    missing = [
        k
        for k in (
            "method",
            "robot",
            "base_parameters",
            "relative_error",
            "base",
            "rank_analysis",
            "covariance",
        )
        if k not in doc
    ]
    if missing:
        raise DataError(
            f"not an identification result of this schema: missing {missing} (write it with "
            "manip-id identify --json or IdentificationResult.to_dict())"
        )
    try:
        rows = doc["base_parameters"]
        b = doc["base"]
        names = [str(r["name"]) for r in rows]
        base = BaseParameters(
            independent=np.asarray(b["independent"], dtype=np.intp),
            dependent=np.asarray(b["dependent"], dtype=np.intp),
            K=np.asarray(b["K"], dtype=float).reshape(len(rows), len(b["dependent"])),
            names=list(b["names"]),
            base_names=names,
            expressions=[str(r["expression"]) for r in rows],
        )
        estimate = _array([r["value"] for r in rows])
        std = _array([r["std"] for r in rows])
        std_pct = _array([np.inf if r["std_percent"] is None else r["std_percent"] for r in rows])
        cov = _array([v for row in doc["covariance"] for v in row]).reshape(len(rows), len(rows))
        rd = doc["rank_analysis"]
        joints = list(doc.get("joints", []))
        outputs = list(doc.get("outputs", joints))
        ns = np.asarray(rd["null_space"], dtype=float).reshape(len(rows), -1)
        ra = RankAnalysis(
            names=names,
            n_parameters=len(rows),
            n_rows=int(rd["n_rows"]),
            rank=int(doc["rank"]),
            tolerance=float(rd["tolerance"]),
            singular_values=_array(rd["singular_values"]),
            singular_values_scaled=_array(rd["singular_values_scaled"]),
            condition_number=np.inf
            if doc["condition_number"] is None
            else float(doc["condition_number"]),
            condition_number_scaled=np.inf
            if rd["condition_number_scaled"] is None
            else float(rd["condition_number_scaled"]),
            base=base,
            null_space=ns,
            unidentifiable=list(rd["unidentifiable"]),
            unexcited=list(rd["unexcited"]),
            notes=list(rd["notes"]),
            source=str(rd["source"]),
        )
        e = doc["relative_error"]

        def arr(key):
            return None if e.get(key) is None else _array(e[key])

        re = RelativeError(
            train=np.nan if e["train"] is None else float(e["train"]),
            train_per_joint=arr("train_per_joint"),
            validation=e.get("validation"),
            validation_per_joint=arr("per_joint_validation"),
            validation_per_file=e.get("validation_per_file"),
            nominal_train=e.get("nominal_train"),
            nominal_train_per_joint=arr("nominal_train_per_joint"),
            nominal_validation=e.get("nominal_validation"),
            nominal_validation_per_joint=arr("nominal_per_joint_validation"),
        )
        nominal = [r.get("nominal") for r in rows]
        own_warnings = _recomputed_warnings(doc)
        context = {k: v for k, v in doc.items() if k not in _OWN}
        context["thresholds"] = doc.get("thresholds") or {}
        context["warnings"] = [w for w in doc.get("warnings", []) if w not in own_warnings]
        return IdentificationResult(
            method=str(doc["method"]),
            robot_name=str(doc["robot"]),
            names=names,
            expressions=list(base.expressions),
            estimate=estimate,
            std=std,
            std_percent=std_pct,
            covariance=cov,
            sigma2=np.nan if doc.get("sigma2") is None else float(doc["sigma2"]),
            noise_variance=_array(list(doc.get("noise_variance", {}).values())),
            condition_number=ra.condition_number,
            rank_analysis=ra,
            relative_error=re,
            n_samples=int(doc["n_samples"]),
            timings={k: float(v) for k, v in doc.get("timings", {}).items()},
            solver=str(doc.get("solver", "")),
            base=base,
            dof_names=joints,
            model=str(doc.get("model", "dynamic")),
            output_names=outputs if outputs != joints else [],
            units=[str(r.get("unit", "")) for r in rows],
            nominal=None if any(x is None for x in nominal) else np.asarray(nominal, dtype=float),
            convergence=doc.get("convergence"),
            context=context,
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DataError(f"a malformed identification result: {type(exc).__name__}: {exc}") from exc


def _recomputed_warnings(doc: dict) -> set[str]:
    """The warnings :func:`result_to_dict` derives itself (recomputed on writing again)."""
    starts = ("non-physical values: ", "the condition number ")
    return {
        w
        for w in doc.get("warnings", [])
        if w.startswith(starts) or (w.startswith("the ") and "has not converged" in w)
    }


def load_result(path) -> IdentificationResult:
    """Read a saved identification result (``manip-id identify --json``, a report's
    result.json) back into an :class:`~manip_id.identification.IdentificationResult`.

    Raises :class:`~manip_id.errors.DataError` for a missing, unreadable or foreign file.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise DataError(f"no such result file: {path}") from exc
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot read {path} as JSON: {exc}") from exc
    try:
        return result_from_dict(doc)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from exc


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * float(x):.3f} %"


def result_text(doc: dict, max_rows: int | None = None) -> str:
    """A saved result as text: what was identified, errors against the nominal model in
    percent, the parameter table with units, nominal values and flags, the warnings."""
    e = doc["relative_error"]
    lines = [
        f"{str(doc['method']).upper()} identification of {doc['robot']}: {doc['n_base']} base "
        f"parameters of {doc.get('n_parameters', '?')}, {doc['n_samples']} training samples"
        + ("" if doc.get("model", "dynamic") == "dynamic" else f" ({doc['model']} model)"),
        f"solver: {doc.get('solver', '')}",
        "condition number "
        + ("n/a" if doc.get("condition_number") is None else f"{doc['condition_number']:.4g}"),
        f"relative torque error: train {_pct(e.get('train'))} (nominal model "
        f"{_pct(e.get('nominal_train'))}), validation {_pct(e.get('validation'))} (nominal "
        f"model {_pct(e.get('nominal_validation'))})",
    ]
    ref = doc.get("reference_torques")
    if ref:
        lines.append(f"reference torques: {ref}")
    rows = list(doc["base_parameters"])
    w = max([len("parameter")] + [len(r["name"]) for r in rows])
    lines.append(
        f"{'parameter':<{w}}  {'value':>12}  {'nominal':>12}  {'std %':>8}  {'unit':<8}  flags"
    )
    shown = rows if max_rows is None else rows[:max_rows]
    for r in shown:
        val = "n/a" if r["value"] is None else f"{r['value']:12.6g}"
        nom = "n/a" if r.get("nominal") is None else f"{r['nominal']:12.6g}"
        sp = "inf" if r["std_percent"] is None else f"{r['std_percent']:8.3g}"
        lines.append(
            f"{r['name']:<{w}}  {val:>12}  {nom:>12}  {sp:>8}  {r.get('unit', ''):<8}  "
            + ", ".join(r.get("flags", []))
        )
    if len(shown) < len(rows):
        lines.append(f"... {len(rows) - len(shown)} more")
    lines += [f"warning: {x}" for x in doc.get("warnings", [])]
    return "\n".join(lines)


__all__ = [
    "CONDITION_LIMIT",
    "CONVERGENCE_LIMIT",
    "POORLY_IDENTIFIED",
    "load_result",
    "parameter_flags",
    "result_from_dict",
    "result_text",
    "result_to_dict",
    "result_warnings",
    "structural_directions",
]
