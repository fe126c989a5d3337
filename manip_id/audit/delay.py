"""The delay of a file's torque stream behind its motion stream, by cross-validation."""

from __future__ import annotations

import numpy as np

from ..regressor import regressor

#: Rows of the motion stream the delay search fits (evenly spaced over the file).
LAG_ROWS = 12000
#: Rows per block of the two interleaved halves of the delay search's cross-validation.
LAG_BLOCK = 200


def stream_lags(robot, proc, eps: float, max_lag: int, gains: np.ndarray):
    """``(common, gain, own)``: the lag [samples] of the whole torque stream, the share of
    the held-out error it removes against lag 0, and per joint the lag of its own torque
    (the others at the common lag); lags are None when not determined.

    The lag is the one whose torques (each divided by its scale at lag 0, ``gains``) one
    rigid-body model predicts best on held-out rows.
    The model is the robot's full regressor with parameters shared by all joints, plus
    per joint ``dq_j``, ``sgn_eps(dq_j)`` and 1 (friction, offset). The rows are cut into
    two interleaved halves of :data:`LAG_BLOCK` rows; the parameters fitted on one half
    for lags ``L`` (``beta = G^+ b``, ``G = sum_j Y_j^T Y_j`` fixed by the motion stream,
    ``b = sum_j Y_j^T tau_j[k + L_j]``) predict the other, and the two prediction errors
    add up (two-fold cross-validation: an in-sample residual lets the lag fit the model's
    own errors). The common lag is swept for all joints at once; each joint's own lag with
    the others held at it. Both are refined to a sub-sample by the parabola through the
    neighbours of the best lag.
    """
    n, nv = proc.n_samples, robot.nv
    if max_lag < 1:
        return None, 0.0, [None] * nv
    k = np.arange(max_lag, n - max_lag)
    k = k[:: max(1, k.size // LAG_ROWS)]
    Y = regressor(robot, proc.q[k], proc.dq[k], proc.ddq[k])  # (N', nv, p)
    F = np.zeros((k.size, nv, 3 * nv))
    for j in range(nv):
        dq = proc.dq[k, j]
        F[:, j, 3 * j : 3 * j + 3] = np.column_stack(
            [dq, np.where(np.abs(dq) >= eps, np.sign(dq), 0.0), np.ones(k.size)]
        )
    Y = np.concatenate([Y, F], axis=2)
    norm = np.sqrt(np.einsum("njc,njc->c", Y, Y))
    Y = Y[:, :, norm > 0] / norm[norm > 0]
    sweep = np.arange(-max_lag, max_lag + 1)
    half = (np.arange(k.size) // LAG_BLOCK) % 2 == 0
    tau = proc.tau / gains  # currents and flipped signs undone: one model fits all joints
    parts = [lag_sums(Y[m], tau, k[m], sweep) for m in (half, ~half)]
    curve = held_out(parts[0], parts[1], None, None) + held_out(parts[1], parts[0], None, None)
    common = vertex(curve)
    gain = float((curve[max_lag] - curve.min()) / curve[max_lag]) if curve[max_lag] > 0 else 0.0
    at = np.full(nv, max_lag if common is None else int(round(common)))  # sweep indices
    own = [
        vertex(held_out(parts[0], parts[1], j, at) + held_out(parts[1], parts[0], j, at))
        for j in range(nv)
    ]
    shift = -max_lag
    return (
        None if common is None else common + shift,
        gain,
        [None if x is None else x + shift for x in own],
    )


def vertex(curve: np.ndarray) -> float | None:
    """Index of the minimum of ``curve``, refined by the parabola through its neighbours;
    None when the curve is flat."""
    c = curve
    if c.max() - c.min() <= 1e-9 * max(abs(c.max()), 1e-300):
        return None
    i = int(np.argmin(c))
    frac = 0.0
    if 0 < i < c.size - 1:
        den = c[i - 1] - 2 * c[i] + c[i + 1]
        if den > 0:
            frac = float(np.clip(0.5 * (c[i - 1] - c[i + 1]) / den, -0.5, 0.5))
    return i + frac


def lag_sums(Y: np.ndarray, tau: np.ndarray, k: np.ndarray, sweep: np.ndarray):
    """``(G, G^+, B, yy)`` of rows ``k``: ``B[j, :, i] = Y_j^T tau_j[k + sweep_i]``,
    ``yy[j, i] = ||tau_j[k + sweep_i]||^2``."""
    nv = Y.shape[1]
    G = np.einsum("njc,njd->cd", Y, Y)
    Gp = np.linalg.pinv(G, rcond=1e-10, hermitian=True)
    idx = k[:, None] + sweep[None, :]
    B = np.stack([Y[:, j, :].T @ tau[idx, j] for j in range(nv)])
    yy = np.stack([np.sum(tau[idx, j] ** 2, axis=0) for j in range(nv)])
    return G, Gp, B, yy


def held_out(train, valid, j: int | None, at: np.ndarray | None) -> np.ndarray:
    """Prediction error on ``valid`` of the fit on ``train`` over the lags: of joint ``j``
    (the other joints at the indices ``at``), or of all joints together (``j`` None); up to
    a constant, shape (lags,)."""
    _, Gp, Bt, yyt = train
    Gv, _, Bv, yyv = valid
    if j is None or at is None:
        bt, bv, yy = Bt.sum(axis=0), Bv.sum(axis=0), yyv.sum(axis=0)
    else:
        nv = Bt.shape[0]
        others = np.flatnonzero(np.arange(nv) != j)
        bt = Bt[others, :, at[others]].sum(axis=0)[:, None] + Bt[j]  # (c, lags)
        bv = Bv[others, :, at[others]].sum(axis=0)[:, None] + Bv[j]
        yy = yyv[j]
    beta = Gp @ bt
    return yy - 2 * np.einsum("cl,cl->l", bv, beta) + np.einsum("cl,cd,dl->l", beta, Gv, beta)
