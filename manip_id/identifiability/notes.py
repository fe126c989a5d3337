"""Robot notes: why whole blocks of parameters never enter a robot's dynamics."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..robot.model import Robot


def robot_notes(robot: Robot, analysis_zero: Sequence[int] | np.ndarray) -> list[str]:
    """Why whole blocks of parameters never enter: bodies moved by prismatic joints only."""
    model = robot.model
    notes = []
    zero = {int(j) for j in analysis_zero}
    explained: set[int] = set()
    for i in range(1, model.njoints):
        path, k = [], i
        while k > 0:
            path.append(k)
            k = model.parents[k]
        prismatic = all(
            "Prismatic" in model.joints[k].shortname()
            or model.joints[k].shortname().startswith("JointModelP")
            for k in path
        )
        rot = {10 * (i - 1) + c for c in range(1, 10)}
        if prismatic and rot <= zero:
            explained |= rot
            notes.append(
                f"{model.names[i]}: every joint between the base and this body is prismatic, so "
                "the body never rotates; its first moments (mcx, mcy, mcz) and rotational "
                "inertia (Ixx ... Izz) never enter the dynamics: only its mass is identifiable"
            )
    rest = sorted(zero - explained)
    if rest:
        shown = ", ".join(robot.parameter_names[j] for j in rest[:8])
        more = f" and {len(rest) - 8} more" if len(rest) > 8 else ""
        notes.append(
            f"{len(rest)} parameters never enter the dynamics at all "
            f"(zero regressor column): {shown}{more}"
        )
    return notes


def zero_columns(R: np.ndarray, tol: float) -> np.ndarray:
    norms = np.linalg.norm(R, axis=0)
    return np.flatnonzero(norms <= tol * (norms.max() if norms.size else 0.0))
