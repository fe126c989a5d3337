"""The physically consistent standard parameters of a saved identification result.

A result written by ``manip-id identify --consistent --json`` (or a report's
``result.json``) holds its standard parameters by name (``standard_parameters``) and
whether they are physically consistent. They are what an export writes later without
identifying again (``manip-id export``): read here by name, in the robot's order, every
value a finite number; a result whose parameters are not physically consistent (plain
least squares gives base parameters, not a physical model) is refused.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def saved_parameters(robot, result, source: str = "the result") -> np.ndarray:
    """The standard parameters of ``result`` (an
    :class:`~manip_id.identification.IdentificationResult`, e.g. from
    :func:`~manip_id.identification.load_result`) in ``robot``'s order, shape (p,).

    Raises :class:`~manip_id.errors.InputError` naming ``source`` when the result holds no
    physically consistent standard parameters or holds those of other parameters.
    """
    ctx = getattr(result, "context", None) or {}
    rows = ctx.get("standard_parameters")
    if not ctx.get("physically_consistent") or not isinstance(rows, list):
        raise InputError(
            f"{source} holds no physically consistent standard parameters (a plain least-"
            "squares result gives base parameters, not a physical model): identify with "
            "--consistent"
        )
    values: dict[str, float] = {}
    for row in rows:
        name = row.get("name") if isinstance(row, dict) else None
        value = row.get("value") if isinstance(row, dict) else None
        if not isinstance(name, str) or isinstance(value, bool):
            continue
        if isinstance(value, int | float) and np.isfinite(value):
            values[name] = float(value)
    names = list(robot.parameter_names)
    missing = [n for n in names if n not in values]
    if missing:
        raise InputError(
            f"{source} holds the standard parameters of another model: {missing[0]} (and "
            f"{len(missing) - 1} more of {robot.name!r}'s {len(names)}) missing or not a "
            "finite number"
        )
    return np.array([values[n] for n in names])


__all__ = ["saved_parameters"]
