"""The questions an identification report answers first, from the run's document.

1. *How good is the model?* The relative torque errors ``||tau - tau_hat|| / ||tau||`` of
   the identified and the nominal (URDF) model, on validation (else training) data, per
   joint, against the reference torques and, when they were filtered, the raw ones.
2. *Can I trust the numbers?* The condition number, the uncertainty (white or honest,
   with its inflation), and the base parameters flagged, by flag.
3. *Is it physical?* With a consistent estimate: yes or no, the smallest eigenvalue of
   the bodies' pseudo-inertias, and per body the mass [kg], centre of mass [m] and
   principal moments about it [kg m^2] beside the nominal ones, with ratios.
4. *What was exported?* Links to the URDF / MJCF and their sidecars.
5. *What to do next?* The warnings, each as a sentence with the option that addresses it.

Every function returns ``(question, HTML)`` pairs for
:func:`manip_id.viz.report.write_report` (``questions=``); text is escaped here.
"""

from __future__ import annotations

import html
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..identification import NOT_DETERMINED
from ..identification.document import REFINED_UNCONSTRAINED
from ..identification.document_text import mass_sources
from ..identification.nominal_check import WORSE_PREFIX
from .report import html_table
from .report_tables import not_determined, number

#: A body mass outside [1/MASS_RATIO, MASS_RATIO] times the nominal one is implausible.
MASS_RATIO = 3.0
#: What addresses a warning: (words of the warning, the advice).
ADVICE: tuple[tuple[str, str], ...] = (
    (
        REFINED_UNCONSTRAINED,
        "where a physical model is needed (export, simulation), use the consistent estimate: "
        "leave out --refine",
    ),
    ("non-physical values", "add --consistent to estimate a physical model"),
    ("not physical", "add --consistent to estimate a physical model"),
    (
        "residuals are not white",
        "the reported standard deviations already hold for correlated residuals (--uncertainty "
        "auto: autocorrelation-consistent); so large a misfit says a model term may be missing "
        "(--friction, --armature)",
    ),
    ("low-pass filtered", "compare the raw-torque errors below: they are what a paper reports"),
    ("repeat the training motion", "validate on another trajectory: --validate FILE"),
    ("condition number", "excite the robot better: --optimize (simulation) or richer motion"),
    ("poorly identified", "longer or richer excitation narrows the standard deviations"),
    (NOT_DETERMINED, "these data do not determine them: excite their joints, or fix them"),
    ("gaps in time", "check the log's time stamps (windows FILE@START:STOP leave gaps out)"),
    ("not excited", "these directions need motion the data lack: add runs that move them"),
    ("implausible", "bound the estimate: --consistent with the nominal prior, check the model"),
)


def _esc(x) -> str:
    return html.escape(str(x))


def _pct(x, digits: int = 3) -> str:
    return "n/a" if x is None else f"{number(100 * float(x), digits)} %"


# ------------------------------------------------------------ how good
def model_quality(doc: Mapping) -> tuple[str, str]:
    """How good is the model: errors of the identified and the nominal model, per joint."""
    rel = doc["relative_error"]
    raw = doc.get("relative_error_raw") or {}
    val = rel.get("validation") is not None
    part = "validation" if val else "training"
    e_id = rel["validation"] if val else rel["train"]
    e_nom = rel.get("nominal_validation" if val else "nominal_train")
    ref = (
        "the filtered torques"
        if (doc.get("preprocess") or {}).get("filter_torque")
        else "the torques"
    )
    text = (
        f'<p class="verdict">On the {part} data the identified model predicts {ref} to '
        f"<b>{_pct(e_id)}</b> (relative error), the nominal URDF model to {_pct(e_nom)}"
    )
    raw_id, raw_nom = (
        raw.get("validation" if val else "train"),
        raw.get("nominal_validation" if val else "nominal_train"),
    )
    if raw_id is not None:
        text += f"; against the raw torques {_pct(raw_id)} and {_pct(raw_nom)}"
    text += ".</p>"
    for w in doc.get("warnings") or []:
        if str(w).startswith(WORSE_PREFIX):  # the first thing a user must know
            said, _, do = str(w).partition(" Do: ")
            text += (
                f'<p class="verdict"><span class="no">Worse than the nominal model</span>'
                f"{_esc(said[len('worse than the nominal model') :])}. <b>Do:</b> {_esc(do)}.</p>"
            )
    joints = doc.get("joints") or []
    per_id = rel.get("per_joint_validation") if val else rel.get("train_per_joint")
    per_nom = rel.get("nominal_per_joint_validation" if val else "nominal_train_per_joint")
    per_train = rel.get("train_per_joint")
    rows = []
    for j, name in enumerate(joints if per_id and len(per_id) == len(joints) else []):
        e = per_id[j]
        rows.append(
            {
                "joint": name,
                f"identified, {part} [%]": number(None if e is None else 100 * e, 3),
                f"nominal, {part} [%]": number(
                    None if not per_nom or per_nom[j] is None else 100 * per_nom[j], 3
                ),
                **(
                    {"identified, training [%]": number(100 * per_train[j], 3)}
                    if val and per_train and per_train[j] is not None
                    else {}
                ),
                **_raw_columns(raw, j, val),
                "_class": "warn" if e is not None and e > 0.1 else "",
            }
        )
    return "How good is the model?", text + html_table(rows, "(no per-joint errors)")


