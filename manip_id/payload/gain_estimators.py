"""Estimators of the drive-gain system from its sums: maximum likelihood, TLS, a presence test.

The system ``[D(i), -X] [g; theta] = c`` (``D(i)`` the currents on the diagonal,
``X`` the robot's base and the payload's unknown columns, ``c`` the known payload
torque) is accumulated once (:class:`~manip_id.estimators.InformationAccumulator`);
everything here works on those sums without another pass over the data:
:func:`ml_gains` (maximum likelihood under current noise), :func:`tls` (total least
squares) and :func:`check_payload_present` (do the loaded runs show the payload).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError, InputError
from ..estimators import InformationAccumulator
from ..estimators.uncertainty import HacEstimate, sandwich_covariance


def check_payload_present(
    acc: InformationAccumulator, nv: int, determined: np.ndarray, dof_names, z_min: float = 5.0
) -> None:
    """Refuse loaded runs that show no payload: free its torque's scale ``s`` and test it.

    The homogeneous system ``[D(i), -X, -c] [g; theta; s] = 0`` (``c`` the known payload
    torque) with the best-informed determined gain fixed to 1 is solved for the rest;
    the loaded runs carry the payload when ``s`` (``1/g_ref`` in truth) is at least
    ``z_min`` standard deviations from zero. All sums come from ``acc``.
    """
    if not determined.any():
        return
    A, b, zz = acc.A, acc.b, acc.zz
    p = acc.p
    G = np.zeros((p + 1, p + 1))  # Gram of [D(i), -X, -c]
    G[:p, :p] = A
    G[:p, p] = G[p, :p] = -b
    G[p, p] = zz
    diag = np.diag(A)[:nv]
    ref = int(np.flatnonzero(determined)[np.argmax(diag[determined])])
    rest = np.array([k for k in range(p + 1) if k != ref])
    Arr = G[np.ix_(rest, rest)]
    brr = -G[rest, ref]
    d = np.sqrt(np.maximum(np.diag(Arr), 0.0))
    d = np.where(d > 0, d, 1.0)
    Ainv = np.linalg.pinv(Arr / np.outer(d, d), hermitian=True) / np.outer(d, d)
    x = Ainv @ brr
    rss = max(G[ref, ref] - 2.0 * brr @ x + x @ Arr @ x, 0.0)
    dof = max(acc.n_rows - np.linalg.matrix_rank(Arr / np.outer(d, d), hermitian=True), 1)
    s, s_std = float(x[-1]), float(np.sqrt(max(rss / dof * Ainv[-1, -1], 0.0)))
    if s_std == 0.0 and s != 0.0:
        return
    if not abs(s) > z_min * s_std:
        raise DataError(
            "the loaded runs carry no payload information: with the gain of "
            f"{dof_names[ref]} fixed, the payload's torque scale comes out {s:.3g} +- "
            f"{s_std:.2g}, not distinguishable from zero; were the loaded runs recorded "
            "with the payload mounted, and is the payload's frame right?"
        )


@dataclass(frozen=True)
class _CurrentSums:
    """The sums of the per-joint current residual ``||e_j||^2`` (see :func:`ml_gains`).

    ``S_j = X~_j^T X~_j`` (nv, m+1, m+1), ``s_j = X~_j^T i_j`` (nv, m+1) and ``ii_j =
    i_j . i_j`` (nv,), ``X~ = [X, c]``, all blocks of the OLS accumulator.
    """

    S: np.ndarray
    s: np.ndarray
    ii: np.ndarray
    nv: int
    m: int

    @classmethod
    def from_accumulator(cls, acc: InformationAccumulator, nv: int) -> _CurrentSums:
        return cls.from_sums(acc.A_joint, acc.b_joint, acc.zz_joint, nv)

    @classmethod
    def from_sums(cls, A, b, zz, nv: int) -> _CurrentSums:
        """From per-joint sums ``A_j`` (nv, p, p), ``b_j`` (nv, p), ``zz_j`` (nv,)."""
        m = A.shape[-1] - nv
        S = np.empty((nv, m + 1, m + 1))
        s = np.empty((nv, m + 1))
        ii = np.empty(nv)
        for j in range(nv):
            S[j, :m, :m] = A[j, nv:, nv:]
            S[j, :m, m] = S[j, m, :m] = -b[j, nv:]
            S[j, m, m] = zz[j]
            s[j, :m] = -A[j, nv:, j]
            s[j, m] = b[j, j]
            ii[j] = A[j, j, j]
        return cls(S, s, ii, nv, m)

    @property
    def p(self) -> int:
        return self.nv + self.m

    def rss(self, k: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """``||e_j||^2`` per joint at ``k = 1/g`` and ``theta``, shape (nv,) [A^2]."""
        tt = np.r_[theta, 1.0]
        St = self.S @ tt  # (nv, m + 1)
        return np.maximum(self.ii - 2.0 * k * (self.s @ tt) + k**2 * (St @ tt), 0.0)

    def normal(self, k: np.ndarray, theta: np.ndarray, w: np.ndarray):
        """Gauss-Newton's ``(H, grad)`` of ``sum_j w_j ||e_j||^2 / 2`` in ``[k, theta]``."""
        S, s, nv, m, p = self.S, self.s, self.nv, self.m, self.p
        tt = np.r_[theta, 1.0]
        St = S @ tt
        H = np.zeros((p, p))
        grad = np.zeros(p)
        for j in range(nv):
            H[j, j] = w[j] * tt @ St[j]
            H[j, nv:] = H[nv:, j] = w[j] * k[j] * St[j, :m]
            H[nv:, nv:] += w[j] * k[j] ** 2 * S[j, :m, :m]
            grad[j] = -w[j] * (s[j] @ tt - k[j] * (tt @ St[j]))
            grad[nv:] += -w[j] * k[j] * (s[j, :m] - k[j] * St[j, :m])
        return H, grad


