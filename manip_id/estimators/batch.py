"""Batch least squares: stacked (QR/SVD) and from accumulated information (Cholesky/eigen).

Ordinary least squares minimises ``||z - Phi theta||^2``; weighted least
squares ``sum_j ||z_j - Phi_j theta||^2 / sigma_j^2`` with per-output noise
variances ``sigma_j^2`` estimated from the ordinary residuals. Both solvers
scale every column to unit norm first (``Phi D``, ``D = diag(1/||Phi_i||)``),
which removes the arbitrary unit-dependent part of the condition number.

Stacked: ``Phi D = Q R`` (economic QR); the singular values of ``R`` decide the
rank; a well-conditioned problem is solved by back substitution, otherwise by
the SVD of ``R``.

Accumulated: ``D A D = L L^T`` (Cholesky) on ``A = Phi^T Phi``; when the
scaled condition number of the regressor exceeds ``cond_limit`` (or Cholesky
fails) the solve falls back to the eigen-decomposition of ``D A D``, and says
so in :attr:`LeastSquaresSolution.solver`. Forming ``A`` squares the condition
number, so the rank tolerance on singular values is coarser there
(``INFO_RANK_RTOL``) than for the stacked solve (``STACKED_RANK_RTOL``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.linalg as sla

from .._checks import as_float_array
from ..errors import InputError, RankDeficiencyError
from ..errors import format_direction as format_direction  # re-exported: the one formatter
from .accumulator import InformationAccumulator, check_finite_rows
from .results import LeastSquaresSolution

#: Singular values of the scaled regressor below this fraction of the largest
#: count as unexcited, when solving from the information matrix.
INFO_RANK_RTOL = 1e-6
#: The same for the stacked (QR/SVD) solve, which does not square the condition.
STACKED_RANK_RTOL = 1e-10
#: Scaled condition number of the regressor above which Cholesky gives way to eigen.
COND_LIMIT = 1e6
#: Weighted least squares: no joint's noise standard deviation counts below this
#: fraction of that joint's own root-mean-square output (a per-joint floor: a floor
#: relative to the largest joint's variance would cap the weight of a quiet wrist,
#: 0.3 N m beside 40 N m, and hand its parameters back to the loud joints' noise).
WLS_MIN_RELATIVE_NOISE = 1e-7
#: ... and no weight exceeds the smallest by more than this (a noise-free joint beside
#: noisy ones would otherwise make the weighted information matrix numerically singular;
#: 1e10 is a noise-std ratio of 1e5, far beyond a quiet wrist's 1e-2 of a shoulder's).
WLS_MAX_WEIGHT_RATIO = 1e10


def _rank_error(null: np.ndarray, rank: int, names, scale: np.ndarray) -> RankDeficiencyError:
    return RankDeficiencyError.from_vectors(
        rank,
        null,
        names,
        scale=scale,
        hint="excite the robot more, or ask for a minimum-norm solution",
    )


def _check_names(names, p: int):
    if names is not None and len(names) != p:
        raise InputError(f"{len(names)} names for p={p} parameters")


# --------------------------------------------------------------- information
def solve_normal_equations(
    A,
    b,
    *,
    names: Sequence[str] | None = None,
    minimum_norm: bool = False,
    cond_limit: float = COND_LIMIT,
    rank_rtol: float = INFO_RANK_RTOL,
) -> tuple[np.ndarray, np.ndarray, int, float, float, str]:
    """Solve ``A theta = b`` for a symmetric positive semi-definite information matrix.

    Returns ``(theta, A_inv, rank, cond, scaled_cond, solver)``: ``A_inv`` is the
    inverse (pseudo-inverse on the excited subspace for a minimum-norm
    solution), ``cond``/``scaled_cond`` the condition numbers of the regressor
    (square roots of those of ``A`` and ``D A D``). Raises
    :class:`RankDeficiencyError` naming the unexcited directions unless
    ``minimum_norm``.
    """
    A = as_float_array(A, "A", ndim=2)
    b = as_float_array(b, "b", ndim=1)
    p = b.shape[0]
    if A.shape != (p, p):
        raise InputError(f"A.shape={A.shape} but b.shape={b.shape}")
    _check_names(names, p)
    if not (np.isfinite(A).all() and np.isfinite(b).all()):
        raise InputError("the information matrix or vector holds NaN or Inf")
    A = 0.5 * (A + A.T)
    diag = np.diag(A).copy()
    scale_ok = diag > 0
    d = np.where(scale_ok, 1.0 / np.sqrt(np.where(scale_ok, diag, 1.0)), 1.0)
    As = A * np.outer(d, d)
    bs = b * d
    lam, V = np.linalg.eigh(As)
    lam_max = max(float(lam[-1]), 0.0)
    excited = lam > lam_max * rank_rtol**2 if lam_max > 0 else np.zeros(p, bool)
    rank = int(excited.sum())
    lam_a = np.linalg.eigvalsh(A)
    cond = float(np.sqrt(lam_a[-1] / lam_a[0])) if lam_a[0] > 0 else float("inf")
    scaled_cond = float(np.sqrt(lam_max / lam[0])) if lam[0] > 0 else float("inf")
    if rank < p:
        null = V[:, ~excited] * d[:, None]  # back to unscaled parameter coordinates
        null /= np.linalg.norm(null, axis=0)
        if not minimum_norm:
            raise _rank_error(null, rank, names, 1.0 / d)
        la, Va = np.linalg.eigh(A)
        keep = la > la[-1] * rank_rtol**2
        Ainv = (Va[:, keep] / la[keep]) @ Va[:, keep].T
        theta = Ainv @ b
        solver = f"minimum-norm eigen solve (rank {rank} of {p})"
        return theta, Ainv, rank, cond, scaled_cond, solver
    solver = ""
    if scaled_cond <= cond_limit:
        try:
            cf = sla.cho_factor(As, lower=True, check_finite=False)
            xs = sla.cho_solve(cf, bs, check_finite=False)
            Ainv_s = sla.cho_solve(cf, np.eye(p), check_finite=False)
            solver = (
                "Cholesky of the column-scaled information matrix "
                f"(scaled condition {scaled_cond:.3g})"
            )
        except np.linalg.LinAlgError:
            solver = "eigen solve (Cholesky failed)"
    else:
        solver = f"eigen solve (scaled condition {scaled_cond:.3g} > {cond_limit:.3g})"
    if solver.startswith("eigen"):
        Ainv_s = (V / lam) @ V.T
        xs = Ainv_s @ bs
    theta = d * xs
    Ainv = Ainv_s * np.outer(d, d)
    return theta, 0.5 * (Ainv + Ainv.T), rank, cond, scaled_cond, solver


def solve_accumulator(
    acc: InformationAccumulator,
    *,
    method: str = "ols",
    names: Sequence[str] | None = None,
    minimum_norm: bool = False,
    cond_limit: float = COND_LIMIT,
    rank_rtol: float = INFO_RANK_RTOL,
    wls_iterations: int = 3,
) -> LeastSquaresSolution:
    """Ordinary (``"ols"``) or weighted (``"wls"``) least squares from accumulated sums.

    Residuals come from the sums alone, per joint
    ``RSS_j = zz_j - 2 b_j.theta + theta.A_j.theta``, so weighted least squares
    needs no second pass over the data: the per-joint variances
    ``sigma_j^2 = RSS_j / (n - rank / nv)`` of the ordinary fit weight the
    second solve. A noisy joint inflates the ordinary residuals of the quiet
    ones (through the error of the ordinary estimate), so the weights are
    re-estimated from the weighted residuals ``wls_iterations`` times (each
    costs one p x p solve, no data pass); ``noise_variance`` is the last
    estimate and the covariance is ``(Phi^T W Phi)^-1`` with its weights.
    """
    if not isinstance(acc, InformationAccumulator):
        raise InputError(f"expected an InformationAccumulator, got {type(acc).__name__}")
    if method not in ("ols", "wls"):
        raise InputError(f"method must be 'ols' or 'wls', got {method!r}")
    if acc.n == 0:
        raise InputError("the accumulator holds no samples")
    kw: dict[str, Any] = dict(
        names=names, minimum_norm=minimum_norm, cond_limit=cond_limit, rank_rtol=rank_rtol
    )
    theta, Ainv, rank, cond, scond, solver = solve_normal_equations(acc.A, acc.b, **kw)
    rss_j = acc.residual_sum_of_squares(theta)
    dof = acc.n_rows - rank
    if dof <= 0:
        raise InputError(
            f"{acc.n_rows} equations for {rank} parameters: no residual degrees of "
            "freedom to estimate the noise; give more samples"
        )
    var_j = rss_j / max(acc.n - rank / acc.nv, 1e-300)
    sigma2 = float(rss_j.sum() / dof)
    if method == "ols":
        return LeastSquaresSolution(
            estimate=theta,
            covariance=sigma2 * Ainv,
            sigma2=sigma2,
            noise_variance=var_j,
            rss_per_joint=rss_j,
            zz_per_joint=acc.zz_joint,
            n_rows=acc.n_rows,
            rank=rank,
            condition_number=cond,
            scaled_condition_number=scond,
            solver=solver,
        )
    for _ in range(max(int(wls_iterations), 1)):
        weights = _weights(var_j, acc.zz_joint, acc.n)
        Aw, bw, _ = acc.weighted(weights)
        theta_w, Ainv_w, rank_w, cond_w, scond_w, solver_w = solve_normal_equations(Aw, bw, **kw)
        rss_w = acc.residual_sum_of_squares(theta_w)
        var_j = rss_w / max(acc.n - rank_w / acc.nv, 1e-300)
    return LeastSquaresSolution(
        estimate=theta_w,
        covariance=Ainv_w,
        sigma2=float(weights @ rss_w / dof),
        noise_variance=var_j,
        rss_per_joint=rss_w,
        zz_per_joint=acc.zz_joint,
        n_rows=acc.n_rows,
        rank=rank_w,
        condition_number=cond_w,
        scaled_condition_number=scond_w,
        solver=(
            f"weighted least squares, per-joint variances from the residuals "
            f"({int(wls_iterations)} reweighting pass(es) after OLS); {solver_w}"
        ),
        weights=weights,
    )


def _weights(var: np.ndarray, zz: np.ndarray, n: int) -> np.ndarray:
    """Inverse variances ``1/sigma_j^2``, floored so that no joint gets an absurd weight.

    Joint ``j``'s variance counts at least ``(WLS_MIN_RELATIVE_NOISE)^2 zz_j / n``, the
    round-off level of a noise-free fit of that joint's own outputs, and at least
    ``max_j sigma_j^2 / WLS_MAX_WEIGHT_RATIO`` (numerical safety only: the old floor of
    1e-6 of the largest variance is what capped a quiet wrist's weight). A joint with no
    output and no residual gets weight 1.
    """
    floor = WLS_MIN_RELATIVE_NOISE**2 * np.asarray(zz, dtype=float) / max(n, 1)
    floor = np.maximum(floor, WLS_MAX_WEIGHT_RATIO**-1 * float(np.max(var)))
    floor = np.where(floor > 0, floor, 1.0)
    return 1.0 / np.maximum(var, floor)


# -------------------------------------------------------------------- stacked
def _stacked_inputs(Phi, z, nv: int, weights, names):
    """``Phi`` (n_rows, p) and ``z`` (n_rows,) checked, and the row weights ``sqrt(w_j)``."""
    Phi = as_float_array(Phi, "Phi", ndim=2)
    z = as_float_array(z, "z", ndim=1)
    n_rows, p = Phi.shape
    if z.shape != (n_rows,):
        raise InputError(f"Phi.shape={Phi.shape} but z.shape={z.shape}")
    if nv < 1 or n_rows % nv:
        raise InputError(f"Phi.shape={Phi.shape} has rows not a multiple of nv={nv}")
    _check_names(names, p)
    check_finite_rows(Phi.reshape(-1, nv, p).transpose(1, 0, 2), "Phi", 0)
    check_finite_rows(z.reshape(-1, nv).T, "z", 0)
    w_rows = None
    if weights is not None:
        w = as_float_array(weights, "weights", ndim=1)
        if w.shape != (nv,) or np.any(w <= 0):
            raise InputError(f"weights must be {nv} positive numbers, got weights.shape={w.shape}")
        w_rows = np.tile(np.sqrt(w), n_rows // nv)
    return Phi, z, w_rows


def solve_stacked(
    Phi,
    z,
    *,
    nv: int = 1,
    weights=None,
    names: Sequence[str] | None = None,
    minimum_norm: bool = False,
    cond_limit: float = COND_LIMIT,
    rank_rtol: float = STACKED_RANK_RTOL,
) -> LeastSquaresSolution:
    """Least squares on a stacked regressor through QR (and SVD when needed).

    Parameters
    ----------
    Phi
        stacked regressor, shape (n_rows, p), sample-major (row ``k*nv + j``).
    z
        stacked outputs, shape (n_rows,).
    nv
        outputs per sample, for the per-joint statistics (``n_rows % nv == 0``).
    weights
        per-output weights ``1/sigma_j^2``, shape (nv,), for weighted least
        squares with known variances; the covariance is then ``(Phi^T W Phi)^-1``.
    """
    Phi, z, w_rows = _stacked_inputs(Phi, z, nv, weights, names)
    n_rows, p = Phi.shape
    Pw = Phi if w_rows is None else Phi * w_rows[:, None]
    zw = z if w_rows is None else z * w_rows
    norms = np.linalg.norm(Pw, axis=0)
    d = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    Q, R = sla.qr(Pw * d, mode="economic", check_finite=False)
    qz = Q.T @ zw
    U, s, Vt = np.linalg.svd(R)
    excited = s > s[0] * rank_rtol if s[0] > 0 else np.zeros(p, bool)
    rank = int(excited.sum())
    scond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    s_raw = np.linalg.svd(Pw, compute_uv=False) if p <= 400 else s
    cond = float(s_raw[0] / s_raw[-1]) if s_raw[-1] > 0 else float("inf")
    if rank < p:
        null = Vt[~excited].T * d[:, None]
        null /= np.linalg.norm(null, axis=0)
        if not minimum_norm:
            raise _rank_error(null, rank, names, 1.0 / d)
        U2, s2, Vt2 = np.linalg.svd(Pw, full_matrices=False)
        keep = s2 > s2[0] * rank_rtol
        theta = Vt2[keep].T @ ((U2[:, keep].T @ zw) / s2[keep])
        Ginv = (Vt2[keep].T / s2[keep] ** 2) @ Vt2[keep]
        solver = f"minimum-norm SVD solve (rank {rank} of {p})"
    else:
        if scond <= cond_limit:
            xs = sla.solve_triangular(R, qz, check_finite=False)
            Rinv = sla.solve_triangular(R, np.eye(p), check_finite=False)
            Ginv_s = Rinv @ Rinv.T
            solver = f"QR of the column-scaled regressor (scaled condition {scond:.3g})"
        else:
            xs = Vt.T @ ((U.T @ qz) / s)
            Ginv_s = (Vt.T / s**2) @ Vt
            solver = f"SVD solve (scaled condition {scond:.3g} > {cond_limit:.3g})"
        theta = d * xs
        Ginv = Ginv_s * np.outer(d, d)
    res = (z - Phi @ theta).reshape(-1, nv)
    rss_j = np.einsum("nj,nj->j", res, res)
    zz_j = np.einsum("nj,nj->j", z.reshape(-1, nv), z.reshape(-1, nv))
    n = n_rows // nv
    dof = n_rows - rank
    if dof <= 0:
        raise InputError(
            f"{n_rows} equations for {rank} parameters: no residual degrees of freedom"
        )
    var_j = rss_j / max(n - rank / nv, 1e-300)
    if weights is None:
        sigma2 = float(rss_j.sum() / dof)
        cov = sigma2 * Ginv
        wts = None
    else:
        wts = np.asarray(weights, dtype=float)
        sigma2 = float(wts @ rss_j / dof)
        cov = Ginv
        solver = "weighted " + solver
    return LeastSquaresSolution(
        estimate=theta,
        covariance=0.5 * (cov + cov.T),
        sigma2=sigma2,
        noise_variance=var_j,
        rss_per_joint=rss_j,
        zz_per_joint=zz_j,
        n_rows=n_rows,
        rank=rank,
        condition_number=cond,
        scaled_condition_number=scond,
        solver=solver,
        weights=wts,
    )
