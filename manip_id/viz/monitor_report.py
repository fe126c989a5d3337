"""The report folder of ``manip-id monitor --report DIR``: the verdict first.

*Was anything detected?* (the detections per file, the first alarm's time [s] in the
file's own clock), *How close did each joint come to its bound?* (per file and joint the
largest residual ``max_t |r_j(t)|`` [N m] against the bound ``b_j`` [N m], as a margin
``max|r_j| / b_j``: above 1 where the bound was crossed), *How were the bounds set?*
(per joint the bound, its noise and model parts, at the false-alarm rate asked), then one
figure per file: the residuals (estimated external torques) with their bounds.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from .report import ReportContent, html_table, write_report
from .report_tables import number


def _esc(x) -> str:
    return html.escape(str(x))


def residual_figure(path, run, title: str) -> None:
    """Residuals (estimated external torques) of one run with their bounds, one axis per joint."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # optional heavy library
    from matplotlib.figure import Figure
    from matplotlib.text import Text  # (matplotlib: optional heavy library)

    nv = run.residual.shape[1]
    fig = Figure(figsize=(10.0, 1.8 * nv + 1.0), dpi=100)
    FigureCanvasAgg(fig)
    stride = max(1, run.t.size // 4000)
    for j in range(nv):
        ax = fig.add_subplot(nv, 1, j + 1)
        ax.plot(run.t[::stride], run.residual[::stride, j], lw=0.8, label="residual r")
        b = run.bounds[j]
        if np.isfinite(b):
            ax.axhline(b, color="r", lw=0.8, ls="--", label="bound")
            ax.axhline(-b, color="r", lw=0.8, ls="--")
        flags = run.detected[:, j]
        if flags.any():
            ax.fill_between(
                run.t, 0, 1, where=flags, color="orange", alpha=0.3,
                transform=ax.get_xaxis_transform(), label="detected",
            )  # fmt: skip
        ax.set_ylabel(f"{run.dof_names[j]}\n[N m]", fontsize=7)
        if j == 0:
            ax.set_title(title, fontsize=9)
            ax.legend(fontsize=7, loc="upper right")
    fig.axes[-1].set_xlabel("t [s]")
    for text in fig.findobj(Text):
        text.set_parse_math(False)  # file names are shown literally
    fig.tight_layout()
    fig.savefig(path, format="png")


def margin_rows(runs) -> list[dict]:
    """Per file and joint: the largest residual [N m], the bound [N m], their ratio
    ``max|r| / b`` [-] (above 1: crossed), the share of samples in alarm [%]."""
    rows = []
    for run in runs:
        peak = np.abs(run.residual).max(axis=0)  # [N m]
        for j, name in enumerate(run.dof_names):
            b = float(run.bounds[j])
            ratio = peak[j] / b if np.isfinite(b) and b > 0 else None
            rows.append(
                {
                    "file": run.file,
                    "joint": name,
                    "largest residual [N m]": number(peak[j], 3),
                    "bound [N m]": number(b, 3),
                    "largest / bound [-]": number(ratio, 3),
                    "bound": "not set"
                    if ratio is None
                    else "crossed"
                    if ratio > 1
                    else f"{number(100 * (1 - ratio), 2)} % to spare",
                    "samples in alarm [%]": number(100 * run.alarm_rate_per_joint[j], 3),
                    "_class": "bad" if ratio is not None and ratio > 1 else "",
                }
            )
    return rows


def verdict(runs, detections) -> tuple[str, str]:
    """*Was anything detected?*: per file the detections and the first alarm [s]."""
    items = []
    for run in runs:
        mine = [d for d in detections if d.file == run.file]
        if not mine:
            items.append(f"<li><b>{_esc(run.file)}</b>: nothing detected</li>")
            continue
        first = min(mine, key=lambda d: d.start)
        items.append(
            f'<li><b>{_esc(run.file)}</b>: <span class="no">{len(mine)} detection(s)</span>, '
            f"the first alarm at {first.start:.4f} s on {_esc(', '.join(first.joints))} "
            f"(peak {number(first.peak, 3)} N m on {_esc(first.peak_joint)})</li>"
        )
    n = len(detections)
    head = (
        f'<p class="verdict"><span class="no">{n} detection(s)</span> in {len(runs)} file(s).</p>'
        if n
        else f'<p class="verdict"><span class="yes">Nothing detected</span> in {len(runs)} '
        "file(s): every residual stayed within its bound.</p>"
    )
    return "Was anything detected?", head + "<ul>" + "".join(items) + "</ul>"


def bound_rows(th) -> list[dict]:
    """Per joint: the bound and its parts [N m], how it was set, the calibration rate."""
    return [
        {
            "joint": j["name"],
            "bound [N m]": number(j["bound"], 4),
            "noise part [N m]": number(j["noise_bound"], 4),
            "model part [N m]": number(j["model_bound"], 4),
            "method": j["method"],
            "false alarms on the calibration files [per sample]": number(j["rate"], 3),
        }
        for j in th.to_dict()["joints"]
    ]


def write_monitor_report(folder, robot, th, runs, detections, doc: dict, *, force=False) -> Path:
    """The report folder of a monitor run; returns its path.

    th: the thresholds; runs: the monitored runs; detections: their detections; doc: the
    command's JSON (result.json).
    """
    figs = {
        f"residuals_{i}": (
            lambda path, run=run: residual_figure(
                path, run, f"estimated external torque, {run.file}"
            )
        )
        for i, run in enumerate(runs)
    }
    det_rows = [
        {
            "file": d["file"],
            "start [s]": f"{d['start']:.4f}",
            "stop [s]": f"{d['stop']:.4f}",
            "joints": ", ".join(d["joints"]),
            "peak [N m]": number(d["peak"], 4),
        }
        for d in doc["detections"]
    ]
    how = (
        f"<p>Bounds at a false-alarm rate of {th.false_alarm:g} per sample (any joint), from "
        f"{th.n_samples} calibration samples (measured rate there {number(th.rate, 3)}).</p>"
    )
    if th.in_sample:
        how += (
            '<p class="bad">Calibrated on the model\'s own training data ('
            + ", ".join(_esc(f) for f in th.in_sample)
            + "): a fit's residuals there are smaller than on a new run, so the bounds are "
            "too tight and new runs will alarm more often than the rate above. Calibrate on "
            "collision-free runs the model was not identified on.</p>"
        )
    content = ReportContent(
        title=f"manip-id monitor {robot.name}",
        summary={
            "robot": robot.name,
            "model": doc["model"],
            "false-alarm rate [per sample]": th.false_alarm,
            "calibration samples": th.n_samples,
            "detections": len(doc["detections"]),
        },
        parameter_table=bound_rows(th),
        figures=figs,
        json_result=doc,
        tables={"Detections": det_rows} if det_rows else None,
        questions=[
            verdict(runs, detections),
            ("How close did each joint come to its bound?", html_table(margin_rows(runs))),
            ("How were the bounds set?", how),
        ],
    )
    return write_report(folder, content, force=force)