def _raw_columns(raw: Mapping, j: int, val: bool) -> dict:
    """Joint ``j``'s errors against the raw torques, when the document has them."""
    key, nkey = (
        ("per_joint_validation", "nominal_per_joint_validation")
        if val
        else (
            "train_per_joint",
            "nominal_train_per_joint",
        )
    )
    out = {}
    for label, k in (("identified, raw [%]", key), ("nominal, raw [%]", nkey)):
        values = raw.get(k)
        if values is not None and j < len(values) and values[j] is not None:
            out[label] = number(100 * values[j], 3)
    return out


# ---------------------------------------------------------------- trust
def trust(doc: Mapping) -> tuple[str, str]:
    """Can I trust the numbers: condition number, uncertainty, flagged parameters."""
    params = doc.get("base_parameters") or []
    counts: dict[str, int] = {}
    for p in params:
        flags = list(p.get("flags") or [])
        if not_determined(p) and NOT_DETERMINED not in flags:
            flags.append(NOT_DETERMINED)
        for f in flags:
            counts[f] = counts.get(f, 0) + 1
    n_flagged = sum(1 for p in params if p.get("flags") or not_determined(p))
    limit = (doc.get("thresholds") or {}).get("poorly_identified", 10.0)
    cond = doc.get("condition_number")
    cond_limit = (doc.get("thresholds") or {}).get("condition_number", 100.0)
    good = cond is not None and cond <= cond_limit
    items = [
        f"condition number {number(cond)} "
        + (
            f'<span class="yes">(below {number(cond_limit)})</span>'
            if good
            else f'<span class="no">(above {number(cond_limit)})</span>'
        ),
        f"{n_flagged} of {len(params)} base parameters flagged"
        + (": " + ", ".join(f"{n} {_esc(f)}" for f, n in sorted(counts.items())) if counts else "")
        + f" (poorly identified: std above {number(limit)} %; flagged rows are listed last in "
        "the parameter table)",
    ]
    fit_scale = (doc.get("consistent_solver") or {}).get("fit_scale")
    unc = doc.get("uncertainty")
    method = unc.get("method", "white") if isinstance(unc, Mapping) else None
    inflation = unc.get("inflation") if isinstance(unc, Mapping) else None
    honest = method == "hac" and inflation is not None
    not_white = fit_scale is not None and fit_scale > 4.0  # chi-square over its expectation
    if fit_scale is not None and not_white:
        told = (  # one figure for the std a reader acts on: the one the tables show
            f"the standard deviations shown are the autocorrelation-consistent ones "
            f"({number(inflation, 3)} times the white-noise ones)"
            if honest
            else f"white-noise standard deviations are about {number(np.sqrt(fit_scale), 2)} "
            "times too small"
        )
        items.append(
            f'<span class="no">the residuals are not white</span>: the physical fit is '
            f"{number(fit_scale, 3)} times its expected chi-square, so {told}"
        )
    if method is not None and not (not_white and honest):  # else the item above says it
        items.append(
            f"standard deviations: {_esc(method)}"
            + ("" if inflation is None else f", {number(inflation, 3)} times the white-noise ones")
        )
    elif method is None:
        items.append(
            "standard deviations: white-noise least squares (they hold for uncorrelated "
            "residuals only)"
        )
    return "Can I trust the numbers?", "<ul>" + "".join(f"<li>{i}</li>" for i in items) + "</ul>"


