"""Per joint, the robust fit of the measured torque on the nominal one (scale, offset)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot.model import Robot

#: Share of the residual torque variance the nominal column must explain for a scale.
EXPLAINED_MIN = 0.3
#: Huber threshold in robust standard deviations (MAD) and iterations of the robust fit.
HUBER, IRLS_STEPS = 1.345, 8


def nominal_torque(robot: Robot, q, dq, ddq) -> np.ndarray:
    """``rnea`` of the robot's own model (URDF inertias and armature), shape (N, nv)."""
    model = robot.model
    data = model.createData()
    out = np.empty((q.shape[0], robot.nv))
    for k in range(q.shape[0]):
        out[k] = pin.rnea(model, data, q[k], dq[k], ddq[k])
    return out


def fit_joint(nom, meas, dq, eps: float, max_lag: int, lag: float | None):
    """``(scale, offset, explained)`` of one joint at the (rounded) ``lag``: the robust fit
    of the measured torque on the nominal one, friction and offset (module docstring)."""
    n = nom.shape[0]
    L = 0 if lag is None else int(round(lag))
    k = np.arange(max_lag, n - max_lag)
    sgn = np.where(np.abs(dq) >= eps, np.sign(dq), 0.0)
    X = np.column_stack([nom[k], dq[k], sgn[k], np.ones(k.size)])
    col = np.abs(X).max(axis=0)
    col[col == 0] = 1.0
    y = meas[k + L]
    coef = huber(X / col, y) / col
    s, offset = float(coef[0]), float(coef[3])
    full = least_squares(X, y)
    rest = least_squares(X[:, 1:], y)
    sse_with = float(np.sum((y - X @ full) ** 2))
    sse_without = float(np.sum((y - X[:, 1:] @ rest) ** 2))
    explained = 1.0 - sse_with / sse_without if sse_without > 0 else None
    if explained is None or explained < EXPLAINED_MIN or s == 0:
        return None, offset, explained
    return s, offset / s, explained


def huber(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Huber-weighted least squares (IRLS, MAD scale) of ``y ~ X c``, shape (p,)."""
    w = np.ones(y.shape[0])
    c = least_squares(X, y)
    for _ in range(IRLS_STEPS):
        r = y - X @ c
        mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        if not mad > 1e-12 * max(float(np.abs(y).max()), 1e-300):
            break
        a = np.abs(r) / (HUBER * mad)
        w = np.where(a <= 1, 1.0, 1.0 / np.maximum(a, 1e-300))
        sw = np.sqrt(w)
        c = least_squares(X * sw[:, None], y * sw)
    return c


def least_squares(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The minimum-norm ``c`` of ``min ||X c - y||`` for a tall ``X`` (N, p) of few columns.

    By the normal equations of the unit-norm columns, ``(D X^T X D) (D^-1 c) = D X^T y``
    with ``D`` the inverse column norms (a zero column keeps a zero coefficient), solved
    by a pseudo-inverse of the (p, p) Gram: about 7x faster than an SVD of ``X`` at N =
    50000, p = 4, and equal to it to round-off times ``cond(X)``, which for the audit's
    columns (nominal torque, velocity, its sign, 1) is small.
    """
    norm = np.sqrt(np.einsum("ij,ij->j", X, X))
    norm[norm == 0] = 1.0
    Xs = X / norm
    return np.linalg.lstsq(Xs.T @ Xs, Xs.T @ y, rcond=1e-12)[0] / norm


# ---------------------------------------------------------------- findings
