"""The tables and text of an identification run's report, from its document.

Every function reads the run's JSON document (``IdentificationResult.to_dict()``)
and returns rows (dicts) for :func:`manip_id.viz.report.write_report` or text for the
terminal. Errors are relative torque errors ``||tau - tau_hat|| / ||tau||`` in percent.
"""

from __future__ import annotations

import numpy as np

from ..identification import NOT_DETERMINED, summary_rows
from ..identification.document import NOT_DETERMINED_PERCENT


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * float(x):.3g} %"


def report_summary(report: dict, source: str) -> dict:
    """The report's summary rows: the result's headline figures as every rendering shows
    them (:func:`manip_id.identification.summary_rows`: errors in percent, the nominal
    model beside the identified one, raw-torque errors, reference torques), then what the
    run knows (source, preprocessing, split, windows, deadband, a simulation's truth)."""
    pre = report.get("preprocess") or {}
    summary: dict = {"robot": report["robot"], "source": source, **summary_rows(report)}
    if pre:
        rate = pre.get("rate")
        summary["preprocessing"] = (
            f"low-pass {pre['cutoff']:g} Hz (Butterworth order {pre['order']}, zero-phase) on "
            f"q, dq{', tau' if pre.get('filter_torque') else ''}; ddq by central differences; "
            f"{pre.get('trim', 0)} samples trimmed at each end of each part (filter edges)"
            + ("" if pre.get("decimate", 1) == 1 else f"; every {pre['decimate']}th sample")
            + (f"; resampled at {rate:g} Hz" if pre.get("resampled") and rate else "")
        )
    else:
        summary["preprocessing"] = "none (the data's own accelerations, unfiltered)"
    src = report.get("source") or {}
    if src.get("split") is not None:
        summary["validation"] = f"the last {100 * (1 - src['split']):.0f} % of the record"
    windows = [f.get("window") for f in report.get("files", []) if f.get("window")]
    if windows:
        summary["windows"] = ", ".join(windows)
    band = report.get("velocity_deadband")
    if band:
        summary["velocity deadband"] = f"{band['eps']:g} rad/s; rows left out: " + ", ".join(
            f"{j} {n}" for j, n in band["excluded_rows"].items()
        )
    if "parameter_error" in report:
        summary["base parameter error vs truth"] = _pct(report["parameter_error"])
    n_bad = sum(bool(p["flags"]) for p in report["base_parameters"])
    summary["flagged parameters"] = f"{n_bad} of {report['n_base']}"
    return summary


def number(x, digits: int = 4) -> str:
    """A number for reading: ``digits`` significant digits without an exponent between
    1e-4 and 1e6 (whole numbers in full), ``n/a`` for None or a non-finite value."""
    if x is None:
        return "n/a"
    x = float(x)
    if not np.isfinite(x):
        return "n/a"
    ax = abs(x)
    if ax == 0:
        return "0"
    if ax >= 1e6 or ax < 1e-4:
        return f"{x:.{digits - 1}e}"
    if ax >= 10 ** (digits - 1):
        return f"{x:.0f}"
    decimals = digits - 1 - int(np.floor(np.log10(ax)))
    return f"{x:.{decimals}f}".rstrip("0").rstrip(".")


def not_determined(p: dict) -> bool:
    """Whether a base parameter of the document reads "not determined by these data"."""
    sp = p.get("std_percent")
    return (
        NOT_DETERMINED in p.get("flags", [])
        or (sp is None and p.get("std") is None)
        or (sp is not None and not sp <= NOT_DETERMINED_PERCENT)
    )


def report_parameter_rows(report: dict) -> list[dict]:
    """The parameter table, trustworthy rows first (no flag, smallest std), flagged rows
    after (non-physical ones last) and highlighted; a parameter the data do not determine
    shows no value, std or std [%] (:func:`not_determined`)."""
    truth = report.get("true_base_parameters")
    rows = []
    for i, p in enumerate(report["base_parameters"]):
        flags = list(p["flags"])
        sp = p["std_percent"]
        undetermined = not_determined(p)
        if undetermined and NOT_DETERMINED not in flags:
            flags.append(NOT_DETERMINED)
        rank = (
            3 if undetermined else 2 if "non-physical" in flags else 1 if flags else 0,
            np.inf if sp is None else sp,
        )
        row = {
            "name": p["name"],
            "unit": p["unit"],
            "identified": "not determined" if undetermined else number(p["value"]),
            "nominal": number(p["nominal"]),
            **({"true": number(truth[i])} if truth is not None else {}),
            "std": "-" if undetermined else number(p["std"], 3),
            "std [%]": "-" if undetermined else number(sp, 3),
            "flags": ", ".join(flags) or "ok",
            "expression": p["expression"],
            "_class": "bad" if "non-physical" in flags or undetermined else "warn" if flags else "",
        }
        rows.append((rank, row))
    return [row for _, row in sorted(rows, key=lambda x: x[0])]


