"""The report folder of a rank analysis (``manip-id rank --report``).

The structural singular values of the robot (random states) and, with data, those of
the data's base regressor; the robot colored by the share of each link's parameters that
is a base parameter on its own; each standard parameter's status (base alone, regrouped,
unidentifiable).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InfeasibleTrajectoryError
from . import figures
from .meshcat_scene import RobotScene, link_identifiability
from .report import ReportContent, write_report


def _individually_identifiable(base) -> np.ndarray:
    """Per standard parameter: a base parameter on its own (independent, nothing regrouped in)."""
    flags = np.zeros(len(base.names), dtype=bool)
    alone = ~np.any(np.abs(base.K) > 0, axis=1) if base.K.size else np.ones(base.n_base, bool)
    flags[base.independent[alone]] = True
    return flags


def write_rank_report(
    folder, robot, structural, document: dict, *, data=None, dataset=None, force: bool = False
) -> Path:
    """The report folder of a rank analysis; returns its path.

    structural: :func:`~manip_id.identifiability.structural_analysis`'s result; data: the
    analysis of a data set (:func:`~manip_id.identifiability.analyze_dataset`) and
    dataset: its samples (the scene is animated along them), or None; document: the
    run's JSON (result.json).
    """
    source = None if data is None else document["data"]["file"]
    figs = {
        "singular_values": lambda path: figures.singular_values(
            path,
            structural.singular_values_scaled,
            tolerance=structural.tolerance,
            rank=structural.rank,
            title=f"structural singular values of {robot.name}: {structural.n_rows} rows from "
            f"random states, rank {structural.rank} of {structural.n_parameters}",
        ),
    }
    notes = list(structural.notes)
    scene = RobotScene(robot, title=f"manip-id rank {robot.name}")
    if data is not None:
        figs["singular_values_data"] = lambda path: figures.singular_values(
            path,
            data.singular_values_scaled,
            tolerance=data.tolerance,
            rank=data.rank,
            title=f"singular values of the data's base regressor: {source}, "
            f"{data.n_rows} rows, rank {data.rank}",
        )
        try:
            scene.animate(dataset.t, dataset.q)
        except InfeasibleTrajectoryError as exc:
            notes.append(f"scene not animated: {exc}")
        if data.unexcited:
            notes.append(f"{len(data.unexcited)} identifiable directions the data do not excite")
    scene.add_inertia(robot.nominal_parameters, label="nominal")
    flags = _individually_identifiable(structural.base)
    ident = link_identifiability(robot, identifiable=flags)
    scene.color_by_identifiability(ident)
    notes += list(scene.notes)
    base = structural.base
    dependent = set(int(i) for i in base.dependent)
    rows = [
        {
            "parameter": name,
            "status": "base, alone"
            if flags[i]
            else ("unidentifiable / regrouped" if i in dependent else "base, regrouped"),
        }
        for i, name in enumerate(robot.parameter_names)
    ]
    summary = {
        "robot": robot.name,
        "standard parameters": structural.n_parameters,
        "base parameters (rank)": structural.rank,
        "identifiable on their own": int(flags.sum()),
        "condition number (scaled)": structural.condition_number_scaled,
        "rank tolerance": structural.tolerance,
    }
    if data is not None:
        summary["data"] = source
        summary["data rank"] = data.rank
        summary["unexcited directions"] = len(data.unexcited)
    content = ReportContent(
        title=f"manip-id rank {robot.name}",
        summary=summary,
        parameter_table=rows,
        figures=figs,
        scene=scene,
        json_result=document,
        notes=notes,
    )
    return write_report(folder, content, force=force)
