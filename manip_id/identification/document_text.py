"""The text of a result document: the one rendering of a saved or fresh result.

:func:`result_text` is what ``table()``, the CLI, ``show`` and reports print;
:func:`summary_rows` its headline figures, :func:`verdict_text` its closing sentence,
:func:`method_label` the method's name ("WLS + consistent (SDP)"), :func:`mass_sources`
where each body's mass comes from. The document is the dictionary of
:mod:`~manip_id.identification.document`.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..identifiability.qr import REGROUPED_NOTE, has_regrouped
from .document import (
    NOT_DETERMINED,
)
from .nominal_check import WORSE_PREFIX


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * float(x):.3f} %"


def _per_joint(names, values) -> str:
    return ", ".join(f"{n} {_pct(v)}" for n, v in zip(names, values, strict=True))


def method_label(doc: dict) -> str:
    """The method of the model a document shows: "WLS", "OLS + consistent (SDP)", ..."""
    label = str(doc.get("method", "")).upper()
    solver = doc.get("consistent_solver") or {}
    if doc.get("standard_parameters_kind") == "consistent" and solver:
        label += f" + consistent ({str(solver.get('solver', '')).upper()})"
    return label


def summary_rows(doc: dict) -> dict[str, str]:
    """The headline figures of a saved result, label -> text (errors in percent, the nominal
    model beside the identified one): the first lines of :func:`result_text`, and the
    summary table of a report."""
    e = doc["relative_error"]
    model = doc.get("model", "dynamic")
    rows = {
        "identification": f"{method_label(doc)} of {doc['robot']}"
        + ("" if model == "dynamic" else f" ({model} model)"),
        "base parameters": f"{doc['n_base']} of {doc.get('n_parameters', '?')}",
        "training samples": str(doc["n_samples"]),
        "solver": str(doc.get("solver", "")),
        "condition number": "n/a"
        if doc.get("condition_number") is None
        else f"{doc['condition_number']:.4g}",
        "relative torque error, train": f"{_pct(e.get('train'))} (nominal model "
        f"{_pct(e.get('nominal_train'))})",
        "relative torque error, validation": f"{_pct(e.get('validation'))} (nominal model "
        f"{_pct(e.get('nominal_validation'))})",
    }
    if doc.get("n_validation_samples") is not None:
        rows["validation samples"] = str(doc["n_validation_samples"])
    for key in ("train_moving", "validation_moving"):
        if e.get(key) is not None:
            rows[f"relative torque error, {key.replace('_', ' ')} rows"] = _pct(e[key])
    raw = doc.get("relative_error_raw")
    if raw:
        rows["relative error against the raw torques"] = (
            f"train {_pct(raw.get('train'))}, validation {_pct(raw.get('validation'))}"
        )
    if doc.get("reference_torques"):
        rows["reference torques"] = str(doc["reference_torques"])
    if doc.get("uncertainty"):
        rows["standard deviations"] = uncertainty_text(doc["uncertainty"])
    return rows


def uncertainty_text(u: dict) -> str:
    """How the standard deviations were made, in words (the ``uncertainty`` section)."""
    if u.get("method") == "hac":
        bw = u.get("bandwidth")
        text = (
            f"autocorrelation-consistent (hac, {u.get('n_blocks')} blocks of "
            f"{u.get('block_samples') or 0:.0f} samples"
            + ("" if bw is None else f", bandwidth {bw:.3g} blocks")
            + ")"
        )
        if u.get("inflation") is not None:
            text += f", {u['inflation']:.3g} x the white-noise ones"
        return text
    text = "white noise, sigma^2 (Y^T Y)^-1"
    return text + (f" ({u['reason']})" if u.get("reason") else "")


def _parameter_lines(rows: list[dict], max_rows: int | None) -> list[str]:
    w = max([len("parameter")] + [len(r["name"]) for r in rows])
    lines = [
        f"{'parameter':<{w}}  {'value':>12}  {'std':>10}  {'std %':>8}  {'nominal':>12}  "
        f"{'unit':<8}  flags"
    ]
    shown = rows if max_rows is None else rows[:max_rows]
    for r in shown:
        if NOT_DETERMINED in r.get("flags", []) or r["value"] is None:
            val, std, sp = f"{'not determined':>12}", f"{'-':>10}", f"{'-':>8}"
        else:
            val = f"{r['value']:12.6g}"
            std = "n/a" if r.get("std") is None else f"{r['std']:10.4g}"
            sp = "inf" if r["std_percent"] is None else f"{r['std_percent']:8.3g}"
        nom = "n/a" if r.get("nominal") is None else f"{r['nominal']:12.6g}"
        lines.append(
            f"{r['name']:<{w}}  {val:>12}  {std:>10}  {sp:>8}  {nom:>12}  "
            f"{r.get('unit', ''):<8}  " + ", ".join(r.get("flags", []))
        )
    more = [f"... {len(rows) - len(shown)} more"] if len(shown) < len(rows) else []
    note = [f"({REGROUPED_NOTE})"] if has_regrouped(r["name"] for r in shown) else []
    return lines + more + note


def _standard_lines(doc: dict) -> list[str]:
    if doc.get("physically_consistent") is None:
        return []
    kind = doc.get("standard_parameters_kind", "standard parameters")
    solver = doc.get("consistent_solver") or {}
    what = (
        f"consistent estimate ({solver.get('solver')}, {solver.get('status')}, prior "
        f"{solver.get('prior')}, weight {solver.get('prior_weight')})"
        if solver
        else f"{kind} standard parameters of the least-squares fit"
    )
    lines = [f"{what}: physically consistent {'yes' if doc['physically_consistent'] else 'NO'}"]
    bodies = (doc.get("consistency") or {}).get("bodies") or []
    if bodies:
        lines.append(
            "min eigenvalue of each pseudo-inertia J: "
            + ", ".join(f"{b['name']} {b['min_eigenvalue']:.3g}" for b in bodies)
        )
    plaus = doc.get("plausibility")
    if plaus:  # the consistent estimate's masses against the nominal ones
        std, source = _mass_std(doc), mass_sources(doc)
        lines.append(
            f"link masses [kg]{' +- std' if std else ''} (x nominal; source): "
            + ", ".join(
                f"{b['name']} {b['mass']:.3g}"
                + _mass_note(std.get(b["name"]), source.get(b["name"]))
                + ("" if b.get("mass_ratio") is None else f" ({b['mass_ratio']:.2g}x)")
                for b in plaus["bodies"]
            )
            + f"; total {plaus['total_mass']:.3g} (nominal {plaus['nominal_total_mass']:.3g})"
        )
    active = doc.get("constraints_active") or []
    if active:
        lines.append("constraints active (values held there, std 'at bound'): " + ", ".join(active))
    return lines


def _mass_note(std: float | None, source: str | None) -> str:
    """`` +- std`` of a mass from the data; `` from the prior`` / `` at bound`` otherwise."""
    if source == "prior":
        return " from the prior (not in the dynamics, no data std)"
    if source == "bound":
        return " at bound"
    if source == "not determined":
        return " not determined"
    return "" if std is None else f" +- {std:.2g}"


def _mass_std(doc: dict) -> dict[str, float]:
    """Link name -> the std of its mass [kg] among the standard parameters (those with one)."""
    rows = doc.get("standard_parameters") or []
    masses = [r for r in rows if r["name"].endswith(".m") and r.get("std") is not None]
    return {r["name"][:-2]: float(r["std"]) for r in masses}


def mass_sources(doc: Mapping) -> dict[str, str]:
    """Link name -> where its mass comes from ("data", "prior", "bound", "not determined";
    empty for documents without sources)."""
    rows = doc.get("standard_parameters") or []
    return {
        r["name"][:-2]: str(r["source"]) for r in rows if r["name"].endswith(".m") and "source" in r
    }


def result_text(doc: dict, max_rows: int | None = None) -> str:
    """A result (its :func:`result_to_dict` dictionary) as text: the headline figures
    (:func:`summary_rows`), the errors per joint, the parameter table with std, nominal
    values, units and flags ("not determined" instead of a number no one can use), the
    standard parameters' check and the warnings. The one rendering of a result."""
    lines = [f"{k}: {v}" for k, v in summary_rows(doc).items()]
    e = doc["relative_error"]
    outputs = doc.get("outputs") or doc.get("joints") or []
    if e.get("train_per_joint") is not None and outputs:
        lines.append("train error per joint: " + _per_joint(outputs, e["train_per_joint"]))
    if e.get("per_joint_validation") is not None:
        lines.append(
            "validation error per joint: " + _per_joint(doc["joints"], e["per_joint_validation"])
        )
    lines += _parameter_lines(list(doc["base_parameters"]), max_rows)
    lines += _standard_lines(doc)
    lines += [f"warning: {x}" for x in doc.get("warnings", [])]
    return "\n".join(lines)


