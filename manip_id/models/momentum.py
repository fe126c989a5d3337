"""The filtered momentum model (see the package docstring for the math).

Regressors, exactly (no finite difference)::

    Y_p(q, dq) theta = M(q) dq          (generalized momentum, armature column dq_j)
    Y_h(q, dq) theta = g(q) - C(q, dq)^T dq + tau_joint(q, dq)

Per body ``i`` with spatial velocity ``v_i`` in its joint frame and spatial
inertia ``I_i = sum_k theta_ik B_k`` (``B_k`` the 6x6 basis of the ten
dynamic parameters): ``K_i = 1/2 v_i^T I_i v_i`` gives

    dK/d dq = sum_i J_i^T I_i v_i,      dK/dq = sum_i (d v_i/dq)^T I_i v_i  (= C^T dq)

with ``J_i = d v_i/d dq`` and ``d v_i/dq`` from Pinocchio's kinematic derivatives
(``getJointVelocityDerivatives``, LOCAL frame), and ``g`` from the torque
regressor at rest. The compiled kernel (:func:`manip_id.robot.compiled_regressor.momentum_block`,
used where the torque regressor's is) evaluates the same sums for a block of samples
without them: ``d v_i/d q_j = iX_j (v_j x S_j)`` for ``j`` an ancestor-or-self of ``i``, so

    (M dq)_j = sum_i S_j^T jX*_i I_i v_i,      dK/dq_j = sum_i (v_j x S_j)^T jX*_i I_i v_i

Filter. ``F(s) = lambda/(s + lambda)`` is integrated exactly for inputs
interpolated by the cubic through the last four samples (lower degrees at the
first steps): ``y_k = a y_{k-1} + sum_j c_j x_{k-j}``, ``a = exp(-lambda dt)``,
run with :func:`scipy.signal.lfilter` over chunks.
``F[Y_p]`` starts at ``Y_p(0)``, the other filters at zero, so
``F[tau] = W theta`` with ``W = lambda (Y_p - F[Y_p]) + F[Y_h]`` holds from
the first sample on (up to the ``O(dt^4)`` interpolation error).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from functools import lru_cache

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..estimators import InformationAccumulator
from ..estimators.blocks import ScoreBlocks
from ..robot.compiled_regressor import momentum_block
from ..robot.model import Robot
from .energy import check_model_states, window_samples

_CHUNK = 1024
#: rows at least this many samples apart: the filter is evaluated at the rows only
_DECIMATE_STRIDE = 8


@lru_cache(maxsize=1)
def _inertia_basis() -> np.ndarray:
    """``B`` of shape (10, 6, 6): ``Inertia.FromDynamicParameters(pi).matrix() = sum pi_k B_k``."""
    ref = np.array([1.0, 0, 0, 0, 1.0, 0, 1.0, 0, 0, 1.0])
    m0 = pin.Inertia.FromDynamicParameters(ref).matrix()
    out = np.empty((10, 6, 6))
    for k in range(10):
        e = ref.copy()
        e[k] += 1.0
        out[k] = pin.Inertia.FromDynamicParameters(e).matrix() - m0
    return out


def momentum_regressors(robot: Robot, q, dq) -> tuple[np.ndarray, np.ndarray]:
    """``(Y_p, Y_h)`` at N samples, each of shape (N, nv, p) (module docstring).

    ``q`` [rad or m] (N, nq), ``dq`` [rad/s or m/s] (N, nv).
    ``Y_p theta = M(q) dq`` [N m s], ``Y_h theta = g(q) - C(q, dq)^T dq + tau_joint`` [N m].
    """
    q, dq, _ = check_model_states(robot, q, dq, np.zeros_like(np.asarray(dq, dtype=float)))
    return _regressors(robot, q, dq)


def _regressors(robot: Robot, q: np.ndarray, dq: np.ndarray):
    n, nv, p = q.shape[0], robot.nv, robot.n_parameters
    Yp = np.zeros((n, nv, p))
    Yh = np.zeros((n, nv, p))
    ev = robot.evaluator
    desc = ev.kernel_for(n)
    if desc is None:
        _rigid_pinocchio(robot, q, dq, Yp, Yh)
    else:  # the compiled loop over the block
        momentum_block(desc, np.ascontiguousarray(q), np.ascontiguousarray(dq), Yp, Yh)
    _add_joint_terms(robot, q, dq, Yp, Yh)
    return Yp, Yh


def _rigid_pinocchio(robot: Robot, q, dq, Yp: np.ndarray, Yh: np.ndarray) -> None:
    """The rigid columns of ``Y_p`` and ``Y_h`` with Pinocchio's kinematic derivatives,
    one call per sample (the reference path, and the fallback without the kernel)."""
    m = robot.model
    d = m.createData()
    n, nv, nb = q.shape[0], robot.nv, robot.n_bodies
    B = _inertia_basis()
    zero = np.zeros(nv)
    J = np.empty((nb, 6, nv))
    dV = np.empty((nb, 6, nv))
    V = np.empty((nb, 6))
    for k in range(n):
        pin.computeForwardKinematicsDerivatives(m, d, q[k], dq[k], zero)
        for i in range(1, nb + 1):
            dv, jac = pin.getJointVelocityDerivatives(m, d, i, pin.LOCAL)
            dV[i - 1], J[i - 1] = np.reshape(dv, (6, nv)), np.reshape(jac, (6, nv))  # nv = 1: (6,)
            V[i - 1] = d.v[i].vector
        H = np.einsum("kab,nb->nka", B, V)  # (nb, 10, 6): I(e_k) v_i
        Yp[k, :, : 10 * nb] = np.einsum("nai,nka->ink", J, H).reshape(nv, 10 * nb)
        dK = np.einsum("nai,nka->ink", dV, H).reshape(nv, 10 * nb)  # dK/dq
        Yh[k, :, : 10 * nb] = pin.computeJointTorqueRegressor(m, d, q[k], zero, zero) - dK


def _add_joint_terms(robot: Robot, q, dq, Yp: np.ndarray, Yh: np.ndarray) -> None:
    """The joint terms' columns (zero in ``Yp`` and ``Yh`` before): armature momentum in
    ``Y_p`` (``T(q, 0, dq) - T(q, 0, 0)``: ``Ia_j dq_j`` only); friction, offset and spring
    in ``Y_h`` (``T(q, dq, 0)``; the armature column 0)."""
    if not robot.terms.enabled:
        return
    ev, nr = robot.evaluator, robot.n_rigid
    zeros = np.zeros_like(dq)
    ev.fill_joint_terms(Yh, q, dq, zeros)
    ev.fill_joint_terms(Yp, q, zeros, dq)
    T0 = np.zeros(Yp.shape)  # calloc: the untouched pages cost nothing
    ev.fill_joint_terms(T0, q, zeros, zeros)
    Yp[:, :, nr:] -= T0[:, :, nr:]


#: Degree of the interpolation of the filter inputs (cubic: O(dt^4) per step).
HOLD_DEGREE = 3


def filter_weights(bandwidth: float, dt: float, degree: int) -> tuple[float, np.ndarray]:
    """``(a, c)`` of the exact first-order filter for a polynomial hold of ``degree``.

    ``y_k = a y_{k-1} + sum_{j=0}^{degree} c_j x_{k-j}`` integrates
    ``dy/dt = lambda (x - y)`` over one step ``dt`` [s] for ``x`` interpolated by the
    polynomial through ``x_{k-degree}, ..., x_k``; ``lambda = bandwidth`` [rad/s],
    ``a = exp(-lambda dt)``. The weights are integrals of the Lagrange basis against
    ``lambda exp(-lambda (dt - s))``, by 24-point Gauss-Legendre quadrature
    (exact to round-off for these smooth integrands).
    """
    lam, h = float(bandwidth), float(dt)
    x, w = np.polynomial.legendre.leggauss(24)
    s = 0.5 * h * (x + 1.0)  # in [0, h], 0 at t_{k-1}
    kern = 0.5 * h * w * lam * np.exp(-lam * (h - s))
    nodes = h * (1.0 - np.arange(degree + 1))  # x_k at h, x_{k-1} at 0, ...
    c = np.empty(degree + 1)
    for j in range(degree + 1):
        basis = np.ones_like(s)
        for m in range(degree + 1):
            if m != j:
                basis *= (s - nodes[m]) / (nodes[j] - nodes[m])
        c[j] = float(kern @ basis)
    return math.exp(-lam * h), c


class _Filter:
    """The exact first-order filter over chunks of (n, ...) arrays, state carried.

    The first samples use lower-degree holds (as many past samples as there are),
    then :func:`scipy.signal.lfilter` runs the degree-``HOLD_DEGREE`` recursion.
    """

    def __init__(self, bandwidth: float, dt: float, y0: np.ndarray):
        self.weights = [filter_weights(bandwidth, dt, d) for d in range(1, HOLD_DEGREE + 1)]
        self.a = self.weights[0][0]
        self.y = np.array(y0, dtype=float)  # last output
        self.past: list[np.ndarray] = []  # last inputs, newest first
        self.zi: np.ndarray | None = None
        self._unrolled_weights: dict[int, np.ndarray] = {}

    def __call__(self, x: np.ndarray) -> np.ndarray:
        from scipy.signal import lfilter

        out = np.empty_like(x)
        k = 0
        while k < x.shape[0] and self.zi is None:
            if not self.past:  # the first sample: the initial condition
                out[k] = self.y
            else:
                _, c = self.weights[len(self.past) - 1]
                out[k] = self.a * self.y + c[0] * x[k]
                for j, xp in enumerate(self.past, start=1):
                    out[k] += c[j] * xp
                self.y = out[k].copy()
            self.past = [x[k].copy(), *self.past][:HOLD_DEGREE]
            k += 1
            if len(self.past) == HOLD_DEGREE:
                self._init_state()
        if k < x.shape[0]:
            _, b = self.weights[-1]
            out[k:], self.zi = lfilter(b, [1.0, -self.a], x[k:], axis=0, zi=self.zi)
        return out

    def at(self, x: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The outputs at the chunk's sorted local ``rows`` only, shape (len(rows), ...).

        After the start-up, the recursion from the last output ``y_L`` to sample
        ``t = L + s`` unrolls to ``y_t = a^s y_L + sum_{d=0}^{s+H-1} w_d(s) x_{t-d}`` with
        ``w_d(s) = sum_i a^i c_{d-i}`` (``0 <= i < s``, ``0 <= d - i <= H``, ``H`` the
        hold degree): one weighted sum per row and one to the chunk's end, whose state
        (last output, last ``H`` inputs) carries on. Do not mix with ``__call__``.
        """
        c = x.shape[0]
        out = np.empty((len(rows), *x.shape[1:]))
        k0 = 0
        if self.zi is None:  # the start-up samples, one at a time
            k0 = min(c, HOLD_DEGREE - len(self.past))
            head = self(x[:k0])
            early = rows < k0
            out[early] = head[rows[early]]
        if k0 == c:
            return out
        H = HOLD_DEGREE
        ext = np.concatenate([np.stack(self.past[::-1]), x[k0:]])  # ext[e]: sample k0 - H + e
        flat = ext.reshape(ext.shape[0], -1)
        last = k0 - 1
        targets = [int(t) for t in rows if t >= k0]
        if not targets or targets[-1] != c - 1:
            targets.append(c - 1)
        y = self.y.reshape(-1)
        j = int(np.searchsorted(rows, k0))
        for t in targets:
            s = t - last
            e0 = last + 1 - k0  # ext index of sample last + 1 - H
            y = self.a**s * y + self._unrolled(s) @ flat[e0 : e0 + s + H]
            if j < len(rows) and rows[j] == t:
                out[j] = y.reshape(x.shape[1:])
                j += 1
            last = t
        self.y = y.reshape(x.shape[1:]).copy()
        self.past = [ext[ext.shape[0] - 1 - i].copy() for i in range(H)]  # newest first
        return out

    def _unrolled(self, s: int) -> np.ndarray:
        """``w`` of ``s`` unrolled steps, oldest sample first, shape (s + H,) (:meth:`at`)."""
        cache = self._unrolled_weights
        if s not in cache:
            _, c = self.weights[-1]
            H = c.size - 1
            w = np.zeros(s + H)  # w[d]: the weight of x_{t-d}
            for i in range(s):
                w[i : i + H + 1] += self.a**i * c
            cache[s] = w[::-1].copy()
        return cache[s]

    def _init_state(self) -> None:
        """Transposed direct-form state after the start-up: z_i = sum_{j>i} b_j x_{s+i-j}."""
        _, b = self.weights[-1]
        M = b.size - 1
        zi = []
        for i in range(M):
            z = self.a * self.y if i == 0 else np.zeros_like(self.y)
            for j in range(i + 1, M + 1):
                z = z + b[j] * self.past[j - i - 1]
            zi.append(z)
        self.zi = np.stack(zi)


