"""The delay of a file's torque stream behind its motion stream, by cross-validation."""

from __future__ import annotations

import numpy as np

from ..robot.regressor import regressor

#: Rows of the motion stream the delay search fits (evenly spaced over the file).
LAG_ROWS = 12000
#: Rows per block of the two interleaved halves of the delay search's cross-validation.
LAG_BLOCK = 200


def stream_lags(robot, proc, eps: float, max_lag: int, gains: np.ndarray):
    """``(common, gain, own)``: the lag [samples] of the whole torque stream, the share of
    the held-out error it removes against lag 0, and per joint the lag of its own torque
    (the others at the common lag); lags are None when not determined.

    The lag is the one whose torques (each divided by its scale at lag 0) one rigid-body
    model predicts best on held-out rows. The scales start from ``gains`` (against the
    nominal model) and are refined at lag 0 against the model itself (:func:`own_scales`):
    a payload the nominal model lacks biases the nominal scales joint by joint (1.25-1.5 on
    a simulated 2 kg ur5 payload), and a lag then passed for the difference (a false 13 ms
    delay on exactly synchronous logs).
    The model is the robot's full regressor with parameters shared by all joints, plus
    per joint ``dq_j``, ``sgn_eps(dq_j)`` and 1 (friction, offset). The rows are cut into
    two interleaved halves of :data:`LAG_BLOCK` rows; the parameters fitted on one half
    for lags ``L`` (``beta = G^+ b``, ``G = sum_j Y_j^T Y_j`` fixed by the motion stream,
    ``b = sum_j Y_j^T tau_j[k + L_j]``) predict the other, and the two prediction errors
    add up (two-fold cross-validation: an in-sample residual lets the lag fit the model's
    own errors). The common lag is swept for all joints at once, on a grid of ``g =
    max_lag // COARSE`` samples and then sample by sample around the best, and refined to
    a sub-sample by the parabola through the neighbours of the best lag. Each joint's own
    lag (informative only) is swept on the coarse grid with the others held at the common
    lag, refined the same way.
    """
    n, nv = proc.n_samples, robot.nv
    if max_lag < 1:
        return None, 0.0, [None] * nv
    k = np.arange(max_lag, n - max_lag)
    k = k[:: max(1, k.size // LAG_ROWS)]
    half = (np.arange(k.size) // LAG_BLOCK) % 2 == 0
    n0 = int(half.sum())
    # the rows of the first half, then the second: each half a contiguous view
    Y = _columns(robot, proc, np.concatenate([k[half], k[~half]]), eps)
    gains = own_scales(Y, proc.tau[np.concatenate([k[half], k[~half]])], gains)
    tau = proc.tau / gains  # currents and flipped signs undone: one model fits all joints
    g = max(1, max_lag // COARSE)
    coarse = np.arange(-(max_lag // g), max_lag // g + 1) * g  # holds lag 0
    masks = (half, ~half)
    halves = [Y[:n0], Y[n0:]]
    grams = [gram(Ym) for Ym in halves]
    parts = [
        lag_sums(Ym, tau, k[m], coarse, gm) for Ym, m, gm in zip(halves, masks, grams, strict=True)
    ]
    curve = _both(parts, None, None)  # the held-out SSE of all joints
    zero = float(curve[coarse.size // 2])
    best = int(coarse[int(np.argmin(curve))])
    fine = np.arange(max(best - g, -max_lag), min(best + g, max_lag) + 1)
    fine_parts = [
        lag_sums(Ym, tau, k[m], fine, gm) for Ym, m, gm in zip(halves, masks, grams, strict=True)
    ]
    fine_curve = _both(fine_parts, None, None)
    v = vertex(fine_curve)
    common = None if v is None else float(fine[0] + v)
    gain = float((zero - fine_curve.min()) / zero) if zero > 0 else 0.0
    at = np.full(nv, int(np.argmin(np.abs(coarse - (0 if common is None else common)))))
    own = []
    for j in range(nv):
        w = vertex(_both(parts, j, at))
        own.append(None if w is None else float(coarse[0] + w * g))
    return common, gain, own


#: Lags on each side of zero in the coarse sweep of the delay search.
COARSE = 20
#: Rows per call of the regressor in the delay search's columns.
COLUMN_BLOCK = 2000


#: Alternations of :func:`own_scales`.
SCALE_ROUNDS = 20


def own_scales(Y: np.ndarray, tau: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """Per-joint scales ``g_j`` with ``tau_j ~ g_j Y_j beta`` for one ``beta`` shared by the
    joints, at lag 0: least squares in ``beta`` and in ``g`` by turns from ``gains``, shape
    (nv,). ``Y``: regressor rows (N, nv, c); ``tau``: their torques (N, nv). The overall
    factor (``beta c``, ``g / c``) is fixed by keeping the geometric mean of ``|gains|``."""
    g = np.asarray(gains, dtype=float).copy()
    flat = Y.reshape(-1, Y.shape[2])
    Gp = np.linalg.pinv(flat.T @ flat, rcond=1e-10, hermitian=True)
    for _ in range(SCALE_ROUNDS):
        beta = Gp @ np.einsum("njc,nj->c", Y, tau / g)
        pred = np.einsum("njc,c->nj", Y, beta)
        den = np.einsum("nj,nj->j", pred, pred)
        num = np.einsum("nj,nj->j", tau, pred)
        new = np.where(den > 0, num / np.where(den > 0, den, 1.0), g)
        if not np.all(np.isfinite(new)) or np.any(new == 0):
            return np.asarray(gains, dtype=float)
        new *= np.exp(np.mean(np.log(np.abs(gains))) - np.mean(np.log(np.abs(new))))
        if np.allclose(new, g, rtol=1e-6):
            return new
        g = new
    return g


def _columns(robot, proc, k: np.ndarray, eps: float) -> np.ndarray:
    """The regressor rows ``k`` with per-joint friction and offset columns, each column
    scaled to unit norm (zero columns dropped), shape (N', nv, c). The regressor is
    evaluated in blocks of :data:`COLUMN_BLOCK` rows twice, for the column norms and
    then into the one array returned (the rows' full regressor is never held twice)."""
    nv = robot.nv
    F = np.zeros((k.size, nv, 3 * nv))
    for j in range(nv):
        dq = proc.dq[k, j]
        F[:, j, 3 * j : 3 * j + 3] = np.column_stack(
            [dq, np.where(np.abs(dq) >= eps, np.sign(dq), 0.0), np.ones(k.size)]
        )
    blocks = [k[s : s + COLUMN_BLOCK] for s in range(0, k.size, COLUMN_BLOCK)]
    sq = sum(np.einsum("njc,njc->c", R, R) for R in _blocks(robot, proc, blocks))
    norm = np.sqrt(np.concatenate([sq, np.einsum("njc,njc->c", F, F)]))
    keep = norm > 0
    p = norm.size - 3 * nv
    cols = np.flatnonzero(keep[:p])
    out = np.empty((k.size, nv, int(keep.sum())))
    s = 0
    for R in _blocks(robot, proc, blocks):
        out[s : s + R.shape[0], :, : cols.size] = R[:, :, cols]
        s += R.shape[0]
    out[:, :, cols.size :] = F[:, :, keep[p:]]
    out /= norm[keep]
    return out


def _blocks(robot, proc, blocks):
    """The regressor of each block of rows, shape (rows, nv, p) each."""
    for b in blocks:
        yield regressor(robot, proc.q[b], proc.dq[b], proc.ddq[b])


def _both(parts, j: int | None, at: np.ndarray | None) -> np.ndarray:
    """The two-fold cross-validated prediction error (see :func:`held_out`)."""
    return held_out(parts[0], parts[1], j, at) + held_out(parts[1], parts[0], j, at)


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


def gram(Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(G, G^+)`` with ``G = sum_j Y_j^T Y_j`` of regressor rows Y, shape (N, nv, c)."""
    flat = Y.reshape(-1, Y.shape[2])
    G = flat.T @ flat
    return G, np.linalg.pinv(G, rcond=1e-10, hermitian=True)


def lag_sums(Y: np.ndarray, tau: np.ndarray, k: np.ndarray, sweep: np.ndarray, grams):
    """``(G, G^+, B, yy)`` of rows ``k`` (``grams``: their :func:`gram`):
    ``B[j, :, i] = Y_j^T tau_j[k + sweep_i]``, ``yy[j, i] = ||tau_j[k + sweep_i]||^2``."""
    nv = Y.shape[1]
    idx = k[:, None] + sweep[None, :]
    B = np.stack([np.ascontiguousarray(Y[:, j, :].T) @ tau[idx, j] for j in range(nv)])
    yy = np.stack([np.sum(tau[idx, j] ** 2, axis=0) for j in range(nv)])
    return grams[0], grams[1], B, yy


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
    return yy - 2 * np.einsum("cl,cl->l", bv, beta) + np.einsum("cl,cl->l", beta, Gv @ beta)
