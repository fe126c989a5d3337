"""The report folders of ``manip-id payload`` and ``manip-id drive-gains``.

Both read the command's JSON document (:meth:`~manip_id.payload.PayloadResult.to_dict`,
:meth:`~manip_id.payload.DriveGainResult.to_dict`) and answer first:

- payload: *What is the payload?* (mass [kg], centre of mass [m] in its frame, inertia
  about the centre of mass [kg m^2], each with its standard deviation, beside a reference
  when one is known), *Is it physical?* (the smallest eigenvalue of its pseudo-inertia),
  *Can I trust it?* (the covariance's method and inflation, the condition number, the
  Wald test that the loaded runs show a payload, the torque errors), *What to do next?*
- drive gains: *What are the gains?* (``tau_j = g_j i_j`` [N m / A] per joint with its
  standard deviation, and whether OLS/WLS/TLS agree with the maximum-likelihood gains),
  *Can I trust them?*, *What to do next?*

The scene shows the robot with the payload's equivalent inertia ellipsoid (the solid
ellipsoid of the same mass, centre of mass and inertia) at its frame.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..payload import QUANTITY_NAMES, QUANTITY_UNITS, payload_frame
from ..payload.gains import ML_DISAGREEMENT
from .meshcat_scene import RobotScene
from .report import ReportContent, html_table, write_report
from .report_answers import next_steps
from .report_tables import number

#: Human names of the payload's quantities (:data:`~manip_id.payload.QUANTITY_NAMES`).
QUANTITY_LABELS = {
    "mass": "mass",
    "com.x": "centre of mass x",
    "com.y": "centre of mass y",
    "com.z": "centre of mass z",
    "inertia.Ixx": "inertia Ixx (about the CoM)",
    "inertia.Ixy": "inertia Ixy (about the CoM)",
    "inertia.Iyy": "inertia Iyy (about the CoM)",
    "inertia.Ixz": "inertia Ixz (about the CoM)",
    "inertia.Iyz": "inertia Iyz (about the CoM)",
    "inertia.Izz": "inertia Izz (about the CoM)",
}
#: A standard deviation above this share of its value [%] reads "poorly determined".
POOR_PERCENT = 10.0


def _esc(x) -> str:
    return html.escape(str(x))


def _quantities(p: Mapping) -> list[tuple[float | None, float | None]]:
    """``(value, std)`` of the 10 quantities of a JSON ``payload`` block, in order."""
    vals = [p.get("mass"), *(p.get("com") or [None] * 3), *(p.get("inertia") or [None] * 6)]
    stds = [
        p.get("mass_std"),
        *(p.get("com_std") or [None] * 3),
        *(p.get("inertia_std") or [None] * 6),
    ]
    return list(zip(vals, stds, strict=True))


def payload_rows(p: Mapping, reference=None, reference_label: str = "true") -> list[dict]:
    """The payload table: per quantity its human name, unit, value, std, std [%], the
    reference (shape (10,), the order of :data:`QUANTITY_NAMES`, or None) and its error in
    standard deviations; "not determined" where the torques do not show it."""
    known = set(p.get("known") or [])
    rows = []
    for i, (name, unit) in enumerate(zip(QUANTITY_NAMES, QUANTITY_UNITS, strict=True)):
        value, std = _quantities(p)[i]
        row: dict = {"quantity": QUANTITY_LABELS[name], "unit": unit}
        if name in known:
            row.update(identified=number(value), std="given", **{"std [%]": "-"})
            status = "given"
        elif value is None:
            row.update(identified="not determined", std="-", **{"std [%]": "-"})
            status = "not shown by these torques"
        else:
            pct = None if std is None or value == 0 else 100.0 * std / abs(value)
            row.update(identified=number(value), std=number(std, 3), **{"std [%]": number(pct, 3)})
            status = "ok" if pct is None or pct <= POOR_PERCENT else "poorly determined"
        if reference is not None:
            ref = float(reference[i])
            row[reference_label] = number(ref)
            err = None if value is None or not std else (value - ref) / std
            row[f"error / std vs {reference_label}"] = number(err, 3) if err is not None else "-"
        row["status"] = status
        row["_class"] = "bad" if value is None and name not in known else ""
        row["_class"] = row["_class"] or ("warn" if status == "poorly determined" else "")
        rows.append(row)
    return rows


def _payload_answer(doc: Mapping, reference, reference_label: str) -> tuple[str, str]:
    p = doc["payload"]
    m, ms = p.get("mass"), p.get("mass_std")
    com = p.get("com") or []
    head = f"The payload at <b>{_esc(p['frame'])}</b> (on {_esc(p['parent_joint'])}): "
    if m is None:
        head += "its mass is <b>not determined</b> by these torques"
    else:
        head += f"mass <b>{number(m)} kg</b>" + (f" &plusmn; {number(ms, 2)} kg" if ms else "")
    if com and all(c is not None for c in com):
        head += ", centre of mass (" + ", ".join(number(c, 3) for c in com) + f") m in {p['frame']}"
    if reference is not None and m is not None:
        head += f"; {reference_label} mass {number(reference[0])} kg"
    missing = p.get("not_identifiable") or []
    if missing:
        head += f"; not shown by the torques: {_esc(', '.join(missing))}"
    text = f'<p class="verdict">{head}.</p>'
    return "What is the payload?", text + html_table(payload_rows(p, reference, reference_label))


def _physical_answer(p: Mapping) -> tuple[str, str]:
    ok = p.get("physically_consistent")
    lam = p.get("pseudo_inertia_min_eigenvalue")
    if ok is None:
        text = (
            '<p class="verdict">Physically consistent: <span class="no">not decided</span>: the '
            "torques leave some of the payload's parameters free, and only a consistent fit "
            "chooses them (add <code>--consistent</code>).</p>"
        )
    else:
        word = '<span class="yes">yes</span>' if ok else '<span class="no">no</span>'
        text = (
            f'<p class="verdict">Physically consistent: {word} (smallest eigenvalue of the '
            f"payload's pseudo-inertia {number(lam, 3)}; positive means a real mass "
            "distribution).</p>"
        )
    return "Is it physical?", text


def _trust_answer(doc: Mapping) -> tuple[str, str]:
    items = []
    unc = doc.get("uncertainty") or {}
    if unc.get("method") == "hac":
        items.append(
            "standard deviations: autocorrelation-consistent (they hold for correlated "
            f"residuals), {number(unc.get('inflation'), 3)} times the white-noise ones, from "
            f"{unc.get('n_blocks')} blocks"
        )
    else:
        items.append(
            "standard deviations: white noise"
            + (f" ({_esc(unc['reason'])})" if unc.get("reason") else "")
            + (
                ""
                if unc
                else " (no autocorrelation-consistent estimate for this fit: correlated "
                "residuals make them too small)"
            )
        )
    cond = doc.get("condition_number")
    items.append(f"condition number of the regressor {number(cond)}")
    test = doc.get("payload_test") or {}
    if test.get("p_value") is not None:
        items.append(
            f"the loaded runs show a payload: Wald statistic {number(test.get('statistic'))} "
            f"for {test.get('dof')} parameters (p-value "
            + ("below 1e-6" if test["p_value"] < 1e-6 else number(test["p_value"], 3))
            + ")"
        )
    rel = doc.get("relative_error") or {}
    errs = ", ".join(f"{k} runs {number(100 * v, 3)} %" for k, v in rel.items() if v is not None)
    if errs:
        items.append(f"relative torque error ||tau - tau_hat|| / ||tau||: {errs}")
    n = doc.get("n_samples") or {}
    if n:
        items.append(f"{n.get('unloaded', 0)} unloaded and {n.get('loaded', 0)} loaded samples")
    items.append(f"solver: {_esc(doc.get('solver', 'n/a'))}")
    return "Can I trust it?", "<ul>" + "".join(f"<li>{i}</li>" for i in items) + "</ul>"


def _warnings(doc: Mapping) -> list[str]:
    audit = doc.get("audit") or {}
    found = [f"{fa['file']}: {f}" for fa in audit.get("files") or [] for f in fa["findings"]]
    return list(doc.get("warnings") or []) + found


def payload_answers(doc: Mapping, reference=None, reference_label: str = "true") -> list:
    """The answers of a payload report, in order (``(question, HTML)`` pairs)."""
    return [
        _payload_answer(doc, reference, reference_label),
        _physical_answer(doc["payload"]),
        _trust_answer(doc),
        next_steps(_warnings(doc)),
    ]


def payload_scene(robot, doc: Mapping, title: str, notes: list):
    """The robot with the payload's equivalent ellipsoid at its frame, or None (noted)."""
    p = doc["payload"]
    std = p.get("standard_parameters") or []
    try:
        phi = np.array([s["value"] for s in std], dtype=float)
        pf = payload_frame(robot, p["frame"])
        theta = np.zeros(robot.n_parameters)
        theta[pf.columns] = pf.transform @ phi  # the payload about its joint's origin
        scene = RobotScene(robot, title=title)
        scene.add_inertia(
            theta, label="payload", bodies=[pf.joint_name], visible=True, estimated=True
        )
    except (TypeError, ValueError, KeyError) as exc:  # a value the data do not fix
        notes.append(f"3-D scene not drawn: the payload is not fully determined ({exc})")
        return None
    except Exception as exc:  # a picture never fails the finished identification
        notes.append(f"3-D scene not drawn: {type(exc).__name__}: {exc}")
        return None
    notes += list(scene.notes)
    return scene


