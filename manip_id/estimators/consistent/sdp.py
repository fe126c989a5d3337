"""The consistent problem as a semidefinite program (cvxpy with Clarabel).

Variables ``theta = G (beta_ls + W^+ u + V_0 v) + N z`` (``G`` onto the independent
columns, ``N`` the null space of ``P``, ``V_0`` the base directions the data do not
see) so that the fit is ``||u||^2`` exactly; each body's ``J_i - eps_i 1`` is a 4 x 4
PSD variable tied linearly to ``theta``, the prior a sum of ``tr(J0_i^-1 J_i) -
log det J_i``. A stalled solve is retried with the objective scaled
(:data:`OBJECTIVE_SCALES`); the minimizer does not change.
"""

from __future__ import annotations

import warnings

import numpy as np

from ...errors import SolverError
from ...physics.consistency import pseudo_inertia_basis
from .bounds import bound_constraints
from .problem import MARGIN, ConsistentProblem, row_and_null_maps

#: Objective scales the SDP is tried with, in turn, until Clarabel reports "optimal" (the
#: large ones for bounds that hold the fit millions of squared standard deviations away).
OBJECTIVE_SCALES: tuple[float, ...] = (1.0, 1e2, 1e4, 1e-2, 1e6, 1e8)


def solve_sdp(problem: ConsistentProblem, *, tolerance: float = 1e-8, max_iter: int = 500):
    """Solve ``problem`` as a semidefinite program (cvxpy with Clarabel), unchecked.

    Every body's pseudo-inertia is constrained to ``J_i >= margin_i 1`` (one 4 x 4 LMI
    each), the joint terms in ``problem.nonnegative`` to ``>= 0`` and, when the problem
    carries them, each body's mass distribution to its bounding ellipsoid
    (``tr(J_i Q_bar_i) >= 0``), its mass to its range and the total mass to its interval
    (:mod:`~manip_id.estimators.consistent.bounds`). Returns ``(theta, status,
    iterations)``; :func:`solve_consistent` adds the independent check. Also the one-body
    payload solve of :mod:`manip_id.payload`.
    """
    import cvxpy as cp  # optional heavy dependency: only the SDP needs it

    theta, u = _theta_expression(cp, problem)
    cons, Js = _constraints(cp, problem, theta)
    obj = _objective(cp, problem, theta, u, Js)
    return _solve_scaled(cp, cons, obj, theta, tolerance, max_iter)


def _theta_expression(cp, pr: ConsistentProblem):
    """``theta = G (beta_ls + W^+ u + V_0 v) + N z`` as a cvxpy expression, and ``u``.

    The fit is ``||u||^2`` exactly, and the ill-conditioning of a nearly noise-free fit
    becomes a column scaling of ``u`` that the solver's equilibration removes (in
    ``theta`` it would be a dense ill-conditioned ``W P``).
    """
    r = pr.P.shape[0]
    G, N = row_and_null_maps(pr)
    _, sw, Vwt = np.linalg.svd(pr.W, full_matrices=True)
    k = int(np.sum(sw > 0))
    Winv = Vwt[:k].T / sw[:k]  # (r, k) so that W (Winv u) = U_k u
    V0 = Vwt[k:].T  # base directions the data do not see, (r, r - k)
    u = cp.Variable(k)
    z = cp.Variable(N.shape[1]) if N.shape[1] else None
    v = cp.Variable(r - k) if r > k else None
    theta = G @ pr.beta_ls + (G @ Winv) @ u
    if v is not None:
        theta = theta + (G @ V0) @ v
    if z is not None:
        theta = theta + N @ z
    return theta, u