def verdict_text(doc: dict) -> str:
    """The one-line verdict of a result document: the relative torque error of the
    identified and the nominal model on validation (else training) data, whether the
    standard parameters are physical, and how many warnings were given."""
    e = doc["relative_error"]
    key = "validation" if e.get("validation") is not None else "train"
    part, mine, nominal = key.replace("train", "training"), e[key], e.get(f"nominal_{key}")
    raw = doc.get("relative_error_raw") or {}
    filtered = "filtered " if raw.get(key) is not None else ""
    text = (
        f"verdict: the identified model predicts the {filtered}{part} torques to {100 * mine:.3f} %"
    )
    if nominal is not None:
        text += f" (nominal model {100 * nominal:.3f} %)"
    if filtered:  # the raw figure too: it is the one a paper reports
        text += f", the raw ones to {100 * raw[key]:.3f} %"
        if raw.get(f"nominal_{key}") is not None:
            text += f" (nominal model {100 * raw[f'nominal_{key}']:.3f} %)"
    consistent = doc.get("physically_consistent")
    if consistent is not None:
        text += ", physically consistent" if consistent else ", NOT physically consistent"
    if doc.get("standard_parameters_kind") == "consistent":
        held = [n for n, s in mass_sources(doc).items() if s == "bound"]
        if held and all(s in ("bound", "prior") for s in mass_sources(doc).values()):
            text += ", masses set by the bounds, not the data"
        elif held:
            text += f", the masses of {', '.join(held)} set by the bounds, not the data"
    if any(str(w).startswith(WORSE_PREFIX) for w in doc.get("warnings") or []):
        text += ", WORSE than the nominal model on some joints (warning above)"
    n = len(doc.get("warnings") or [])
    return text + (
        f", {n} warning(s) on the result (as warnings)" if n else ", no warnings on the result"
    )


__all__ = [
    "mass_sources",
    "method_label",
    "result_text",
    "summary_rows",
    "uncertainty_text",
    "verdict_text",
]