def momentum_rows(
    robot: Robot,
    q,
    dq,
    tau,
    *,
    dt: float,
    window_length: float | None = None,
    bandwidth: float | None = None,
    chunk: int = _CHUNK,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Filtered momentum rows ``(W (n_r, nv, p), F[tau] (n_r, nv))``, chunk by chunk.

    Parameters
    ----------
    q
        positions [rad or m], shape (N, nq); dq [rad/s or m/s] and tau [N m or N], (N, nv)
    dt
        sample time [s] (uniform sampling)
    window_length
        spacing of the rows [s] (default :data:`~manip_id.models.DEFAULT_WINDOW`):
        samples ``k = s, 2 s, ...`` with ``s = round(window_length / dt)``
    bandwidth
        lambda of the filter [rad/s]; default ``3 / window_length``
    chunk
        samples per regressor chunk
    """
    q, dq, tau = check_model_states(robot, q, dq, tau)
    stride = window_samples(window_length, dt, even=False)
    lam = 3.0 / (stride * float(dt)) if bandwidth is None else float(bandwidth)
    if not (math.isfinite(lam) and lam > 0):
        raise InputError(f"bandwidth must be a positive filter bandwidth [rad/s], got {bandwidth}")
    n = q.shape[0]
    if n <= stride:
        raise InputError(
            f"{n} samples give no momentum row every {stride} samples: shorten window_length"
        )
    filters: tuple[_Filter, _Filter] | None = None
    for start in range(0, n, int(chunk)):
        stop = min(start + int(chunk), n)
        Yp, Yh = _regressors(robot, q[start:stop], dq[start:stop])
        Yh -= lam * Yp  # W = lam Y_p + F[Y_h - lam Y_p], its filter starting at -lam Y_p(0)
        if filters is None:  # F[Y_p] starts at Y_p(0), F[Y_h] and F[tau] at zero
            filters = (_Filter(lam, dt, -lam * Yp[0]), _Filter(lam, dt, np.zeros(robot.nv)))
        keep = np.arange(start, stop)
        keep = keep[(keep % stride == 0) & (keep > 0)] - start
        fx, ft = filters
        if stride < _DECIMATE_STRIDE:  # rows at (almost) every sample: filter them all
            Fx, Ft = fx(Yh)[keep], ft(tau[start:stop])[keep]
        else:  # only the rows' outputs, the states carried between them
            Fx, Ft = fx.at(Yh, keep), ft.at(tau[start:stop], keep)
        if keep.size:
            yield lam * Yp[keep] + Fx, Ft


def accumulate_momentum(
    robot: Robot,
    q,
    dq,
    tau,
    *,
    dt: float,
    window_length: float | None = None,
    columns=None,
    blocks: ScoreBlocks | None = None,
) -> InformationAccumulator:
    """The momentum rows' information on ``columns`` (default all), per joint (``nv`` outputs);
    with ``blocks`` (empty) also per block of consecutive rows. The rows are
    :func:`momentum_rows` at its default filter bandwidth (the same keywords as
    :func:`~manip_id.models.energy.accumulate_energy`, so the two are interchangeable)."""
    cols = np.arange(robot.n_parameters) if columns is None else np.asarray(columns, np.intp)
    acc = InformationAccumulator(cols.size, robot.nv, blocks=False if blocks is None else blocks)
    for W, z in momentum_rows(robot, q, dq, tau, dt=dt, window_length=window_length):
        acc.add(W, z, columns=cols, check=False)
    return acc