def _constraints(cp, pr: ConsistentProblem, theta):
    """The LMIs ``J_i - eps_i 1 >= 0`` (as PSD variables ``Js``), signs and bounds."""
    E = pseudo_inertia_basis().reshape(10, 16).T  # vec(J_i) = E @ pi_i (row-major vec)
    eye_vec = np.eye(4).ravel()
    Js = [cp.Variable((4, 4), symmetric=True) for _ in range(pr.n_bodies)]
    cons = []
    for i, Ji in enumerate(Js):
        # Ji is the part of body i's pseudo-inertia above its margin: J_i - eps_i 1
        cons.append(
            cp.vec(Ji, order="C") == E @ theta[10 * i : 10 * i + 10] - pr.margin[i] * eye_vec
        )
        cons.append(Ji >> 0)
        if pr.J0 is None:  # no prior: also a margin relative to the body's own size
            Jfull = Ji + pr.margin[i] * np.eye(4)
            cons.append(Jfull - MARGIN * cp.trace(Jfull) * np.eye(4) >> 0)
    if pr.nonnegative.size:
        cons.append(theta[pr.nonnegative] >= 0)
    if pr.bounds is not None:
        cons += bound_constraints(pr.bounds, theta)
    if pr.linear is not None:  # the temperature law's friction >= 0 over its range
        cons.append(pr.linear @ theta >= 0)
    return cons, Js


def _objective(cp, pr: ConsistentProblem, theta, u, Js):
    """``||u||^2 + w (sum_i tr(J0_i^-1 J_i) - log det J_i + joint-term squares)``."""
    nb, p = pr.n_bodies, pr.p
    obj = cp.sum_squares(u)
    if pr.J0 is not None and pr.weight > 0:
        prior = 0
        for Ji, J0i in zip(Js, pr.J0, strict=True):
            prior = prior + cp.trace(np.linalg.inv(J0i) @ Ji) - cp.log_det(Ji)
        if p > 10 * nb:
            prior = prior + cp.sum_squares(
                cp.multiply(1.0 / pr.term_scale, theta[10 * nb :] - pr.theta0[10 * nb :])
            )
        obj = obj + pr.weight * prior
    return obj


def _solve_scaled(cp, cons, obj, theta, tolerance: float, max_iter: int):
    """Clarabel on ``obj / scale`` for each of :data:`OBJECTIVE_SCALES` until "optimal".

    The interior-point method stalls on badly scaled objectives (a fit of 1e4 squared
    standard deviations when least squares is far from physical); the minimizer does
    not change with the scale. Returns ``(theta, status, iterations)`` or raises
    :class:`SolverError` with every status.
    """
    opts = dict(
        tol_gap_abs=tolerance,
        tol_gap_rel=tolerance,
        tol_feas=tolerance,
        tol_ktratio=1e-8,
        max_iter=int(max_iter),
    )
    statuses = []
    best = None
    inv_scale = cp.Parameter(nonneg=True)  # a parameter: compiled once for every scale
    prob = cp.Problem(cp.Minimize(inv_scale * obj), cons)
    for scale in OBJECTIVE_SCALES:
        inv_scale.value = 1.0 / scale
        try:
            with warnings.catch_warnings():  # "solution may be inaccurate": in the status
                warnings.simplefilter("ignore")
                prob.solve(solver=cp.CLARABEL, **opts)
        except cp.error.SolverError:
            statuses.append(f"scale {scale:g}: solver error")
            continue
        status = str(prob.status)
        statuses.append(f"scale {scale:g}: {status}")
        if theta.value is None or status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
            if "infeasible" in status and status == cp.INFEASIBLE:
                break
            continue
        iters = int(getattr(prob.solver_stats, "num_iters", 0) or 0)
        value = np.array(theta.value, dtype=float)
        if status == cp.OPTIMAL:
            scaled = f" (objective scaled by 1/{scale:g})" if scale != 1 else ""
            return value, status + scaled, iters
        if best is None:
            best = (value, status, iters)
    if best is not None:
        return best
    infeasible = any("infeasible" in st for st in statuses)
    what = "the problem is infeasible" if infeasible else "no solution"
    raise SolverError(what, "sdp", "; ".join(statuses))
