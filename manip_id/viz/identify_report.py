"""The report folder of an identification: figures, the robot scene, tables, the document.

:func:`write_identify_report` draws one run (a simulation, one or several log files held
in memory): the torque fit of the identified and the nominal model, the residuals
``tau - Y_b theta_b``, the singular values of the base regressor, an online method's
parameter history and a simulation's trajectory against the position limits.
:func:`write_fleet_report` draws a run of many files (Dask): singular values and the
per-file parameters. Both hand the folder to :func:`manip_id.viz.report.write_report`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InfeasibleTrajectoryError
from ..identification.document_text import method_label
from . import figures
from .meshcat_scene import RobotScene, link_identifiability
from .report import ReportContent, write_report
from .report_answers import identify_answers
from .report_document import ReportOptions, ReportSamples
from .report_tables import (
    report_parameter_rows,
    report_quality_rows,
    report_selection_rows,
    report_summary,
)
from .rollout_figure import rollout_traces


def build_scene(robot, result, full, title: str, notes: list, assets: str = "inline"):
    """The report's scene, or None (with a note) when it cannot be drawn: never fatal."""
    try:
        scene = RobotScene(robot, title=title)
        scene.assets = assets
        if full is not None:
            try:
                scene.animate(full.t, full.q)
            except InfeasibleTrajectoryError as exc:
                notes.append(f"scene not animated: {exc}")
        scene.add_inertia(robot.nominal_parameters, label="nominal")
        if result.standard is not None and result.standard.solver:  # --consistent
            # off at first like the nominal set (they hide the arm); the legend shows them
            scene.add_inertia(
                result.standard.values, label="identified (consistent)", estimated=True
            )
        ind = result.base.independent
        flags = np.zeros(robot.n_parameters, dtype=bool)
        flags[ind] = True
        rel = np.full(robot.n_parameters, np.inf)
        est = np.asarray(result.estimate, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel[ind] = np.asarray(result.std, dtype=float) / np.abs(est)
        scene.color_by_identifiability(
            link_identifiability(robot, identifiable=flags, relative_std=rel, threshold=0.1)
        )
    except Exception as exc:  # a picture never fails the finished identification
        notes.append(f"3-D scene not drawn: {type(exc).__name__}: {exc}")
        return None
    notes += list(scene.notes)
    return scene


def history_figure(robot, result, train, report: dict):
    """parameter_history.png of an online method (a callable(path)), or None without one."""
    h = result.history
    if h is None or len(h.t) < 2:
        return None
    samples = np.minimum(np.arange(len(h.t)) * max(result.n_samples // 1000, 1), len(train.t) - 1)
    t = train.t[samples]
    truth = report.get("true_base_parameters")  # a simulation's
    if truth is not None:
        ref, label = np.asarray(truth, dtype=float), "truth"
    else:
        ref, label = np.asarray(result.estimate, dtype=float), "final estimate"
    rms = float(np.sqrt(np.mean(np.asarray(train.tau) ** 2)) * np.sqrt(robot.nv))
    return lambda path: figures.online_history(
        path,
        t,
        h.theta,
        names=result.names,
        reference=ref,
        reference_label=label,
        prediction_error=h.error,
        torque_rms=rms,
        options=figures.FigureOptions(
            title=f"{report['method']} on {robot.name}: convergence of the base parameters"
        ),
    )


def _temp(samples):
    """The samples' temperature (the ``temperature`` law's), or None."""
    return getattr(samples, "temp", None)


def _joined(robot, result, samples: ReportSamples, chunk: int) -> dict:
    """Training and validation one after the other: t, tau, the identified and nominal
    predictions, where validation starts, and the validation residual's arguments."""
    nominal = replace(result, estimate=result.nominal)
    train, valid = samples.train, samples.valid
    pred = result.predict(robot, train.q, train.dq, train.ddq, chunk=chunk, temp=_temp(train))
    npred = nominal.predict(robot, train.q, train.dq, train.ddq, chunk=chunk, temp=_temp(train))
    out: dict = dict(t=train.t, tau=train.tau, pred=pred, npred=npred, start=None, res_kw={})
    if valid is None:
        return out
    vpred = result.predict(robot, valid.q, valid.dq, valid.ddq, chunk=chunk, temp=_temp(valid))
    vnom = nominal.predict(robot, valid.q, valid.dq, valid.ddq, chunk=chunk, temp=_temp(valid))
    t, tv = train.t, valid.t
    if tv[0] <= t[-1]:  # separate validation files: drawn after the training record
        step = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
        tv = tv - tv[0] + t[-1] + step
    out.update(
        t=np.concatenate([t, tv]),
        tau=np.vstack([train.tau, valid.tau]),
        pred=np.vstack([pred, vpred]),
        npred=np.vstack([npred, vnom]),
        start=float(tv[0]),
        res_kw=dict(t_validation=valid.t, residual_validation=valid.tau - vpred),
    )
    return out


def _fit_figures(robot, result, report: dict, samples: ReportSamples, run_name: str, chunk: int):
    """torque_fit, residuals and singular_values (callables(path))."""
    j = _joined(robot, result, samples, chunk)
    train = samples.train
    joints = list(robot.dof_names)
    rel = report["relative_error"]
    use_val = rel.get("per_joint_validation") is not None
    e_id = rel["per_joint_validation"] if use_val else rel["train_per_joint"]
    e_nom = rel.get("nominal_per_joint_validation" if use_val else "nominal_train_per_joint")
    errors = list(zip(e_id, e_nom or [None] * len(joints), strict=True))
    units = ["N" if robot.is_prismatic(i) else "N m" for i in range(robot.nv)]
    part = "validation" if use_val else "train"
    pre = report.get("preprocess") or {}
    reference = f"filtered at {pre['cutoff']:g} Hz" if pre.get("filter_torque") else "raw"
    ra = result.rank_analysis
    return {
        "torque_fit": lambda path: figures.torque_comparison(
            path,
            j["t"],
            j["tau"],
            j["pred"],
            j["npred"],
            validation_start=j["start"],
            errors=errors,
            reference=reference,
            options=figures.FigureOptions(
                title=f"measured, identified and nominal torques ({part} errors in the "
                f"titles): {run_name}",
                joint_names=joints,
                units=units,
            ),
        ),
        "residuals": lambda path: figures.residuals(
            path,
            train.t,
            train.tau
            - result.predict(robot, train.q, train.dq, train.ddq, chunk=chunk, temp=_temp(train)),
            joint_names=joints,
            units=units,
            title=f"residuals tau - Y_b theta_b: {run_name}",
            **j["res_kw"],
        ),
        "singular_values": lambda path: figures.singular_values(
            path,
            ra.singular_values_scaled,
            tolerance=ra.tolerance,
            rank=ra.rank,
            title=f"singular values of the data's base regressor: {robot.name}, "
            f"{ra.n_rows} rows, rank {ra.rank} of {ra.n_parameters}",
        ),
    }


def report_sections(report: dict) -> dict | None:
    """The report's sections after the parameters: the friction model chosen per joint
    (``--friction auto``) and the data quality, those the document has."""
    tables = {}
    selection = report_selection_rows(report)
    if selection:
        by = report.get("friction_criterion") or "validation error or BIC"
        tables[f"Friction model per joint (chosen by {by})"] = selection
    quality = report_quality_rows(report)
    if quality:
        tables["Data quality"] = quality
    return tables or None


def write_identify_report(
    folder, robot, result, report: dict, samples: ReportSamples, *, options: ReportOptions
) -> Path:
    """The report folder of one identification run; returns its path.

    folder: a :class:`~manip_id._io.ReportFolder` claimed before the work (or a path);
    report: the run's document (:meth:`~manip_id.identification.IdentificationResult.to_dict`).
    """
    run_name = (
        f"{robot.name}, {method_label(report)}, {options.source}, "
        f"{samples.train.n_samples} training samples"
    )
    figs = _fit_figures(robot, result, report, samples, run_name, options.chunk)
    history = history_figure(robot, result, samples.train, report)
    if history is not None:
        figs["parameter_history"] = history
    full = samples.full
    if options.rollout is not None and options.rollout.traces:
        ro = options.rollout
        figs["rollout"] = lambda path: rollout_traces(
            path,
            ro.traces,
            ro.joints,
            title=f"rollout over {ro.horizon:g} s from the measured torques: {run_name}",
        )
    if options.simulated:
        figs["trajectory"] = lambda path: figures.trajectory_limits(
            path,
            full.t,
            full.q,
            lower=robot.lower,
            upper=robot.upper,
            joint_names=list(robot.dof_names),
            title=f"simulated excitation of {robot.name} against its position limits",
        )
    notes: list[str] = []  # the warnings are answered under "What to do next?"
    title = f"manip-id identify: {run_name}"
    scene = build_scene(robot, result, full, title, notes, options.scene_assets)
    content = ReportContent(
        title=title,
        summary=report_summary(report, options.source),
        parameter_table=report_parameter_rows(report),
        figures=figs,
        scene=scene,
        json_result=report,
        notes=notes,
        tables=report_sections(report),
        questions=identify_answers(report, getattr(folder, "path", folder)),
    )
    return write_report(folder, content, force=options.force)


def write_fleet_report(
    folder, robot, result, report: dict, *, options: ReportOptions, per_file: bool = False
) -> Path:
    """The report of many files: summary, parameters, singular values and (``per_file``)
    each file's parameters against the pooled fit; returns the folder's path."""
    files = report["source"]["data"]
    run_name = (
        f"{robot.name}, {method_label(report)}, {len(files)} files, {result.n_samples} samples"
    )
    ra = result.rank_analysis
    figs = {
        "singular_values": lambda path: figures.singular_values(
            path,
            ra.singular_values_scaled,
            tolerance=ra.tolerance,
            rank=ra.rank,
            title=f"singular values of the pooled base regressor: {run_name}",
        )
    }
    solved = [f for f in (result.per_file or []) if f.result is not None and per_file]
    if solved:
        est = np.array([f.result.estimate for f in solved])
        std = np.array([f.result.std for f in solved])
        figs["per_file_parameters"] = lambda path: figures.per_file_parameters(
            path,
            est,
            std,
            pooled=result.estimate,
            names=result.names,
            files=[Path(f.path).name for f in solved],
            title=f"per-file parameters (+-1 std) relative to the pooled fit: {run_name}",
        )
    summary = {
        **report_summary(report, f"{len(files)} files"),
        "scheduler": report["source"]["scheduler"],
    }
    notes = [  # the warnings are answered under "What to do next?"
        f"{f.path}: not solvable alone ({f.error})"
        for f in (result.per_file or [])
        if f.result is None
    ]
    content = ReportContent(
        title=f"manip-id identify: {run_name}",
        summary=summary,
        parameter_table=report_parameter_rows(report),
        figures=figs,
        json_result=report,
        notes=notes,
        tables=report_sections(report),
        questions=identify_answers(report, getattr(folder, "path", folder)),
    )
    return write_report(folder, content, force=options.force)