def _scaled_solve(H: np.ndarray, grad: np.ndarray, free: np.ndarray, lam: float) -> np.ndarray:
    """The Levenberg step on the ``free`` parameters (Jacobi-scaled, damping ``lam``)."""
    Hf, gf = H[np.ix_(free, free)], grad[free]
    dg = np.diag(Hf)
    d = np.where(dg > 0, np.sqrt(np.where(dg > 0, dg, 1.0)), 1.0)
    stepf = -np.linalg.solve(Hf / np.outer(d, d) + lam * np.eye(free.size), gf / d) / d
    step = np.zeros(H.shape[0])
    step[free] = stepf
    return step


def _descend(cs: _CurrentSums, k, theta, w, free, max_iter: int, tol: float):
    """Damped Gauss-Newton on ``sum_j w_j ||e_j||^2`` at fixed weights: ``(k, theta, its)``."""
    nv = cs.nv
    cost = float(w @ cs.rss(k, theta))
    lam = 1e-6
    iters = 0
    for _ in range(int(max_iter)):
        iters += 1
        H, grad = cs.normal(k, theta, w)
        step = None
        while lam < 1e12:
            try:
                step = _scaled_solve(H, grad, free, lam)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            new = float(w @ cs.rss(k + step[:nv], theta + step[nv:]))
            if new <= cost:
                break
            lam *= 10.0
            step = None
        if step is None:
            break
        k, theta = k + step[:nv], theta + step[nv:]
        done = cost - new <= tol * max(cost, 1e-300)
        cost = new
        lam = max(lam / 10.0, 1e-12)
        if done:
            break
    return k, theta, iters


