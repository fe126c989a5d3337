"""A trajectory a scene animates: shapes, finite values, increasing time, joint limits."""

from __future__ import annotations

import numpy as np

from .._checks import as_float_array, check_finite
from ..errors import InfeasibleTrajectoryError, InputError
from ..robot.model import Robot
from ..robot.parameters import bounded_range


def check_trajectory(robot: Robot, t, q, *, tolerance: float = 1e-6):
    """Validated ``(t, q)``: t [s] shape (N,) strictly increasing, q shape (N, nq) within limits.

    Raises :class:`InputError` for wrong shapes or non-finite values and
    :class:`InfeasibleTrajectoryError` (carrying joint, limit, excess) for a
    position outside the robot's finite limits by more than ``tolerance``.
    """
    q = as_float_array(q, "q", ndim=(1, 2))
    if q.ndim == 1:
        q = q[None, :]
    if q.shape[1] != robot.nq:
        raise InputError(f"q.shape={q.shape} but robot.nq={robot.nq} ({robot.name})")
    t = as_float_array(t, "t", ndim=1)
    if t.shape[0] != q.shape[0]:
        raise InputError(f"t.shape={t.shape} but q.shape={q.shape}: one time per row of q")
    check_finite(t, "t")
    check_finite(q, "q")
    if t.shape[0] > 1 and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise InputError(f"time must increase strictly: t[{k}]={t[k]} after t[{k - 1}]={t[k - 1]}")
    lo, hi = robot.lower, robot.upper
    names = _q_names(robot)
    bounded = bounded_range(lo, hi)
    for i in np.flatnonzero(bounded):
        below, above = lo[i] - q[:, i].min(), q[:, i].max() - hi[i]
        excess = max(below, above)
        if excess > tolerance:
            k = int(np.argmin(q[:, i]) if below >= above else np.argmax(q[:, i]))
            raise InfeasibleTrajectoryError(
                f"trajectory leaves the position limits of {names[i]}: q={q[k, i]:.4g} at "
                f"sample {k} (t={t[k]:.4g} s), limits [{lo[i]:.4g}, {hi[i]:.4g}]",
                joint=names[i],
                limit="position",
                excess=float(excess),
            )
    return t, q


def _q_names(robot: Robot) -> list[str]:
    names = []
    for i in range(1, robot.model.njoints):
        nq = robot.model.joints[i].nq
        names += (
            [robot.model.names[i]]
            if nq == 1
            else [f"{robot.model.names[i]}[{k}]" for k in range(nq)]
        )
    return names
