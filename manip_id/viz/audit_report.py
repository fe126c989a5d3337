"""The report folder of ``manip-id audit --report DIR``: the data-quality findings first.

Reads the audit's JSON (:meth:`manip_id.audit.Audit.to_dict`): *What is wrong with the
data?* (each file's findings as sentences), *What to fix?* (the options the findings
recommend, ready to paste), then a table per file and joint with human names and units:
measured / nominal torque scale [-], torque delay [ms], torque offset [N m], share of rows
at rest [%], share of the residual variance the nominal model explains [%].
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from pathlib import Path

from .report import ReportContent, write_report
from .report_tables import number


def _esc(x) -> str:
    return html.escape(str(x))


def _ms(x) -> str:
    return "not determined" if x is None else number(1e3 * x, 3)


def _pct(x) -> str:
    return "not determined" if x is None else number(100 * x, 3)


def joint_rows(doc: Mapping) -> list[dict]:
    """One row per file and joint, in words and units."""
    rows = []
    for fa in doc["files"]:
        for j in fa["joints"]:
            scale = j.get("scale")
            odd = scale is not None and (scale < 0 or not 0.5 <= abs(scale) <= 2.0)
            rows.append(
                {
                    "file": fa["file"],
                    "joint": j["joint"],
                    "measured / nominal torque [-]": "not determined"
                    if scale is None
                    else number(scale, 3),
                    "torque delay [ms]": _ms(j.get("delay")),
                    "torque offset [N m]": "not determined"
                    if j.get("offset") is None
                    else number(j["offset"], 3),
                    "at rest [%]": _pct(j.get("standstill")),
                    "explained by the nominal model [%]": _pct(j.get("explained")),
                    "_class": "warn" if odd else "",
                }
            )
    return rows


def file_rows(doc: Mapping) -> list[dict]:
    """One row per file: rows, rate [Hz], rest at the edges [s], rows dropped."""
    out = []
    for fa in doc["files"]:
        rest = fa.get("rest") or {}
        out.append(
            {
                "file": fa["file"],
                "rows": fa["n_rows"],
                "rate [Hz]": number(fa.get("rate")),
                "robot at rest at the start [s]": number(rest.get("start")),
                "robot at rest at the end [s]": number(rest.get("end")),
                "static file": "yes" if fa.get("static") else "no",
                "rows dropped": sum((fa.get("dropped") or {}).values()),
                "findings": len(fa["findings"]),
                "_class": "warn" if fa["findings"] else "",
            }
        )
    return out


def _fixes(fa: Mapping) -> list[str]:
    s = fa.get("suggestions") or {}
    out = []
    if s.get("torque_scale") is not None:
        out.append(
            "--torque-scale "
            + ",".join("?" if g is None else f"{g:g}" for g in s["torque_scale"])
            + (" (? : not determined, give the gain)" if None in s["torque_scale"] else "")
        )
    if s.get("delay") is not None:
        out.append(f"--delay {s['delay']:g}")
    if s.get("trim_standstill"):
        out.append("--trim-standstill")
    return out


def audit_answers(doc: Mapping) -> list[tuple[str, str]]:
    """*What is wrong with the data?* and *What to fix?*, as ``(question, HTML)`` pairs."""
    items, fixes = [], []
    for fa in doc["files"]:
        for f in fa["findings"]:
            items.append(f"<li><b>{_esc(fa['file'])}</b>: {_esc(f)}</li>")
        opts = _fixes(fa)
        if opts:
            fixes.append(f"<li><b>{_esc(fa['file'])}</b>: <code>{_esc(' '.join(opts))}</code></li>")
    n = len(doc["files"])
    if items:
        wrong = f'<p class="verdict">{len(items)} finding(s) in {n} file(s):</p><ul>'
        wrong += "".join(items) + "</ul>"
    else:
        wrong = (
            f'<p class="verdict"><span class="yes">Nothing found</span> in {n} file(s): the '
            "torques match the nominal model in scale, sign and timing.</p>"
        )
    fix = (
        "<p>Pass these options to identify, payload or drive-gains:</p><ul>"
        + "".join(fixes)
        + "</ul>"
        if fixes
        else "<p>No option to add.</p>"
    )
    return [("What is wrong with the data?", wrong), ("What to fix?", fix)]


def write_audit_report(folder, doc: dict, *, force: bool = False) -> Path:
    """The report folder of an audit (``doc``: :meth:`~manip_id.audit.Audit.to_dict`)."""
    title = f"manip-id audit: {doc['robot']}, {len(doc['files'])} file(s)"
    content = ReportContent(
        title=title,
        summary={"robot": doc["robot"], "files": ", ".join(f["file"] for f in doc["files"])},
        parameter_table=joint_rows(doc),
        figures={},
        json_result={"audit": doc},
        tables={"Files": file_rows(doc)},
        questions=audit_answers(doc),
    )
    return write_report(folder, content, force=force)