def _fit_rows(doc: Mapping) -> list[dict]:
    """Per joint: the relative torque errors of each kind of run, rows left out."""
    per = doc.get("relative_error_per_joint") or {}
    left = doc.get("rows_left_out") or {}
    rows = []
    for j, name in enumerate(doc["joints"]):
        row: dict = {"joint": name}
        for kind, values in per.items():
            v = values[j] if j < len(values) else None
            row[f"{kind} error [%]"] = number(None if v is None else 100 * v, 3)
        row["rows left out (deadband)"] = left.get(name, 0)
        rows.append(row)
    return rows


def _base_rows(doc: Mapping) -> list[dict]:
    rows = []
    for b in doc.get("base_parameters") or []:
        v, s = b.get("value"), b.get("std")
        undetermined = v is None or s is None or (v != 0 and abs(s / v) > 1e3)
        rows.append(
            {
                "name": b["name"],
                "value": "not determined" if undetermined else number(v),
                "std": "-" if undetermined else number(s, 3),
                "expression": b.get("expression", ""),
                "_class": "bad" if undetermined else "",
            }
        )
    return rows


def write_payload_report(
    folder, robot, doc: dict, *, reference=None, reference_label: str = "true", force=False
) -> Path:
    """The report folder of a payload identification; returns its path.

    folder: a claimed :class:`~manip_id._io.ReportFolder` (or a path); doc: the command's
    JSON; reference: the payload's known quantities ``[m, c (3), I_c (6)]`` [kg, m,
    kg m^2] (a simulation's truth, a datasheet), shown beside the estimate.
    """
    method = str(doc.get("method", "")).upper()
    title = f"manip-id payload: {robot.name}, {doc['payload']['frame']}, {method}"
    notes: list[str] = []
    scene = payload_scene(robot, doc, title, notes)
    content = ReportContent(
        title=title,
        summary=_summary(doc),
        parameter_table=_base_rows(doc),
        figures={},
        scene=scene,
        json_result=doc,
        notes=notes,
        tables={"Torque errors per joint": _fit_rows(doc)},
        questions=payload_answers(doc, reference, reference_label),
    )
    return write_report(folder, content, force=force)


