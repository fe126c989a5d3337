"""One entry to both solvers: solve, project onto the margins, check independently."""

from __future__ import annotations

import time

import numpy as np

from ...errors import InputError
from ...physics.consistency import check_consistency, parameters_from_pseudo_inertia, pseudo_inertia
from .logchol import solve_logchol
from .problem import SOLVERS, ConsistentProblem, ConsistentSolution
from .sdp import solve_sdp


def solve_consistent(
    robot, problem: ConsistentProblem, *, solver: str = "sdp", **options
) -> ConsistentSolution:
    """Solve ``problem`` with ``solver`` ("sdp" or "logchol"); check the result independently.

    Options: ``sdp``: ``tolerance`` (Clarabel's gap/feasibility tolerances, default
    1e-8), ``max_iter``; ``logchol``: ``max_iter`` (default 500), ``tolerance``
    (relative decrease/gradient, default 1e-13), ``theta_start`` (a consistent start).
    Raises :class:`SolverError` with the solver's status on failure or infeasibility.

    Bounds (``problem.bounds``): the SDP holds them as constraints. The log-Cholesky
    parametrization has no room for them, so its result is checked against them
    afterwards; when it breaks one, the problem is solved again by the SDP and the
    status says so (``"logchol broke the bounds (...); solved by the SDP: ..."``);
    without cvxpy the log-Cholesky result stays, with the status ``"bounds not held:
    ..."`` and the plausibility check of the estimate names the bodies. The temperature
    law's linear constraints (``problem.linear``) are held the same way.
    """
    if solver not in SOLVERS:
        raise InputError(f"solver must be one of {list(SOLVERS)}, got {solver!r}")
    t0 = time.perf_counter()
    if solver == "sdp":
        theta, status, iters = solve_sdp(problem, **options)
    else:
        theta, status, iters = solve_logchol(problem, **options)
        broken = [] if problem.bounds is None else problem.bounds.violations(theta)
        broken += problem.linear_violations(theta)
        if broken:
            theta, status, iters = _bounded_by_sdp(problem, theta, status, iters, broken)
    elapsed = time.perf_counter() - t0
    theta, moved = project(problem, theta)
    if moved > 0:
        status += f"; projected onto the margins (largest change {moved:.2g})"
    consistency = check_consistency(robot, theta)
    return ConsistentSolution(
        theta=theta,
        beta=problem.P @ theta,
        solver=solver,
        status=status,
        iterations=iters,
        time=elapsed,
        fit=problem.fit(theta),
        prior_distance=problem.prior(theta) if problem.J0 is not None else 0.0,
        objective=problem.objective(theta),
        consistency=consistency,
    )


def project(pr: ConsistentProblem, theta: np.ndarray) -> tuple[np.ndarray, float]:
    """Project an interior-point result onto the constraints it misses by round-off.

    Each body whose ``J_i`` has an eigenvalue below ``eps_i`` gets those eigenvalues
    raised to ``eps_i`` (the nearest matrix with ``J >= eps 1`` in the Frobenius norm);
    negative ``Ia, fv, fc`` become 0. Returns the vector and the largest change of a
    parameter; the result is still checked independently afterwards.
    """
    theta = theta.copy()
    before = theta.copy()
    nb = pr.n_bodies
    J = pseudo_inertia(theta[: 10 * nb].reshape(nb, 10))
    for i in range(nb):
        lam, V = np.linalg.eigh(J[i])
        if lam[0] < pr.margin[i]:
            Jc = (V * np.maximum(lam, pr.margin[i])) @ V.T
            theta[10 * i : 10 * i + 10] = parameters_from_pseudo_inertia(Jc)
    k = pr.nonnegative
    if k.size:
        theta[k] = np.maximum(theta[k], 0.0)
    return theta, float(np.abs(theta - before).max())


def _bounded_by_sdp(problem: ConsistentProblem, theta, status: str, iters: int, broken: list):
    """The SDP's solution of a problem whose log-Cholesky result broke its bounds."""
    what = "; ".join(broken[:3]) + ("; ..." if len(broken) > 3 else "")
    try:
        theta_b, status_b, iters_b = solve_sdp(problem)
    except ImportError:  # cvxpy is optional: keep the unbounded result, say so
        return theta, f"{status}; bounds not held: {what} (install cvxpy for the SDP)", iters
    return theta_b, f"logchol broke the bounds ({what}); solved by the SDP: {status_b}", iters_b