# ------------------------------------------------------------- physical
def body_rows(doc: Mapping) -> list[dict]:
    """Per body of a standard-parameter estimate: mass, centre of mass and principal
    moments about it, identified beside nominal, with ratios.

    ``c = mc / m`` [m]; ``I_c = I_o - m (|c|^2 E - c c^T)`` [kg m^2] (inertia about the
    centre of mass from the one about the joint origin); moments are its eigenvalues.
    """
    std = doc.get("standard_parameters") or []
    blocks: dict[str, dict[str, tuple[float, float]]] = {}
    for p in std:
        body, _, kind = str(p["name"]).rpartition(".")
        if kind in ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"):
            blocks.setdefault(body, {})[kind] = (p.get("value"), p.get("nominal"))
    flags = _plausibility_flags(doc)
    sources = mass_sources(doc)
    rows = []
    for body, b in blocks.items():
        if len(b) != 10 or any(v is None for pair in b.values() for v in pair):
            continue
        ident, nom = (_body(b, k) for k in (0, 1))
        ratio = ident["m"] / nom["m"] if nom["m"] > 0 else None
        implausible = ratio is not None and not 1 / MASS_RATIO <= ratio <= MASS_RATIO
        note = list(flags.get(body, []))
        if implausible:
            note.append(f"mass {number(ratio, 3)} x nominal")
        rows.append(
            {
                "body": body,
                "mass [kg]": number(ident["m"]),
                "nominal [kg]": number(nom["m"]),
                "mass ratio": number(ratio, 3),
                **({"mass from": sources[body]} if body in sources else {}),
                "centre of mass [m]": _vector(ident["c"]),
                "nominal [m]": _vector(nom["c"]),
                "shift [m]": number(float(np.linalg.norm(ident["c"] - nom["c"])), 3),
                "moments about the CoM [kg m^2]": _vector(ident["moments"]),
                "nominal [kg m^2]": _vector(nom["moments"]),
                "trace ratio": number(
                    ident["moments"].sum() / nom["moments"].sum()
                    if nom["moments"].sum() > 0
                    else None,
                    3,
                ),
                "plausibility": "; ".join(note) or "ok",
                "_class": "bad" if note else "",
            }
        )
    return rows


def _body(b: Mapping, k: int) -> dict:
    """Mass [kg], centre of mass [m], principal moments about it [kg m^2] of one block."""
    m = float(b["m"][k])
    mc = np.array([b["mcx"][k], b["mcy"][k], b["mcz"][k]], dtype=float)
    c = mc / m if m > 0 else np.full(3, np.nan)
    I_o = np.array(
        [
            [b["Ixx"][k], b["Ixy"][k], b["Ixz"][k]],
            [b["Ixy"][k], b["Iyy"][k], b["Iyz"][k]],
            [b["Ixz"][k], b["Iyz"][k], b["Izz"][k]],
        ],
        dtype=float,
    )
    I_c = I_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c)) if m > 0 else I_o
    moments = np.sort(np.linalg.eigvalsh(0.5 * (I_c + I_c.T)))
    return {"m": m, "c": c, "moments": moments}


def _vector(v) -> str:
    return "(" + ", ".join(number(x, 3) for x in np.asarray(v, dtype=float)) + ")"


def _plausibility_flags(doc: Mapping) -> dict[str, list[str]]:
    """Flags per body of the document's ``plausibility`` section, when it has one."""
    out: dict[str, list[str]] = {}
    section = doc.get("plausibility")
    bodies = section.get("bodies") if isinstance(section, Mapping) else section
    for item in bodies if isinstance(bodies, list) else []:
        if isinstance(item, Mapping):
            name = item.get("body") or item.get("name")
            if name is not None and item.get("flags"):
                out.setdefault(str(name), []).extend(str(f) for f in item["flags"])
    return out


