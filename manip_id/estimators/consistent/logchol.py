"""The consistent problem in log-Cholesky parameters: unconstrained, no SDP solver.

Each ``J_i - eps_i 1 = U U^T`` with ``U = e^alpha [[e^d1, s12, s13, t1], [0, e^d2, s23,
t2], [0, 0, e^d3, t3], [0, 0, 0, 1]]`` (Rucker & Wensing 2022; Pinocchio's
``LogCholeskyParameters``), the non-negative joint terms as squares. In these
parameters ``-log det(U U^T)`` is linear and ``tr(J0^-1 U U^T)`` a sum of squares, so
the objective is ``||r(x)||^2 + g^T x``; Levenberg-Marquardt on it (:func:`solve_logchol`),
with Newton's clipped curvature of the residuals, a second-order correction that keeps
steps on the stiff fit, and QR solves (no normal equations).
"""

from __future__ import annotations

import contextlib

import numpy as np
import pinocchio as pin
import scipy.linalg as sla

from ..._checks import as_float_array
from ...errors import InputError, SolverError
from ...physics.consistency import parameters_from_pseudo_inertia, pseudo_inertia
from .problem import ConsistentProblem, row_and_null_maps


def _U(eta: np.ndarray) -> np.ndarray:
    """Upper-triangular ``U`` of log-Cholesky parameters ``eta`` (10,), ``J = U U^T``."""
    a, d1, d2, d3, s12, s23, s13, t1, t2, t3 = eta
    return np.exp(a) * np.array(
        [
            [np.exp(d1), s12, s13, t1],
            [0.0, np.exp(d2), s23, t2],
            [0.0, 0.0, np.exp(d3), t3],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _dU(eta: np.ndarray) -> np.ndarray:
    """``dU/deta_k``, shape (10, 4, 4)."""
    a, d1, d2, d3 = eta[:4]
    ea = np.exp(a)
    out = np.zeros((10, 4, 4))
    out[0] = _U(eta)
    out[1, 0, 0] = ea * np.exp(d1)
    out[2, 1, 1] = ea * np.exp(d2)
    out[3, 2, 2] = ea * np.exp(d3)
    for k, (i, j) in enumerate([(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)], start=4):
        out[k, i, j] = ea
    return out


def log_cholesky(J) -> np.ndarray:
    """Log-Cholesky parameters (10,) of a positive definite pseudo-inertia ``J`` (4, 4).

    ``J = U U^T`` with ``U`` upper triangular (a Cholesky factor of the reversed
    matrix); the inverse of ``pinocchio.LogCholeskyParameters(eta).toPseudoInertia()``.
    """
    J = as_float_array(J, "J", ndim=2)
    rev = J[::-1, ::-1]
    try:
        L = np.linalg.cholesky(0.5 * (rev + rev.T))
    except np.linalg.LinAlgError as exc:
        raise InputError("the pseudo-inertia is not positive definite") from exc
    U = L[::-1, ::-1]
    ea = U[3, 3]
    Un = U / ea
    return np.array(
        [
            np.log(ea),
            np.log(Un[0, 0]),
            np.log(Un[1, 1]),
            np.log(Un[2, 2]),
            Un[0, 1],
            Un[1, 2],
            Un[0, 2],
            Un[0, 3],
            Un[1, 3],
            Un[2, 3],
        ]
    )


#: Body parameters of ``J = 1`` (the 4 x 4 identity): ``[1, 0, 0, 0, 2, 0, 2, 0, 0, 2]``.
_SHIFT = parameters_from_pseudo_inertia(np.eye(4))


def _dual_matrix(c: np.ndarray) -> np.ndarray:
    """The symmetric ``M`` (4, 4) with ``<M, J> = c . pi(J)`` for every pseudo-inertia ``J``.

    ``pi(J) = [m, h, I]`` with ``I = tr(Sigma) 1 - Sigma``: with ``C_I`` the symmetric
    matrix of the inertia weights, ``M = [[tr(C_I) 1 - C_I, c_h / 2], [c_h^T / 2, c_m]]``.
    """
    cm, chx, chy, chz, cxx, cxy, cyy, cxz, cyz, czz = c
    CI = np.array([[cxx, cxy / 2, cxz / 2], [cxy / 2, cyy, cyz / 2], [cxz / 2, cyz / 2, czz]])
    M = np.zeros((4, 4))
    M[:3, :3] = np.trace(CI) * np.eye(3) - CI
    M[:3, 3] = M[3, :3] = 0.5 * np.array([chx, chy, chz])
    M[3, 3] = cm
    return M


def _quad_hessian(M: np.ndarray, eta: np.ndarray, dU: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hessian of ``<M, U U^T>`` in the log-Cholesky parameters, as ``H1 + H2`` (10, 10).

    ``H1_kl = 2 <dU_k, M dU_l>`` (first derivatives of U), ``H2_kl = 2 <M U, d2U_kl>``
    (second derivatives: ``d2U/dalpha^2 = U``, ``d2U/dalpha deta_k = dU_k``,
    ``d2U/dd_k^2 = dU/dd_k``, all others zero).
    """
    MdU = np.einsum("ac,lcb->lab", M, dU)
    H1 = 2.0 * np.einsum("kab,lab->kl", dU, MdU)
    inner = np.einsum("ab,kab->k", M @ _U(eta), dU)  # <M U, dU_k>; dU_0 = U
    H2 = np.zeros((10, 10))
    H2[0, :] = H2[:, 0] = 2.0 * inner
    H2[[1, 2, 3], [1, 2, 3]] += 2.0 * inner[1:4]
    return H1, H2


class _LogChol:
    """The log-Cholesky parametrization ``x -> theta`` of a problem, with its Jacobian."""

    def __init__(self, pr: ConsistentProblem):
        self.pr = pr
        nb, p = pr.n_bodies, pr.p
        self.nb = nb
        self.nonneg = np.zeros(p - 10 * nb, dtype=bool)
        self.nonneg[pr.nonnegative - 10 * nb] = True
        self.shift = _SHIFT
        self.L0inv = None
        if pr.J0 is not None:
            self.L0inv = np.stack([np.linalg.inv(np.linalg.cholesky(J)) for J in pr.J0])

    def start(self, theta: np.ndarray) -> np.ndarray:
        """Parameters ``x`` of a start ``theta`` (bodies pulled inside the margin if needed)."""
        pr, nb = self.pr, self.nb
        x = np.empty(pr.p)
        J = pseudo_inertia(theta[: 10 * nb].reshape(nb, 10))
        for i in range(nb):
            Ji = J[i] - pr.margin[i] * np.eye(4)
            lam, V = np.linalg.eigh(Ji)
            floor = max(float(pr.margin[i]), 1e-12 * float(np.abs(lam).max()))
            Ji = (V * np.maximum(lam, floor)) @ V.T
            x[10 * i : 10 * i + 10] = log_cholesky(Ji)
        t = theta[10 * nb :].copy()
        s = pr.term_scale
        tn, sn = t[self.nonneg], s[self.nonneg]  # non-positive starts: a small positive value
        t[self.nonneg] = np.sqrt(np.where(tn > 0, tn, 1e-2 * sn))
        x[10 * nb :] = t
        return x

    def theta(self, x: np.ndarray) -> np.ndarray:
        pr, nb = self.pr, self.nb
        out = np.empty(pr.p)
        for i in range(nb):
            eta = x[10 * i : 10 * i + 10]
            lc = pin.LogCholeskyParameters(eta)
            out[10 * i : 10 * i + 10] = lc.toDynamicParameters() + pr.margin[i] * self.shift
        t = x[10 * nb :].copy()
        t[self.nonneg] = t[self.nonneg] ** 2
        out[10 * nb :] = t
        return out

    def curvature(self, x: np.ndarray, theta: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``S = sum_k r_k d2 r_k`` (p, p), the part of the Hessian of ``F / 2`` that
        Gauss-Newton drops (large when the fit's residual is large, as on real data)."""
        pr, nb = self.pr, self.nb
        k_fit = pr.W.shape[0]
        c = pr.P.T @ (pr.W.T @ r[:k_fit])  # d(||r_fit||^2 / 2)/dtheta
        if self.L0inv is not None:
            tdiff = (theta[10 * nb :] - pr.theta0[10 * nb :]) / pr.term_scale
            c = c.copy()
            c[10 * nb :] += pr.weight * tdiff / pr.term_scale
        S = np.zeros((pr.p, pr.p))
        for i in range(nb):
            sl = slice(10 * i, 10 * i + 10)
            eta = x[sl]
            dU = _dU(eta)
            H1, H2 = _quad_hessian(_dual_matrix(c[sl]), eta, dU)
            S[sl, sl] = H1 + H2
            if self.L0inv is not None:  # the prior's residual vec(L0^-1 U): its d2 part
                J0inv = self.L0inv[i].T @ self.L0inv[i]
                S[sl, sl] += 0.5 * _quad_hessian(pr.weight * J0inv, eta, dU)[1]
        t = np.arange(10 * nb, pr.p)[self.nonneg]
        S[t, t] = 2.0 * c[t]  # theta_t = s^2
        return S

    def evaluate(self, x: np.ndarray, jacobian: bool = True):
        """Residuals ``r``, extra (non-squared) objective ``g``, and their derivatives.

        Objective ``F(x) = ||r(x)||^2 + g(x)``; ``g = -w sum_i log det(J_i - eps_i 1)
        = -2 w sum_i (4 alpha_i + d1_i + d2_i + d3_i)``, linear in the log-Cholesky
        parameters (so Gauss-Newton's Hessian of F is exact in it: zero).
        """
        pr, nb = self.pr, self.nb
        theta = self.theta(x)
        r_fit = pr.W @ (pr.P @ theta - pr.beta_ls)
        res = [r_fit]
        g = 0.0
        Jt = dg = None
        if jacobian:
            Jt = np.zeros((pr.p, pr.p))  # dtheta/dx (block diagonal)
            for i in range(nb):
                sl = slice(10 * i, 10 * i + 10)
                Jt[sl, sl] = pin.LogCholeskyParameters(x[sl]).calculateJacobian()
            d = np.ones(pr.p - 10 * nb)
            d[self.nonneg] = 2.0 * x[10 * nb :][self.nonneg]
            Jt[10 * nb :, 10 * nb :] = np.diag(d)
            jac = [pr.W @ (pr.P @ Jt)]
            dg = np.zeros(pr.p)
        if self.L0inv is not None:
            sw = np.sqrt(pr.weight)
            for i in range(nb):
                sl = slice(10 * i, 10 * i + 10)
                U = _U(x[sl])
                res.append(sw * (self.L0inv[i] @ U).ravel())
                eta = x[sl]
                g -= 2.0 * pr.weight * (4.0 * eta[0] + eta[1] + eta[2] + eta[3])  # log det U U^T
                if jacobian:
                    dU = _dU(eta)
                    blk = np.zeros((16, pr.p))
                    blk[:, sl] = sw * np.einsum("ab,kbc->ack", self.L0inv[i], dU).reshape(16, 10)
                    jac.append(blk)
                    assert dg is not None
                    dg[10 * i : 10 * i + 4] = -2.0 * pr.weight * np.array([4.0, 1.0, 1.0, 1.0])
            tdiff = (theta[10 * nb :] - pr.theta0[10 * nb :]) / pr.term_scale
            res.append(sw * tdiff)
            if Jt is not None:
                jac.append(sw * Jt[10 * nb :] / pr.term_scale[:, None])
        r = np.concatenate(res)
        if not jacobian:
            return theta, r, g
        return theta, r, g, np.vstack(jac), dg


def _inside(pr: ConsistentProblem, theta: np.ndarray) -> bool:
    """Whether ``theta`` meets the problem's constraints (margins and signs)."""
    nb = pr.n_bodies
    J = pseudo_inertia(theta[: 10 * nb].reshape(nb, 10)) - pr.margin[:, None, None] * np.eye(4)
    if np.linalg.eigvalsh(J)[:, 0].min() <= 0:
        return False
    return bool(np.all(theta[pr.nonnegative] >= 0))


def solve_logchol(
    problem: ConsistentProblem,
    *,
    max_iter: int = 500,
    tolerance: float = 1e-13,
    theta_start=None,
):
    model = _LogChol(problem)
    pr = problem
    if theta_start is None:
        # the prior moved onto the least-squares fit along the row space of P when that
        # is inside the cone (a nearly exact, physical fit); else the prior's bodies
        # (well inside the cone) with the moved joint terms (their LS values, mostly)
        # (two ways of moving: onto the independent columns, or the correction of least
        # scaled size, which shares it with the dependent parameters)
        G, _ = row_and_null_maps(pr)
        gap = pr.beta_ls - pr.P @ pr.theta0
        nb10 = 10 * pr.n_bodies
        scale = np.abs(pr.theta0).copy()
        for i in range(pr.n_bodies):
            blk = scale[10 * i : 10 * i + 10]
            blk[:] = np.maximum(blk, 1e-3 * max(float(blk.max()), 1e-12))
        scale[nb10:] = pr.term_scale
        D2P = (scale**2)[:, None] * pr.P.T
        shared = pr.theta0 + D2P @ np.linalg.lstsq(pr.P @ D2P, gap, rcond=None)[0]
        candidates = [pr.theta0 + G @ gap, shared]
        moved = next((c for c in candidates if _inside(pr, c)), None)
        if moved is None:
            moved = candidates[0]
            moved[:nb10] = pr.theta0[:nb10]
        x = model.start(moved)
    else:
        x = model.start(as_float_array(theta_start, "theta_start", ndim=1))
    with np.errstate(over="ignore", invalid="ignore"), _one_blas_thread():  # trial steps
        return _lm(model, pr, x, max_iter, tolerance)  # may overflow exp()


def _one_blas_thread():
    """BLAS on one thread for the solve (threadpoolctl, when installed; else as it is).

    Every matrix of the iteration is small (p x p, p < a few hundred): threaded BLAS
    only adds synchronization, which on a busy machine made the solve of the Panda
    log 90x slower (60 iterations: 14.7 s on 2 threads, 0.16 s on one).
    """
    try:
        from threadpoolctl import threadpool_limits  # optional (the fast extra)
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _lm(model: _LogChol, pr: ConsistentProblem, x: np.ndarray, max_iter: int, tolerance: float):
    """Levenberg-Marquardt with Newton's clipped curvature and a second-order correction."""
    k_fit = pr.W.shape[0]
    eye = np.eye(x.size)  # Levenberg damping: Marquardt's column scaling would damp the
    # null-space moves by the (much stiffer) fit's scale
    theta, r, g, Jr, dg = model.evaluate(x)
    F = float(r @ r + g)
    mu = 1e-3
    status = "max_iter"
    iterations = 0
    small = 0
    for it in range(1, int(max_iter) + 1):
        iterations = it
        grad = Jr.T @ r + 0.5 * dg  # half the gradient of F
        J_fit = Jr[:k_fit]
        pinv_fit = np.linalg.pinv(J_fit, rcond=1e-13)
        # Newton's curvature beyond Gauss-Newton, its negative part clipped (modified
        # Newton), as a square-root factor stacked under the Jacobian: the QR keeps the
        # accuracy of a nearly noise-free fit (no normal equations formed)
        lam_s, V_s = np.linalg.eigh(model.curvature(x, theta, r))
        keep = lam_s > 0
        S_half = np.sqrt(lam_s[keep])[:, None] * V_s[:, keep].T
        accepted = False
        for _ in range(40):
            R = sla.qr(np.vstack([Jr, S_half, np.sqrt(mu) * eye]), mode="r")[0][: x.size]
            try:
                y = sla.solve_triangular(R, -grad, trans="T", check_finite=False)
                dx = sla.solve_triangular(R, y, check_finite=False)
            except (ValueError, np.linalg.LinAlgError):
                mu *= 10.0
                continue
            # second-order correction: pull the step back onto the fit's linearization
            # (the fit can be many orders of magnitude stiffer than the prior)
            theta_t = model.theta(x + dx)
            r_fit_t = pr.W @ (pr.P @ theta_t - pr.beta_ls)
            x_new = x + dx - pinv_fit @ (r_fit_t - r[:k_fit] - J_fit @ dx)
            theta_n, r_n, g_n = model.evaluate(x_new, jacobian=False)
            F_new = float(r_n @ r_n + g_n) if np.all(np.isfinite(r_n)) else np.inf
            if np.isfinite(F_new) and F_new <= F:
                accepted = True
                break
            mu *= 4.0
        if not accepted:
            status = "converged (no further decrease)"
            break
        decrease = F - F_new
        step = float(np.linalg.norm(x_new - x)) / max(float(np.linalg.norm(x)), 1.0)
        x = x_new
        theta, r, g, Jr, dg = model.evaluate(x)
        F = F_new
        mu = max(mu / 10.0, 1e-15)
        if decrease <= tolerance * max(abs(F), 1.0):
            small += 1
            if small >= 2 and step <= 1e-9:
                status = "converged"
                break
            if small >= 10:  # steps along directions that no longer change the objective
                status = "converged (objective stalled)"
                break
        else:
            small = 0
    if not np.all(np.isfinite(theta)):
        raise SolverError("the iteration diverged", "logchol", status)
    return theta, status, iterations
