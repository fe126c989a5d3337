"""The report folder of an adaptive-control run (``manip-id adapt --report``).

The base-parameter estimates against the truth and the prediction error over time, the
tracking error of the adaptive and the fixed-parameter controller, the robot animated
along the run with the true and the final inertia ellipsoids, and the standard
parameters (true, initial, final).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InfeasibleTrajectoryError
from ..identifiability import analyze
from . import figures
from .meshcat_scene import RobotScene
from .report import ReportContent, write_report


def _figures(robot, cmp, run_name: str, base) -> dict:
    """parameter_estimates (base parameters against the truth) and tracking_error."""
    a, f = cmp.adaptive, cmp.fixed
    joints = list(robot.dof_names)
    figs = {
        "parameter_estimates": lambda path: figures.online_history(
            path,
            a.t,
            base.to_base(a.theta_hat),
            names=base.base_names,
            reference=base.to_base(a.theta_true),
            reference_label="truth",
            prediction_error=a.prediction_error,
            options=figures.FigureOptions(
                title=f"base-parameter error and prediction error over time: {run_name}",
                error_label="torque prediction error on new states [-]",
            ),
        ),
        "tracking_error": lambda path: figures.tracking_error(
            path,
            a.t,
            a.q - a.q_d,
            joint_names=joints if a.q.shape[1] == len(joints) else None,
            baseline=f.q - f.q_d if f.q.shape == a.q.shape else None,
            title=f"tracking error: {run_name}",
        ),
    }
    return figs


def write_adapt_report(
    folder, robot, cmp, document: dict, *, run_name: str, settings: dict, force: bool = False
) -> Path:
    """The report folder of an adaptive run; returns its path.

    cmp: the adaptive and fixed runs (:func:`manip_id.control.closed_loop.compare_fixed`);
    document: the run's JSON (result.json); settings: summary rows of the run's options
    (duration [s], rate [Hz]).
    """
    a, f = cmp.adaptive, cmp.fixed
    law = "composite" if a.composite else "plain"
    base = analyze(robot).base  # the combinations adaptation can converge to
    figs = _figures(robot, cmp, run_name, base)
    notes = []
    scene = RobotScene(robot, title=f"manip-id adapt: {run_name}")
    try:
        scene.animate(a.t, a.q)
    except InfeasibleTrajectoryError as exc:
        notes.append(f"scene not animated: {exc}")
    scene.add_inertia(a.theta_true, label="true")
    scene.add_inertia(a.theta_hat[-1], label="final_estimate", estimated=True)
    notes += list(scene.notes)
    rows = [
        {"parameter": n, "unit": u, "true": t, "initial": s0, "final": s1}
        for n, u, t, s0, s1 in zip(
            robot.parameter_names,
            robot.parameter_units,
            a.theta_true,
            a.theta0,
            a.theta_hat[-1],
            strict=True,
        )
    ]
    summary = {
        "robot": robot.name,
        "law": law,
        **settings,
        "rms tracking error, adaptive [rad]": a.rms_tracking_error,
        "rms tracking error, fixed parameters [rad]": f.rms_tracking_error,
        "final tracking error, adaptive [rad]": a.final_tracking_error,
        "final tracking error, fixed parameters [rad]": f.final_tracking_error,
        "torque prediction error, start": f"{100 * a.initial_prediction_error:.3g} %",
        "torque prediction error, end": f"{100 * a.final_prediction_error:.3g} %",
    }
    notes.append(
        f"the estimates are shown as the {base.n_base} base parameters (the combinations the "
        f"regressor can determine); the {robot.n_parameters} standard parameters in the table "
        "need not converge"
    )
    content = ReportContent(
        title=f"manip-id adapt: {run_name}",
        summary=summary,
        parameter_table=rows,
        figures=figs,
        scene=scene,
        json_result=document,
        notes=notes,
    )
    return write_report(folder, content, force=force)
