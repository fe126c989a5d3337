"""The tables and text of an identification run's report, from its document.

Every function reads the run's JSON document (:func:`manip_id.viz.report_document.result_document`)
and returns rows (dicts) for :func:`manip_id.viz.report.write_report` or text for the
terminal. Errors are relative torque errors ``||tau - tau_hat|| / ||tau||`` in percent.
"""

from __future__ import annotations

import numpy as np


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * float(x):.3g} %"


def report_summary(report: dict, source: str) -> dict:
    """The report's summary rows: errors in percent as the CLI prints them, the nominal
    model beside the identified one, and the preprocessing stated."""
    rel = report["relative_error"]
    pre = report.get("preprocess") or {}
    summary = {
        "robot": report["robot"],
        "method": report["method"]
        + ("" if report.get("model", "dynamic") == "dynamic" else f" ({report['model']} model)"),
        "source": source,
        "training samples": report["n_samples"],
        "validation samples": report.get("n_validation_samples"),
        "base parameters": f"{report['n_base']} of {report['n_parameters']}",
        "condition number": report["condition_number"],
        "relative torque error, train": f"{_pct(rel['train'])} (nominal URDF model "
        f"{_pct(rel.get('nominal_train'))})",
        "relative torque error, validation": f"{_pct(rel['validation'])} (nominal URDF model "
        f"{_pct(rel.get('nominal_validation'))})",
        "reference torques": report.get("reference_torques", "raw"),
    }
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


def report_parameter_rows(report: dict) -> list[dict]:
    """The parameter table, trustworthy rows first (no flag, smallest std), flagged rows
    after (non-physical ones last) and highlighted."""
    truth = report.get("true_base_parameters")
    rows = []
    for i, p in enumerate(report["base_parameters"]):
        flags = list(p["flags"])
        sp = p["std_percent"]
        rank = (2 if "non-physical" in flags else 1 if flags else 0, np.inf if sp is None else sp)
        rows.append(
            (
                rank,
                {
                    "name": p["name"],
                    "unit": p["unit"],
                    "identified": p["value"],
                    "nominal": p["nominal"],
                    **({"true": truth[i]} if truth is not None else {}),
                    "std": p["std"],
                    "std [%]": sp,
                    "flags": ", ".join(flags) or "ok",
                    "expression": p["expression"],
                    "_class": "bad" if "non-physical" in flags else "warn" if flags else "",
                },
            )
        )
    return [row for _, row in sorted(rows, key=lambda x: x[0])]


def report_quality_rows(report: dict) -> list[dict]:
    """The data-quality section: one row per file (training and validation)."""
    rows = []
    for kind, key in (("training", "data_quality"), ("validation", "validation_data_quality")):
        for q in report.get(key) or []:
            row: dict[str, str | int | float | None] = {"part": kind}
            for k, v in q.items():
                if isinstance(v, str | int | float | bool) or v is None:
                    row[k] = v
                elif isinstance(v, list) and all(isinstance(x, str) for x in v):
                    row[k] = "; ".join(v) or "none"
            rows.append(row)
    return rows


def summary_text(report: dict) -> str:
    """The run in a few lines, as ``manip-id identify`` prints them after the table.

    An energy or momentum model (``report["model"]``) without per-joint validation
    reports its own outputs (``report["outputs"]``), not the joints.
    """
    if report.get("model", "dynamic") != "dynamic":
        rel = report["relative_error"]
        shown = report if rel["per_joint_validation"] else {**report, "joints": report["outputs"]}
        text = _summary_lines(shown)
        return text.replace("relative torque error: train", "relative error: train")
    return _summary_lines(report)


def _summary_lines(report: dict) -> str:
    rel = report["relative_error"]

    def pct(x):
        return "n/a" if x is None else f"{100 * x:.3f} %"

    lines = [
        f"robot {report['robot']}: {report['n_base']} base parameters of {report['n_parameters']}, "
        f"{report['n_samples']} training samples, method {report['method']}",
        f"condition number {report['condition_number']:.6g}"
        if report["condition_number"]
        else "condition number n/a",
        f"relative torque error: train {pct(rel['train'])}, validation {pct(rel['validation'])}",
        f"nominal model (URDF): train {pct(rel.get('nominal_train'))}, validation "
        f"{pct(rel.get('nominal_validation'))}",
    ]
    if report.get("reference_torques"):
        lines.append(f"reference torques: {report['reference_torques']}")
    per_joint = rel["per_joint_validation"] or rel["train_per_joint"]
    label = "validation" if rel["per_joint_validation"] else "train"
    lines.append(
        f"per joint ({label}): "
        + ", ".join(f"{j} {pct(e)}" for j, e in zip(report["joints"], per_joint, strict=True))
    )
    if "parameter_error" in report:
        lines.append(
            f"base parameter error vs truth: {pct(report['parameter_error'])} "
            f"(max {report['parameter_error_in_std']:.2f} std)"
        )
    return "\n".join(lines)
