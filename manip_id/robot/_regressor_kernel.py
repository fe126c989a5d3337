"""numba kernels of :mod:`manip_id.robot.compiled_regressor` (imported only with numba).

The math and conventions are in :mod:`manip_id.robot.compiled_regressor`. Four kernels: the
forward pass of one sample (placements, velocities, accelerations of every joint frame),
the body regressor A(v, a) of one body, and the block loop that projects each body's
A through its chain of ancestors; and the momentum loop of
:mod:`manip_id.models.momentum`. Compiled code is cached on disk (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np

REVOLUTE = 0
PRISMATIC = 1
UNBOUNDED = 2


@numba.njit(cache=True, inline="always")
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@numba.njit(cache=True)
def _forward(tree, q, dq, ddq, work):
    """Joint placements R (n,3,3), P (n,3) and spatial v, a (n,6) of one sample.

    ``tree``: the model's arrays (:func:`block`); ``work``: ``(R, P, V, A, S)``, the
    outputs and a scratch ``S`` of shape (6, 3).
    """
    parent, kind, axis, rot0, pos0, idx_q, idx_v, gravity = tree
    R, P, V, A, S = work
    n = parent.shape[0]
    RJ = S[:3]
    tmp = S[3]
    lin = S[4]
    ang = S[5]
    for i in range(n):
        u = axis[i]
        x = q[idx_q[i]]
        if kind[i] == PRISMATIC:
            c, s = 1.0, 0.0
        elif kind[i] == UNBOUNDED:
            c, s = x, q[idx_q[i] + 1]
        else:
            c, s = np.cos(x), np.sin(x)
        # Rodrigues: R_J = c I + s [u]x + (1 - c) u u^T
        for r in range(3):
            for k in range(3):
                RJ[r, k] = (1.0 - c) * u[r] * u[k]
            RJ[r, r] += c
        RJ[0, 1] -= s * u[2]
        RJ[0, 2] += s * u[1]
        RJ[1, 0] += s * u[2]
        RJ[1, 2] -= s * u[0]
        RJ[2, 0] -= s * u[1]
        RJ[2, 1] += s * u[0]
        for r in range(3):
            for k in range(3):
                R[i, r, k] = (
                    rot0[i, r, 0] * RJ[0, k] + rot0[i, r, 1] * RJ[1, k] + rot0[i, r, 2] * RJ[2, k]
                )
            P[i, r] = pos0[i, r]
            if kind[i] == PRISMATIC:
                P[i, r] += x * (rot0[i, r, 0] * u[0] + rot0[i, r, 1] * u[1] + rot0[i, r, 2] * u[2])
        p = parent[i]
        # the parent's motion carried into this frame: v_lin = R^T (vp_lin - P x vp_ang)
        for field in range(2):  # 0: velocity, 1: acceleration
            src = V if field == 0 else A
            if p < 0:
                for r in range(3):
                    lin[r] = -gravity[r] if field == 1 else 0.0
                    ang[r] = 0.0
            else:
                for r in range(3):
                    lin[r] = src[p, r]
                    ang[r] = src[p, 3 + r]
            _cross(P[i], ang, tmp)
            for r in range(3):
                lin[r] -= tmp[r]
            for r in range(3):
                src[i, r] = R[i, 0, r] * lin[0] + R[i, 1, r] * lin[1] + R[i, 2, r] * lin[2]
                src[i, 3 + r] = R[i, 0, r] * ang[0] + R[i, 1, r] * ang[1] + R[i, 2, r] * ang[2]
        qd = dq[idx_v[i]]
        qdd = ddq[idx_v[i]]
        off = 0 if kind[i] == PRISMATIC else 3
        for r in range(3):
            V[i, off + r] += u[r] * qd
        # a += S ddq + v x (S dq); motion cross (v, w) x (m, n) = (w x m + v x n, w x n)
        for r in range(3):
            lin[r] = u[r] * qd if kind[i] == PRISMATIC else 0.0
            ang[r] = 0.0 if kind[i] == PRISMATIC else u[r] * qd
        _cross(V[i, 3:], lin, tmp)
        for r in range(3):
            A[i, r] += tmp[r]
        _cross(V[i, :3], ang, tmp)
        for r in range(3):
            A[i, r] += tmp[r]
        _cross(V[i, 3:], ang, tmp)
        for r in range(3):
            A[i, 3 + r] += tmp[r]
            A[i, off + r] += u[r] * qdd


@numba.njit(cache=True)
def _axes(parent, kind, axis, R, P, T):
    """T[i, j]: the motion axis S_j of every ancestor-or-self joint j, in frame i (6,)."""
    n = parent.shape[0]
    for i in range(n):
        off = 0 if kind[i] == PRISMATIC else 3
        for r in range(6):
            T[i, i, r] = 0.0
        for r in range(3):
            T[i, i, off + r] = axis[i, r]
        j = parent[i]
        p = j
        while j >= 0:
            # motion from the parent's frame: lin = R^T (lin_p - P x ang_p), ang = R^T ang_p
            src = T[p, j]
            l0 = src[0] - (P[i, 1] * src[5] - P[i, 2] * src[4])
            l1 = src[1] - (P[i, 2] * src[3] - P[i, 0] * src[5])
            l2 = src[2] - (P[i, 0] * src[4] - P[i, 1] * src[3])
            for r in range(3):
                T[i, j, r] = R[i, 0, r] * l0 + R[i, 1, r] * l1 + R[i, 2, r] * l2
                T[i, j, 3 + r] = R[i, 0, r] * src[3] + R[i, 1, r] * src[4] + R[i, 2, r] * src[5]
            j = parent[j]


@numba.njit(cache=True, inline="always")
def _project(s, v, a, y):
    """y (10,) = s^T A(v, a): body force regressor projected on the motion axis s (6,).

    With ``ac = a_lin + w x v_lin``: m -> s_lin . ac; h -> -alpha x s_lin + w x (w x s_lin)
    + ac x s_ang; I -> s_ang^T I alpha + (s_ang x w)^T I w (I symmetric, six entries).
    """
    w0, w1, w2 = v[3], v[4], v[5]
    c0 = a[0] + w1 * v[2] - w2 * v[1]
    c1 = a[1] + w2 * v[0] - w0 * v[2]
    c2 = a[2] + w0 * v[1] - w1 * v[0]
    x0, x1, x2 = a[3], a[4], a[5]
    l0, l1, l2, g0, g1, g2 = s[0], s[1], s[2], s[3], s[4], s[5]
    y[0] = l0 * c0 + l1 * c1 + l2 * c2
    # w x s_lin
    u0 = w1 * l2 - w2 * l1
    u1 = w2 * l0 - w0 * l2
    u2 = w0 * l1 - w1 * l0
    y[1] = -(x1 * l2 - x2 * l1) + (w1 * u2 - w2 * u1) + (c1 * g2 - c2 * g1)
    y[2] = -(x2 * l0 - x0 * l2) + (w2 * u0 - w0 * u2) + (c2 * g0 - c0 * g2)
    y[3] = -(x0 * l1 - x1 * l0) + (w0 * u1 - w1 * u0) + (c0 * g1 - c1 * g0)
    # b = s_ang x w
    b0 = g1 * w2 - g2 * w1
    b1 = g2 * w0 - g0 * w2
    b2 = g0 * w1 - g1 * w0
    y[4] = g0 * x0 + b0 * w0
    y[5] = g0 * x1 + g1 * x0 + b0 * w1 + b1 * w0
    y[6] = g1 * x1 + b1 * w1
    y[7] = g0 * x2 + g2 * x0 + b0 * w2 + b2 * w0
    y[8] = g1 * x2 + g2 * x1 + b1 * w2 + b2 * w1
    y[9] = g2 * x2 + b2 * w2


@numba.njit(cache=True)
def block(tree, q, dq, ddq, out):
    """Y_rigid of every sample of the block into ``out`` (N, nv, >= 10 n), in place.

    ``tree = (parent, kind, axis, rot0, pos0, idx_q, idx_v, gravity)``: the arrays of
    :class:`~manip_id.robot.compiled_regressor.CompiledModel`, gravity as used (zero for the
    gravity-free model).
    """
    parent, kind, axis, _, _, _, idx_v, _ = tree
    n = parent.shape[0]
    R = np.empty((n, 3, 3))
    P = np.empty((n, 3))
    V = np.empty((n, 6))
    A = np.empty((n, 6))
    T = np.empty((n, n, 6))
    work = (R, P, V, A, np.empty((6, 3)))
    y = np.empty(10)
    for k in range(q.shape[0]):
        _forward(tree, q[k], dq[k], ddq[k], work)
        _axes(parent, kind, axis, R, P, T)
        Y = out[k]
        for row in range(Y.shape[0]):
            for c in range(10 * n):
                Y[row, c] = 0.0
        for i in range(n):
            j = i
            while j >= 0:
                _project(T[i, j], V[i], A[i], y)
                row = idx_v[j]
                for c in range(10):
                    Y[row, 10 * i + c] = y[c]
                j = parent[j]


@numba.njit(cache=True, inline="always")
def _momentum_columns(s, v, y):
    """y (10,) = s^T B_k v for the ten parameters k (``B_k`` Pinocchio's spatial inertia
    of parameter k): ``m -> s_lin . v_lin``, ``mc -> v_lin x s_ang - v_ang x s_lin``,
    ``I -> s_ang^T E_k v_ang`` (six symmetric entries)."""
    l0, l1, l2, w0, w1, w2 = v[0], v[1], v[2], v[3], v[4], v[5]
    a0, a1, a2, g0, g1, g2 = s[0], s[1], s[2], s[3], s[4], s[5]
    y[0] = a0 * l0 + a1 * l1 + a2 * l2
    y[1] = (l1 * g2 - l2 * g1) - (w1 * a2 - w2 * a1)
    y[2] = (l2 * g0 - l0 * g2) - (w2 * a0 - w0 * a2)
    y[3] = (l0 * g1 - l1 * g0) - (w0 * a1 - w1 * a0)
    y[4] = g0 * w0
    y[5] = g0 * w1 + g1 * w0
    y[6] = g1 * w1
    y[7] = g0 * w2 + g2 * w0
    y[8] = g1 * w2 + g2 * w1
    y[9] = g2 * w2


@numba.njit(cache=True)
def momentum(tree, q, dq, out_p, out_h):
    """The rigid momentum regressors of every sample into ``out_p`` and ``out_h``.

    ``out_p[k] = Y_p(q_k, dq_k)`` (``Y_p theta = M dq``) and ``out_h[k] = g(q_k) - dK/dq``
    (``dK/dq = C^T dq``), both (N, nv, >= 10 n), rigid columns written (the others
    untouched). Per body ``i`` and ancestor-or-self joint ``j``, with ``v_j`` carried to
    frame ``i`` (:mod:`manip_id.models.momentum`)::

        Y_p[j, 10 i + k] = S_j^T B_k v_i,     dK/dq_j = (v_j x S_j)^T B_k v_i

    and ``g`` the torque regressor at rest (:func:`_project` of the gravity pass).
    """
    parent, kind, axis, _, _, _, idx_v, _ = tree
    n = parent.shape[0]
    R = np.empty((n, 3, 3))
    P = np.empty((n, 3))
    V = np.empty((n, 6))
    A = np.empty((n, 6))
    G = np.empty((n, 6))
    T = np.empty((n, n, 6))
    work = (R, P, V, A, np.empty((6, 3)))
    zero = np.zeros(dq.shape[1])
    rest = np.zeros(6)
    yp = np.empty(10)
    yh = np.empty(10)
    yg = np.empty(10)
    u = np.empty(6)
    c = np.empty(6)
    for k in range(q.shape[0]):
        _forward(tree, q[k], zero, zero, work)  # at rest: A = the gravity pass
        G[:, :] = A
        _forward(tree, q[k], dq[k], zero, work)
        _axes(parent, kind, axis, R, P, T)
        Yp = out_p[k]
        Yh = out_h[k]
        for row in range(Yp.shape[0]):
            for col in range(10 * n):
                Yp[row, col] = 0.0
                Yh[row, col] = 0.0
        for i in range(n):
            for r in range(6):
                u[r] = V[i, r]  # v_j in frame i, from j = i up to the root
            j = i
            while j >= 0:
                s = T[i, j]
                # motion cross (v, w) x (m, n) = (w x m + v x n, w x n): c = u x s
                c[0] = u[4] * s[2] - u[5] * s[1] + u[1] * s[5] - u[2] * s[4]
                c[1] = u[5] * s[0] - u[3] * s[2] + u[2] * s[3] - u[0] * s[5]
                c[2] = u[3] * s[1] - u[4] * s[0] + u[0] * s[4] - u[1] * s[3]
                c[3] = u[4] * s[5] - u[5] * s[4]
                c[4] = u[5] * s[3] - u[3] * s[5]
                c[5] = u[3] * s[4] - u[4] * s[3]
                _momentum_columns(s, V[i], yp)
                _momentum_columns(c, V[i], yh)
                _project(s, rest, G[i], yg)
                row = idx_v[j]
                for b in range(10):
                    Yp[row, 10 * i + b] = yp[b]
                    Yh[row, 10 * i + b] = yg[b] - yh[b]
                qd = dq[k, row]
                for r in range(6):
                    u[r] -= s[r] * qd
                j = parent[j]


def build():
    """The block kernel (compiled on first call, then loaded from numba's cache)."""
    return block


def build_momentum():
    """The momentum kernel (compiled on first call, then loaded from numba's cache)."""
    return momentum