def ml_gains(
    acc: InformationAccumulator,
    nv: int,
    x0: np.ndarray,
    n_rows: np.ndarray,
    active: np.ndarray | None = None,
    *,
    reweight: int = 3,
    max_iter: int = 100,
    tol: float = 1e-13,
) -> tuple[np.ndarray, np.ndarray, float, str]:
    """Maximum likelihood under current noise: residuals in current units, from the sums.

    With ``k_j = 1/g_j`` and the torque model ``tau_j = X_j theta + c_j`` (``X`` the
    base and unknown payload columns, ``c`` the known payload torque), the current
    residual ``e_j = i_j - k_j (X_j theta + c_j)`` of every joint has, with
    ``theta~ = [theta; 1]`` and ``X~ = [X, c]``::

        ||e_j||^2 = i_j.i_j - 2 k_j (X~_j^T i_j).theta~ + k_j^2 theta~^T X~_j^T X~_j theta~

    All these sums are blocks of the OLS accumulator of ``[D(i), -X] x = c``, so
    Gauss-Newton (Levenberg-damped) on ``sum_j w_j ||e_j||^2`` needs no data pass;
    ``w_j = 1/sigma_j^2`` are re-estimated from the residuals ``reweight`` times.
    Unlike OLS, whose regressor holds the noisy currents (an errors-in-variables
    problem: the gains shrink by about ``sigma_i^2 / mean(i^2)``), this is unbiased at
    low current-to-noise ratios. Joints not ``active`` (gains the data do not determine)
    keep their start and their rows stay out of the cost; directions without
    information do not move (damped steps). Returns ``(x = [g, theta], covariance,
    sigma2 [A^2], description)``; the covariance is ``(J^T W J)^+`` mapped to ``g`` by
    ``dg/dk = -g^2``.
    """
    active = np.ones(nv, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    cs = _CurrentSums.from_accumulator(acc, nv)
    p, m = cs.p, cs.m
    k = np.where(active, 1.0 / np.where(active, x0[:nv], 1.0), 0.0)
    theta = x0[nv:].copy()
    free = np.r_[np.flatnonzero(active), nv + np.arange(m)]  # parameters that move
    dof_j = np.maximum(n_rows - p / nv, 1.0)
    floor = (1e-9) ** 2 * cs.ii / np.maximum(n_rows, 1)
    w = active.astype(float)
    iters = 0
    for _ in range(max(int(reweight), 1) + 1):
        k, theta, its = _descend(cs, k, theta, w, free, max_iter, tol)
        iters += its
        var = np.maximum(cs.rss(k, theta) / dof_j, np.maximum(floor, 1e-300))
        w = np.where(active, 1.0 / var, 0.0)
    cov = _ml_covariance(cs, k, theta, w, free, active)
    kk = np.where(active, k, 1.0)
    g = np.where(active, 1.0 / kk, x0[:nv])
    res = cs.rss(k, theta)[active]
    sigma2 = float(res.sum() / max(int(n_rows[active].sum()) - free.size, 1))
    what = (
        f"ML in current units (Gauss-Newton on sum_j ||i_j - (X_j theta + c_j) / g_j||^2 / "
        f"sigma_j^2 from the sums, {iters} iterations)"
    )
    return np.r_[g, theta], cov, sigma2, what


def _scaled_pinv(Hf: np.ndarray) -> np.ndarray:
    """``Hf^+`` computed on the Jacobi-scaled matrix."""
    dg = np.diag(Hf)
    d = np.where(dg > 0, np.sqrt(np.where(dg > 0, dg, 1.0)), 1.0)
    return np.linalg.pinv(Hf / np.outer(d, d), hermitian=True) / np.outer(d, d)


def _ml_covariance(cs: _CurrentSums, k, theta, w, free, active, meat=None) -> np.ndarray:
    """``(J^T W J)^+`` on the free parameters (``H^+ meat(H^+) H^+`` with ``meat``, a
    function of the bread giving the sandwiched covariance), mapped from ``k`` to ``g``
    by ``dg/dk = -1/k^2``."""
    p, nv = cs.p, cs.nv
    H, _ = cs.normal(k, theta, w)
    Hinv = _scaled_pinv(H[np.ix_(free, free)])
    cov_xi = np.zeros((p, p))
    cov_xi[np.ix_(free, free)] = Hinv if meat is None else meat(Hinv)
    Jt = np.eye(p)
    kk = np.where(active, k, 1.0)
    Jt[np.arange(nv), np.arange(nv)] = -1.0 / kk**2
    cov = Jt @ cov_xi @ Jt.T
    return 0.5 * (cov + cov.T)


def tls(acc: InformationAccumulator) -> np.ndarray:
    """Total least squares of ``W x ~ y`` from its sums: ``C = [W y]^T [W y]``, scaled."""
    A, b, zz = acc.A, acc.b, acc.zz
    C = np.block([[A, b[:, None]], [b[None, :], np.array([[zz]])]])
    d = np.sqrt(np.maximum(np.diag(C), 0.0))
    d = np.where(d > 0, d, 1.0)
    Cs = C / np.outer(d, d)
    w, V = np.linalg.eigh(0.5 * (Cs + Cs.T))
    v = V[:, 0] / d
    if v[-1] == 0:
        raise InputError("total least squares found no solution with the known payload scale")
    return -v[:-1] / v[-1]


def ml_weights(acc: InformationAccumulator, nv: int, x: np.ndarray, n_rows, active) -> tuple:
    """``(k, theta, w, free)`` of an ML estimate ``x = [g, theta]``: ``k = 1/g``, the final
    weights ``w_j = 1 / sigma_j^2`` of :func:`ml_gains` and the parameters that moved."""
    active = np.asarray(active, dtype=bool)
    cs = _CurrentSums.from_accumulator(acc, nv)
    k = np.where(active, 1.0 / np.where(active, x[:nv], 1.0), 0.0)
    theta = x[nv:]
    dof_j = np.maximum(np.asarray(n_rows, dtype=float) - cs.p / nv, 1.0)
    floor = (1e-9) ** 2 * cs.ii / np.maximum(n_rows, 1)
    var = np.maximum(cs.rss(k, theta) / dof_j, np.maximum(floor, 1e-300))
    w = np.where(active, 1.0 / var, 0.0)
    free = np.r_[np.flatnonzero(active), nv + np.arange(cs.m)]
    return k, theta, w, free


def ml_sandwich(
    acc: InformationAccumulator,
    nv: int,
    x: np.ndarray,
    n_rows,
    active,
    bandwidth: float | None = None,
) -> tuple[np.ndarray, HacEstimate]:
    """The autocorrelation-consistent covariance of an ML estimate ``x = [g, theta]``.

    With ``xi = [k, theta]`` the ML estimate zeroes the gradient of
    ``sum_j w_j ||e_j||^2 / 2``, a sum over the recorded blocks of samples ``k`` of
    ``grad_k(xi)``, each from that block's per-joint sums
    (:attr:`~manip_id.estimators.blocks.ScoreBlocks.A_joint` ...) as the whole is from the
    accumulator. Gauss-Newton's ``H = sum_k H_k`` is the bread, the block gradients the
    scores: ``Cov(xi) = c H^+ Omega_hat H^+``
    (:func:`~manip_id.estimators.uncertainty.sandwich_covariance`; white noise gives
    ``Omega = H`` and the white ``H^+``), then ``dg/dk = -1/k^2`` as :func:`ml_gains`.
    Returns ``(covariance of [g, theta], HacEstimate)``; ``acc.blocks`` must be recorded.
    """
    blocks = acc.blocks
    if blocks is None:
        raise InputError("the ML sandwich needs the per-block sums (acc.blocks)")
    active = np.asarray(active, dtype=bool)
    k, theta, w, free = ml_weights(acc, nv, x, n_rows, active)
    cs = _CurrentSums.from_accumulator(acc, nv)
    Ab, bb, zb = blocks.A_joint, blocks.b_joint, blocks.zz_joint
    Hk, gk = [], []
    for a, b, z in zip(Ab, bb, zb, strict=True):
        H, grad = _CurrentSums.from_sums(a, b, z, nv).normal(k, theta, w)
        Hk.append(H[np.ix_(free, free)])
        gk.append(grad[free])
    out: list[HacEstimate] = []

    def meat(Hinv: np.ndarray) -> np.ndarray:
        est = sandwich_covariance(np.array(gk), Hinv, np.array(Hk), bandwidth=bandwidth)
        out.append(est)
        return est.covariance

    cov = _ml_covariance(cs, k, theta, w, free, active, meat=meat)
    return cov, out[0]
