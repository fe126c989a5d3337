"""The short answer of ``manip-id identify``: what the run found, first, in at most ~25 lines.

The order a newcomer reads: how much better the identified model predicts than the
nominal (URDF) one, the verdict, the errors per joint as a small table, what the
estimate is (method, base parameters, condition number, physical or not), the flagged
base parameters by name, the audit in one line, and where the full table is. The
full rendering (:func:`manip_id.identification.result_text`: every base parameter
with its std, nominal value, unit and flags) is printed with ``--verbose`` and is
always in the JSON and the report.

The gain is the ratio of relative torque errors ``||tau - tau_hat_nominal|| /
||tau - tau_hat||`` on validation data (else training data): both errors divide
by the same ``||tau||``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from ..identification import NOT_DETERMINED, result_text, verdict_text
from ..identification.document_text import uncertainty_text
from ..viz.report_answers import ADVICE

#: Error ratios within [1 / SAME, SAME] say "about as good as the nominal model".
SAME = 1.2
#: Flagged base parameters named in the short answer; the rest are counted.
NAMED_FLAGS = 6
#: The flags the short answer counts, in the order it names them.
FLAG_ORDER = ("non-physical", NOT_DETERMINED, "not excited by this data", "poorly identified")


def gain_text(doc: Mapping) -> str:
    """The first line: how much better the identified model predicts than the nominal one.

    ``N x better than the nominal model`` with both errors, on validation data when
    there are some (else "on the training data", said as such), or why no ratio is given.
    """
    e = doc.get("relative_error") or {}
    key = "validation" if e.get("validation") is not None else "train"
    where = "on the validation data" if key == "validation" else "on the training data"
    mine, nominal = e.get(key), e.get(f"nominal_{key}")
    if mine is None:
        return f"identified model: no torque error {where} (not computed)"
    if nominal is None:
        return f"identified model: torque error {_pct(mine)} {where} (no nominal model to compare)"
    ratio = nominal / mine if mine > 0 else math.inf
    if ratio >= SAME:
        head = f"identified model: {_ratio(ratio)} x better than the nominal model"
    elif ratio > 1.0 / SAME:
        head = "identified model: about as good as the nominal model"
    else:
        head = f"identified model: {_ratio(1.0 / ratio)} x WORSE than the nominal model"
    return f"{head} {where} (torque error {_pct(mine)}, nominal model {_pct(nominal)})"


def joint_table(doc: Mapping) -> list[str]:
    """The relative torque errors per joint [%]: train, validation and the nominal model's."""
    e = doc.get("relative_error") or {}
    joints = list(doc.get("outputs") or doc.get("joints") or [])
    valid = e.get("per_joint_validation") is not None
    nominal = "nominal_per_joint_validation" if valid else "nominal_train_per_joint"
    wanted = [("train", "train_per_joint")]
    wanted += [("validation", "per_joint_validation")] if valid else []
    wanted += [("nominal", nominal)]
    columns: list[tuple[str, list]] = [
        (name, list(e[key]))
        for name, key in wanted
        if e.get(key) is not None and len(e[key]) == len(joints)
    ]
    if not joints or not columns:
        return []
    head = "error per joint [%]"
    w = max(len(head), *(len(j) for j in joints))
    lines = [f"{head:<{w}}  " + "  ".join(f"{n:>10}" for n, _ in columns)]
    for k, joint in enumerate(joints):
        lines.append(f"{joint:<{w}}  " + "  ".join(f"{_num(v[k]):>10}" for _, v in columns))
    return lines


def estimate_line(doc: Mapping) -> str:
    """What the estimate is: method, base parameters, samples, condition number, physical."""
    cond = doc.get("condition_number")
    model = doc.get("model", "dynamic")
    text = (
        f"{str(doc.get('method', '')).upper()} of {doc.get('robot')}"
        + ("" if model == "dynamic" else f" ({model} model)")
        + f": {doc.get('n_base')} base "
        f"parameters of {doc.get('n_parameters', '?')}, {doc.get('n_samples')} training samples"
    )
    if doc.get("n_validation_samples"):
        text += f", {doc['n_validation_samples']} validation samples"
    text += ", condition number " + ("n/a" if cond is None else f"{cond:.3g}")
    consistent = doc.get("physically_consistent")
    if consistent is not None:
        text += "; physically consistent" if consistent else "; NOT physically consistent"
    return text


def flagged_lines(rows: Sequence[Mapping]) -> list[str]:
    """The flagged base parameters: one line per flag, the first names and a count."""
    lines = []
    for flag in FLAG_ORDER:
        names = [str(r["name"]) for r in rows if flag in (r.get("flags") or [])]
        if not names:
            continue
        shown = ", ".join(names[:NAMED_FLAGS]) + (", ..." if len(names) > NAMED_FLAGS else "")
        lines.append(f"{flag}: {len(names)} of {len(rows)} ({shown})")
    if any(str(r["name"]).endswith("R") for r in rows if r.get("flags")):
        lines.append(
            "(a name ending in R is a base parameter that regroups others: "
            "'manip-id rank ROBOT' writes it out)"
        )
    return lines or [f"flagged: none of the {len(rows)} base parameters"]


def audit_line(doc: Mapping) -> str | None:
    """The pre-fit audit in one line (its findings were printed before the fit)."""
    audit = doc.get("audit")
    if not audit:
        return None
    files = audit.get("files") or []
    found = sum(len(f.get("findings") or []) for f in files)
    if not found:
        return f"pre-fit audit: nothing found in {len(files)} file(s)"
    return f"pre-fit audit: {found} finding(s) in {len(files)} file(s) (printed above, in the JSON)"


def answer_text(doc: Mapping, *, verbose: bool = False) -> str:
    """The run's answer on stdout (module docstring); ``verbose``: then the full rendering."""
    lines = [gain_text(doc), verdict_text(dict(doc))]
    if verbose:
        lines.append(result_text({**doc, "warnings": []}))
    else:
        lines += joint_table(doc)
        lines.append(estimate_line(doc))
        if doc.get("uncertainty"):
            lines.append("standard deviations: " + uncertainty_text(doc["uncertainty"]))
        lines += flagged_lines(list(doc.get("base_parameters") or []))
    if doc.get("parameter_error") is not None:
        worst = doc.get("parameter_error_in_std")
        lines.append(
            f"base parameter error vs truth: {100 * doc['parameter_error']:.3f} %"
            + ("" if worst is None else f" (max {worst:.2f} std)")
        )
    audit = audit_line(doc)
    if audit is not None:
        lines.append(audit)
    if not verbose:
        lines.append("every parameter with its std: --verbose (always in --json and --report)")
    return "\n".join(lines)


def advice_for(warning: str) -> str | None:
    """What addresses ``warning``: the report's advice (its "Do:"), or None."""
    return next((a for key, a in ADVICE if key in warning), None)


def _pct(x: float) -> str:
    return f"{100 * float(x):#.3g} %"


def _num(x) -> str:
    return "n/a" if x is None else f"{100 * float(x):.2f}"


def _ratio(r: float) -> str:
    if not math.isfinite(r):
        return "infinitely"
    return f"{r:.3g}" if r < 100 else f"{r:.0f}"


__all__ = ["advice_for", "answer_text", "audit_line", "flagged_lines", "gain_text", "joint_table"]