def _per_joint_range(values: dict | None, scale: float = 1.0, digits: int = 2) -> str:
    """``"lo - hi"`` of a per-joint mapping (times ``scale``), or ``n/a``."""
    vals = [float(v) * scale for v in (values or {}).values() if v is not None]
    if not vals:
        return "n/a"
    lo, hi = min(vals), max(vals)
    return number(lo, digits) if lo == hi else f"{number(lo, digits)} - {number(hi, digits)}"


def report_quality_rows(report: dict) -> list[dict]:
    """The data-quality section: one row per file (training and validation), in words
    and units (times in s or ms, rates in Hz, shares in %)."""
    rows = []
    for kind, key in (("training", "data_quality"), ("validation", "validation_data_quality")):
        for q in report.get(key) or []:
            eps = q.get("standstill_eps")
            jitter = q.get("jitter")
            ms = [None if q.get(k) is None else 1e3 * q[k] for k in ("dt_min", "dt_max")]
            rows.append(
                {
                    "part": kind,
                    "file": q.get("file"),
                    "format": q.get("format"),
                    "window": q.get("window") or "whole file",
                    "samples": q.get("n_samples"),
                    "rows dropped": q.get("n_dropped"),
                    "first dropped row": q.get("first_dropped")
                    if q.get("first_dropped") is not None
                    else "-",
                    "start [s]": number(q.get("t_start")),
                    "duration [s]": number(q.get("duration")),
                    "rate [Hz]": number(q.get("rate")),
                    "jitter [%]": "n/a" if jitter is None else number(100 * jitter, 2),
                    "shortest step [ms]": number(ms[0], 3),
                    "longest step [ms]": number(ms[1], 3),
                    "gaps": q.get("n_gaps"),
                    f"standstill (|dq| < {number(eps)} rad/s) [%]"
                    if eps is not None
                    else "standstill [%]": _per_joint_range(q.get("standstill_share"), 100.0),
                    "clipped [%]": _per_joint_range(q.get("clipped_share"), 100.0),
                    "warnings": "; ".join(q.get("warnings") or []) or "none",
                    "_class": "warn" if q.get("warnings") else "",
                }
            )
    return rows


_SHAPE_TEXT = {"vs": ("vs", "rad/s"), "slope": ("a", "s/rad"), "shift": ("c", "rad/s")}


def _shape_text(parameters: dict) -> str:
    """``"vs = 0.06 rad/s"``, ``"a = 30 s/rad, c = 0 rad/s"``, or ``-`` for a linear law."""
    cells = []
    for key, value in (parameters or {}).items():
        name, unit = _SHAPE_TEXT.get(key, (key, ""))
        cells.append(f"{name} = {number(value, 3)} {unit}".rstrip())
    return ", ".join(cells) or "-"


def report_selection_rows(report: dict) -> list[dict]:
    """The ``--friction auto`` section: per joint each candidate model with its number of
    parameters (the joint's identified coefficients plus its shapes), its shapes, its
    validation error [%] and BIC; the chosen model of each joint marked. Empty without
    ``friction_selection`` in the document."""
    rows = []
    for js in report.get("friction_selection") or []:
        for c in js["candidates"]:
            err, bic = c.get("validation_error"), c.get("bic")
            chosen = c["model"] == js["chosen"]
            rows.append(
                {
                    "joint": js["joint"],
                    "model": c["model"],
                    "chosen": "chosen" if chosen else "",
                    "parameters": "n/a" if c.get("n_parameters") is None else c["n_parameters"],
                    "shape": _shape_text(c.get("parameters")),
                    "validation error [%] (not used)": "n/a"
                    if err is None
                    else number(100 * err, 4),
                    "BIC": "n/a (not excited)" if bic is None else number(bic, 6),
                }
            )
    return rows