def physical(doc: Mapping) -> tuple[str, str]:
    """Is it physical: the consistent estimate's check and its bodies beside nominal."""
    q = "Is it physical?"
    if doc.get("standard_parameters_kind") != "consistent":
        bad = [p["name"] for p in doc.get("base_parameters") or [] if "non-physical" in p["flags"]]
        text = (
            '<p class="verdict"><span class="no">Not checked</span>: plain least squares gives '
            "base parameters (combinations), not a physical model"
            + (f"; {len(bad)} of them are non-physical ({_esc(', '.join(bad[:5]))})" if bad else "")
            + ". Run with <code>--consistent</code> to estimate masses, centres of mass and "
            "inertias that describe a real robot (and <code>--export-urdf OUT.urdf</code> to "
            "write them).</p>"
        )
        return q, text
    cons = doc.get("consistency") or {}
    bodies = cons.get("bodies") or []
    ok = bool(doc.get("physically_consistent"))
    worst = min(bodies, key=lambda b: b.get("min_eigenvalue", np.inf)) if bodies else None
    text = '<p class="verdict">Physically consistent: ' + (
        '<span class="yes">yes</span>' if ok else '<span class="no">no</span>'
    )
    if worst is not None:
        text += (
            f" (smallest eigenvalue of a body's pseudo-inertia {number(worst['min_eigenvalue'], 3)}"
            f" at {_esc(worst['name'])}; positive definite means a real mass distribution)"
        )
    rows = body_rows(doc)
    odd = [r["body"] for r in rows if r["_class"]]
    text += (
        f"; {len(odd)} implausible bod{'y' if len(odd) == 1 else 'ies'}: {_esc(', '.join(odd))}"
        if odd
        else "; every body's mass within 1/3 and 3 times nominal"
        if rows
        else ""
    ) + ".</p>"
    for v in cons.get("violations") or []:
        text += f"<p>{_esc(v)}</p>"
    return q, text + html_table(rows, "(no bodies)")


# ------------------------------------------------------------- exported
def exported(doc: Mapping, report_dir=None) -> tuple[str, str]:
    """What was exported: links to the files ``doc["exported"]`` names."""
    files = doc.get("exported") or {}
    if not files:
        hint = (
            "add <code>--export-urdf OUT.urdf</code> to write the identified robot"
            if doc.get("standard_parameters_kind") == "consistent"
            else "a physical model can be exported with <code>--consistent --export-urdf "
            "OUT.urdf</code>"
        )
        return "What was exported?", f"<p>Nothing: {hint}.</p>"
    items = []
    for what, path in files.items():
        href = _href(path, report_dir)
        items.append(f'<li>{_esc(what)}: <a href="{_esc(href)}">{_esc(path)}</a></li>')
    return "What was exported?", "<ul>" + "".join(items) + "</ul>"


def _href(path, report_dir) -> str:
    """A link to ``path`` from the report folder (relative when it can be)."""
    p = Path(path).resolve()
    if report_dir is None:
        return p.as_uri()
    try:
        return os.path.relpath(p, Path(report_dir).resolve())
    except ValueError:  # another drive
        return p.as_uri()


# ------------------------------------------------------------ next steps
def next_steps(warnings: Sequence[str]) -> tuple[str, str]:
    """What to do next: each warning as a sentence, with what addresses it."""
    if not warnings:
        return "What to do next?", "<p>Nothing to fix: no warning.</p>"
    items = []
    for w in warnings:
        text, _, own = str(w).strip().partition(" Do: ")  # a warning may carry its own
        sentence = text[:1].upper() + text[1:] + ("" if text.endswith(".") else ".")
        advice = own.rstrip(".") or next((a for key, a in ADVICE if key in text), None)
        items.append(
            f"<li>{_esc(sentence)}" + (f" <b>Do:</b> {_esc(advice)}." if advice else "") + "</li>"
        )
    return "What to do next?", "<ul>" + "".join(items) + "</ul>"


def identify_answers(doc: Mapping, report_dir=None) -> list[tuple[str, str]]:
    """The five answers of an identification report, in order."""
    warnings = list(doc.get("warnings") or []) + list(doc.get("data_warnings") or [])
    return [
        model_quality(doc),
        trust(doc),
        physical(doc),
        exported(doc, report_dir),
        next_steps(warnings),
    ]