def _summary(doc: Mapping) -> dict:
    src = doc.get("source") or {}
    out = {
        "robot": doc["robot"],
        "method": str(doc.get("method", "")).upper()
        + (", consistent" if doc.get("consistent") else ""),
        "unloaded runs": ", ".join(src.get("unloaded") or []) or "-",
        "loaded runs": ", ".join(src.get("loaded") or []) or "-",
    }
    if src.get("known_base"):
        out["robot's base parameters from"] = src["known_base"]
    return out


# ------------------------------------------------------------- drive gains
def gain_rows(doc: Mapping) -> list[dict]:
    """Per joint: gain [N m / A], std and std [%]; "not determined" where the data do not
    fix it."""
    rows = []
    for g in doc["drive_gains"]:
        row: dict = {"joint": g["joint"], "unit": "N m / A"}
        if not g["determined"] or g["gain"] is None:
            row.update(gain="not determined", std="-", **{"std [%]": "-"})
            row["_class"] = "bad"
        else:
            pct = g.get("std_percent")
            row.update(
                gain=number(g["gain"]), std=number(g["std"], 3), **{"std [%]": number(pct, 3)}
            )
            row["_class"] = "warn" if pct is not None and pct > POOR_PERCENT else ""
        rows.append(row)
    return rows


def _ml_agreement(doc: Mapping) -> str:
    """How the gains compare with the maximum-likelihood gains of the same data."""
    method = str(doc.get("method", "")).lower()
    if method == "ml":
        return "they are the maximum-likelihood gains (in current units, started from OLS)"
    if any("maximum-likelihood gain" in w for w in doc.get("warnings") or []):
        return (
            '<span class="no">some differ from the maximum-likelihood gains of the same '
            "data</span> (named under What to do next?)"
        )
    return (
        f'<span class="yes">each agrees with the maximum-likelihood gain</span> of the same '
        f"data within {ML_DISAGREEMENT:g} of its standard deviations"
    )


def drive_gain_answers(doc: Mapping) -> list:
    """The answers of a drive-gain report, in order."""
    gains = doc["drive_gains"]
    n_ok = sum(bool(g["determined"]) for g in gains)
    verdict = (
        f'<p class="verdict">{n_ok} of {len(gains)} joint gains determined (torque = gain '
        "&times; current [N m / A]) by "
        f"{_esc(str(doc.get('method', '')).upper())}: {_ml_agreement(doc)}.</p>"
    )
    return [
        ("What are the drive gains?", verdict + html_table(gain_rows(doc))),
        ("Can I trust them?", _trust_answer(doc)[1]),
        ("What is the payload?", html_table(payload_rows(doc["payload"]))),
        next_steps(_warnings(doc)),
    ]


def write_drive_gain_report(folder, robot, doc: dict, *, force: bool = False) -> Path:
    """The report folder of a drive-gain identification; returns its path."""
    title = f"manip-id drive-gains: {robot.name}, {str(doc.get('method', '')).upper()}"
    content = ReportContent(
        title=title,
        summary=_summary(doc),
        parameter_table=_base_rows(doc),
        figures={},
        json_result=doc,
        tables={"Torque errors per joint": _fit_rows(doc)},
        questions=drive_gain_answers(doc),
    )
    return write_report(folder, content, force=force)
