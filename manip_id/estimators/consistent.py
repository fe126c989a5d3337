"""Physically consistent least squares: standard parameters whose base parameters fit the data.

The data enter only through the streamed information of the base regressor
``Y_b`` (:class:`~manip_id.estimators.InformationAccumulator`): ``A = Y_b^T W Y_b``
(r, r), ``b = Y_b^T W tau`` (r,). The base parameters of a standard vector are
``beta = P theta`` (``P`` the (r, p) base map: identity on the independent
columns, ``K`` on the dependent ones), so the weighted residual is::

    ||W^1/2 (Y_b P theta - tau)||^2 = theta^T P^T A P theta - 2 b^T P theta + zz
                                   = (P theta - beta_ls)^T A (P theta - beta_ls) + RSS_min

with ``beta_ls`` the least-squares solution. Measured in standard deviations of
``beta_ls`` (covariance ``C = s A^-1``, ``s`` the residual variance) the fit is
``f(theta) = (P theta - beta_ls)^T C^-1 (P theta - beta_ls)``. The estimate solves::

    minimize    f(theta) + w * [ sum_i D(J_i - eps_i 1 || J0_i - eps_i 1)
                                 + sum_t ((theta_t - theta0_t) / s_t)^2 ]
    subject to  J_i(theta) - eps_i 1 >= 0  (each body i),   Ia, fv, fc >= 0

where ``J_i`` is body i's pseudo-inertia (:mod:`manip_id.consistency`) and

- ``D(J || J0) = tr(J0^-1 J) - log det(J0^-1 J) - 4`` is the log-det (Bregman)
  divergence (Lee, Wensing & Park 2019): zero at ``J = J0``, invariant to the body
  frame and to units. It is taken on the part of each pseudo-inertia above its
  margin, so that it is also the barrier of the margin;
- ``eps_i = min(MARGIN lambda_max(J0_i), lambda_min(J0_i) / 2)`` is the margin of
  body i (``MARGIN lambda_max(|J0_i|)`` without a prior);
- ``s_t = sqrt(zz / H_tt)``, ``H = P^T A P``, is the scale of joint term ``t``: the
  value that alone would explain all the torque (parameter units, whatever the
  noise level);
- ``w`` is the prior weight. With a small ``w`` the prior only picks, among the
  standard vectors that fit equally well (the null space of ``Y_b P``), the one
  closest to the prior, and moves a physical fit by a fraction of a standard
  deviation. :func:`consistent_estimate` measures the fit in honest standard
  deviations: ``C`` inflated by the scale ``k = max(1, f_feas / r)``, the fit of the
  feasibility solve against its expected value (the reduced chi-square, or Birge
  ratio, of the physical model), so it solves with ``w k`` in place of ``w``. On
  white noise ``f_feas << r`` and ``k = 1``; on filtered real data, whose residuals
  are correlated over hundreds of samples, ``sigma^2 (Y^T Y)^-1`` is too small by
  about the correlation time and ``k`` measures by how much (the real Panda log:
  ``k = 247``; batch means over 8-16 contiguous blocks give 260-300, a 3 Hz
  low-pass at 1 kHz leaves ``fs / (2 fc) = 167`` samples per independent one).
  ``prior="none"``: ``w = 0``, feasibility alone; the SDP then also asks
  ``J_i >= MARGIN tr(J_i) 1`` (a margin relative to the body's own size), and
  nothing bounds the unidentifiable directions: the interior-point method returns a
  point inside the optimal set, whose standard parameters may be large.

Two solvers (:data:`SOLVERS`) return the same minimizer within their tolerances
(the problem is convex in ``theta``; the log-Cholesky map is a smooth bijection
onto the interior of the cone):

- ``"sdp"``: the convex problem above (log-det, PSD cones, a quadratic) with cvxpy
  and Clarabel, in the variables ``theta = G (beta_ls + W^+ u) + N z`` (``G`` onto
  the independent columns, ``N`` the null space) so that the fit is ``||u||^2``
  exactly and a nearly noise-free fit stays well conditioned. A stalled solve is
  retried with the objective scaled (:data:`OBJECTIVE_SCALES`); eigenvalues an
  interior-point result misses by round-off are raised onto the margin.
- ``"logchol"``: each ``J_i - eps_i 1 = U U^T`` in Pinocchio's log-Cholesky
  parameters (``U = e^alpha [[e^d1, s12, s13, t1], [0, e^d2, s23, t2],
  [0, 0, e^d3, t3], [0, 0, 0, 1]]``, Rucker & Wensing 2022), the non-negative joint
  terms as squares: unconstrained, so no SDP solver. In these parameters
  ``-log det(U U^T)`` is linear and ``tr(J0^-1 U U^T)`` a sum of squares, so the
  objective is ``||r(x)||^2 + g^T x``; Levenberg-Marquardt on it, with Jacobians from
  ``pinocchio.LogCholeskyParameters.calculateJacobian``, Newton's curvature of the
  residuals (clipped to its positive part; large on real data whose fit residual
  is large), a second-order correction that keeps steps on the stiff fit, and QR
  solves (no normal equations). Cost per iteration: O(p^3) for p parameters.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from .._checks import as_float_array
from ..consistency import (
    NONNEGATIVE_TERMS,
    ConsistencyReport,
    PhysicalConsistencyError,
    Violation,
    check_consistency,
    pseudo_inertia,
    pseudo_inertia_basis,
)
from ..errors import InputError, ManipIdError

SOLVERS: tuple[str, ...] = ("sdp", "logchol")
PRIORS: tuple[str, ...] = ("nominal", "none")
#: Default weight of the prior against the fit measured in honest standard deviations
#: (the OLS ones times ``sqrt(fit_scale)``, see :func:`consistent_estimate`): the prior
#: moves the fit by less than one of them beyond what physical consistency needs
#: (0.04-0.8 on simulated white noise of 1-5 %, 0.37 on the real Panda log).
DEFAULT_PRIOR_WEIGHT = 0.1
#: Weight of the scale solve (in OLS standard deviations): small enough that its fit
#: is the feasibility minimum, large enough that the problem stays bounded.
SCALE_WEIGHT = 1e-3
#: Margin of positive definiteness: ``J_i >= min(MARGIN lambda_max(J0_i), lambda_min(J0_i) / 2) 1``.
MARGIN = 1e-6
#: Relative floor of the residual variance used to measure the fit, ``(FLOOR * rms tau)^2``:
#: the round-off level of a residual computed from the sums.
VARIANCE_FLOOR = 1e-8
#: Objective scales the SDP is tried with, in turn, until Clarabel reports "optimal".
OBJECTIVE_SCALES: tuple[float, ...] = (1.0, 1e2, 1e4, 1e-2)


class SolverError(ManipIdError):
    """The consistent solver failed or the problem is infeasible.

    Attributes
    ----------
    solver: "sdp" or "logchol"; status: the solver's own status string.
    """

    def __init__(self, message: str, solver: str, status: str):
        super().__init__(f"{solver} solver: {message} (status {status!r})")
        self.solver = solver
        self.status = status


@dataclass(frozen=True)
class ConsistentProblem:
    """The fit and the prior of a consistent estimate (see the module docstring).

    Attributes
    ----------
    P: base map, shape (r, p): ``beta = P theta``.
    beta_ls: unconstrained least-squares base parameters, shape (r,).
    W: whitening, shape (r, r): ``f(theta) = ||W (P theta - beta_ls)||^2`` (``W^T W = C^-1``).
    n_bodies: bodies; the first ``10 n_bodies`` entries of theta are theirs.
    nonnegative: indices of the joint terms constrained ``>= 0``.
    theta0: the prior's standard parameters (or the reference point when none), (p,).
    J0: prior pseudo-inertias less their margins, ``J0_i - eps_i 1``, shape
        (n_bodies, 4, 4) (None without a prior).
    term_scale: ``s_t`` of each joint term, shape (p - 10 n_bodies,).
    margin: ``eps_i`` per body, shape (n_bodies,).
    weight: prior weight ``w`` (0 for no prior).
    independent, dependent: the base parametrization's column indices.
    names: standard parameter names.
    """

    P: np.ndarray
    beta_ls: np.ndarray
    W: np.ndarray
    n_bodies: int
    nonnegative: np.ndarray
    theta0: np.ndarray
    J0: np.ndarray | None
    term_scale: np.ndarray
    margin: np.ndarray
    weight: float
    independent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    dependent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    names: list[str] = field(default_factory=list)

    @property
    def p(self) -> int:
        return int(self.P.shape[1])

    def fit(self, theta: np.ndarray) -> float:
        """``f(theta)``, the fit excess in squared standard deviations."""
        e = self.W @ (self.P @ theta - self.beta_ls)
        return float(e @ e)

    def prior(self, theta: np.ndarray) -> float:
        """Unweighted prior distance: sum of log-det divergences plus the joint-term squares."""
        if self.J0 is None:
            return 0.0
        nb = self.n_bodies
        J = pseudo_inertia(theta[: 10 * nb].reshape(nb, 10))
        total = 0.0
        for Ji, J0i, eps in zip(J, self.J0, self.margin, strict=True):
            M = np.linalg.solve(J0i, Ji - eps * np.eye(4))
            sign, logdet = np.linalg.slogdet(M)
            total += float(np.trace(M) - logdet - 4.0) if sign > 0 else np.inf
        dt = (theta[10 * nb :] - self.theta0[10 * nb :]) / self.term_scale
        return total + float(dt @ dt)

    def objective(self, theta: np.ndarray) -> float:
        """``f(theta) + w * prior(theta)``."""
        return self.fit(theta) + (self.weight * self.prior(theta) if self.weight else 0.0)


@dataclass(frozen=True)
class ConsistentSolution:
    """A physically consistent estimate.

    Attributes
    ----------
    theta: standard parameters, shape (p,).
    beta: base parameters implied, ``P theta``, shape (r,).
    solver: "sdp" or "logchol"; status: the solver's status; iterations; time [s].
    fit: ``f(theta)`` [squared standard deviations of the LS base estimate].
    prior_distance: the unweighted prior term at theta; objective: ``fit + w prior``.
    consistency: the independent eigenvalue test of theta (not the solver's word).
    """

    theta: np.ndarray
    beta: np.ndarray
    solver: str
    status: str
    iterations: int
    time: float
    fit: float
    prior_distance: float
    objective: float
    consistency: ConsistencyReport

    @property
    def physically_consistent(self) -> bool:
        return self.consistency.consistent


# ----------------------------------------------------------------- problem
def base_map(base, p: int) -> np.ndarray:
    """The (r, p) matrix ``P`` with ``beta = P theta`` for :class:`BaseParameters` ``base``."""
    P = np.zeros((base.n_base, p))
    P[np.arange(base.n_base), base.independent] = 1.0
    P[:, base.dependent] = base.K
    return P


def build_problem(
    robot,
    base,
    A,
    b,
    *,
    variance: float,
    prior: str = "nominal",
    prior_weight: float = DEFAULT_PRIOR_WEIGHT,
    prior_parameters=None,
    n_rows: int | None = None,
    zz: float | None = None,
) -> ConsistentProblem:
    """The consistent problem of ``robot`` from the information of its base regressor.

    Parameters
    ----------
    robot: the robot (its parameter layout and nominal parameters).
    base: :class:`~manip_id.identifiability.BaseParameters` of the accumulated columns.
    A: ``Y_b^T W Y_b``, shape (r, r) [(N m)^2 / units of beta^2]; may be singular
        (directions the data do not excite are then left to the prior).
    b: ``Y_b^T W tau``, shape (r,).
    variance: the residual variance ``s`` with ``C^-1 = A / s`` (1 for weighted least
        squares whose weights are inverse variances) [(N m)^2]; floored at
        ``VARIANCE_FLOOR^2 zz / n_rows`` when ``zz`` and ``n_rows`` are given.
    prior: "nominal" or "none"; prior_weight: ``w`` >= 0.
    prior_parameters: standard parameters (p,) to use as the prior instead of the
        robot's nominal ones.
    n_rows: number of stacked equations; zz: ``tau^T W tau`` [(N m)^2].

    Raises
    ------
    InputError: unknown prior, bad weight or shapes.
    PhysicalConsistencyError: the prior itself is not physical (names the body).
    """
    if prior not in PRIORS:
        raise InputError(f"prior must be one of {list(PRIORS)}, got {prior!r}")
    w = float(prior_weight)
    if not (np.isfinite(w) and w >= 0):
        raise InputError(f"prior_weight must be a finite number >= 0, got {prior_weight!r}")
    if prior == "none":
        w = 0.0
    p, r = robot.n_parameters, base.n_base
    if len(base.names) != p:
        raise InputError(f"base is for {len(base.names)} parameters but robot has {p}")
    A = as_float_array(A, "A", ndim=2)
    b = as_float_array(b, "b", ndim=1)
    if A.shape != (r, r) or b.shape != (r,):
        raise InputError(f"A.shape={A.shape}, b.shape={b.shape} but the base has r={r}")
    s = float(variance)
    if zz is not None and n_rows:
        s = max(s, VARIANCE_FLOOR**2 * float(zz) / int(n_rows))
    if not (np.isfinite(s) and s > 0):
        raise InputError(f"variance must be positive, got {variance}")
    A = 0.5 * (A + A.T)
    lam, V = np.linalg.eigh(A)
    keep = lam > max(float(lam[-1]), 0.0) * 1e-14
    beta_ls = (V[:, keep] / lam[keep]) @ (V[:, keep].T @ b)
    W = np.sqrt(lam[keep] / s)[:, None] * V[:, keep].T  # (k, r): W^T W = A / s
    P = base_map(base, p)

    nb = robot.n_bodies
    names = list(robot.parameter_names)
    terms = [n.rsplit(".", 1)[1] for n in names[10 * nb :]]
    nonneg = np.array(
        [10 * nb + k for k, t in enumerate(terms) if t in NONNEGATIVE_TERMS], dtype=np.intp
    )
    theta0 = (
        np.array(robot.nominal_parameters, dtype=float)
        if prior_parameters is None
        else as_float_array(prior_parameters, "prior_parameters", ndim=1).copy()
    )
    if theta0.shape != (p,):
        raise InputError(f"prior_parameters.shape={theta0.shape} but robot has p={p}")
    J0 = pseudo_inertia(theta0[: 10 * nb].reshape(nb, 10))
    lam0 = np.linalg.eigvalsh(J0)
    if prior == "nominal":
        report = check_consistency(robot, np.where(np.isin(np.arange(p), nonneg), 0, theta0))
        bad = [v for v in report.violations if "." not in v.name]
        neg = [Violation(names[k], ">= 0", float(theta0[k])) for k in nonneg if theta0[k] < 0]
        if bad or neg:
            raise PhysicalConsistencyError("the prior (nominal parameters)", bad + neg)
        margin = np.minimum(MARGIN * lam0[:, -1], 0.5 * lam0[:, 0])
    else:
        scale = np.abs(lam0).max(axis=1)
        fallback = float(scale[scale > 0].mean()) if np.any(scale > 0) else 1.0
        margin = MARGIN * np.where(scale > 0, scale, fallback)
    # joint-term scales: the value that alone would explain all the (weighted) torque,
    # sqrt(zz / H_tt) with H = P^T A P; in parameter units, so that the prior weighs
    # the same whatever the noise level
    H_tt = np.einsum("it,ij,jt->t", P[:, 10 * nb :], A, P[:, 10 * nb :])
    zz_eff = float(zz) if zz is not None else float(beta_ls @ A @ beta_ls)
    ref = np.abs(theta0[10 * nb :])
    with np.errstate(divide="ignore", invalid="ignore"):
        term_scale = np.sqrt(zz_eff / H_tt)
    term_scale = np.where(
        np.isfinite(term_scale) & (term_scale > 0), term_scale, np.where(ref > 0, ref, 1.0)
    )
    return ConsistentProblem(
        P=P,
        beta_ls=beta_ls,
        W=W,
        n_bodies=nb,
        nonnegative=nonneg,
        theta0=theta0,
        J0=J0 - margin[:, None, None] * np.eye(4) if w > 0 else None,
        term_scale=term_scale,
        margin=margin,
        weight=w,
        independent=np.asarray(base.independent, dtype=np.intp),
        dependent=np.asarray(base.dependent, dtype=np.intp),
        names=names,
    )


def solve_consistent(
    robot, problem: ConsistentProblem, *, solver: str = "sdp", **options
) -> ConsistentSolution:
    """Solve ``problem`` with ``solver`` ("sdp" or "logchol"); check the result independently.

    Options: ``sdp``: ``tolerance`` (Clarabel's gap/feasibility tolerances, default
    1e-8), ``max_iter``; ``logchol``: ``max_iter`` (default 500), ``tolerance``
    (relative decrease/gradient, default 1e-13), ``theta_start`` (a consistent start).
    Raises :class:`SolverError` with the solver's status on failure or infeasibility.
    """
    if solver not in SOLVERS:
        raise InputError(f"solver must be one of {list(SOLVERS)}, got {solver!r}")
    t0 = time.perf_counter()
    if solver == "sdp":
        theta, status, iters = solve_sdp(problem, **options)
    else:
        theta, status, iters = _solve_logchol(problem, **options)
    elapsed = time.perf_counter() - t0
    theta, moved = _project(problem, theta)
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


# --------------------------------------------------------------------- SDP
def _project(pr: ConsistentProblem, theta: np.ndarray) -> tuple[np.ndarray, float]:
    """Project an interior-point result onto the constraints it misses by round-off.

    Each body whose ``J_i`` has an eigenvalue below ``eps_i`` gets those eigenvalues
    raised to ``eps_i`` (the nearest matrix with ``J >= eps 1`` in the Frobenius norm);
    negative ``Ia, fv, fc`` become 0. Returns the vector and the largest change of a
    parameter; the result is still checked independently afterwards.
    """
    from ..consistency import parameters_from_pseudo_inertia

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


def solve_sdp(problem: ConsistentProblem, *, tolerance: float = 1e-8, max_iter: int = 500):
    """Solve ``problem`` as a semidefinite program (cvxpy with Clarabel), unchecked.

    Every body's pseudo-inertia is constrained to ``J_i >= margin_i 1`` (one 4 x 4 LMI
    each), the joint terms in ``problem.nonnegative`` to ``>= 0``. Returns
    ``(theta, status, iterations)``; :func:`solve_consistent` adds the independent
    check. Also the one-body payload solve of :mod:`manip_id.payload`.
    """
    import cvxpy as cp

    pr = problem
    nb, p = pr.n_bodies, pr.p
    E = pseudo_inertia_basis().reshape(10, 16).T  # vec(J_i) = E @ pi_i (row-major vec)
    eye_vec = np.eye(4).ravel()
    # theta = G (beta_ls + W^+ u + V_0 v) + N z: the fit is ||u||^2 exactly, and the
    # ill-conditioning of a nearly noise-free fit becomes a column scaling of u that
    # the solver's equilibration removes (in theta it would be a dense ill-conditioned W P).
    r = pr.P.shape[0]
    G, N = _row_and_null_maps(pr)
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
    Js = [cp.Variable((4, 4), symmetric=True) for _ in range(nb)]
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
    opts = dict(
        tol_gap_abs=tolerance,
        tol_gap_rel=tolerance,
        tol_feas=tolerance,
        tol_ktratio=1e-8,
        max_iter=int(max_iter),
    )
    # The interior-point method stalls on badly scaled objectives (a fit of 1e4 squared
    # standard deviations when least squares is far from physical): retry with the
    # objective divided by growing scales; the minimizer does not change.
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
            return (
                value,
                status + (f" (objective scaled by 1/{scale:g})" if scale != 1 else ""),
                iters,
            )
        if best is None:
            best = (value, status, iters)
    if best is not None:
        return best
    infeasible = any("infeasible" in st for st in statuses)
    what = "the problem is infeasible" if infeasible else "no solution"
    raise SolverError(what, "sdp", "; ".join(statuses))


def _row_and_null_maps(pr: ConsistentProblem) -> tuple[np.ndarray, np.ndarray]:
    """``G`` (p, r) with ``P G = 1`` and ``N`` (p, p - r) with ``P N = 0``.

    ``G`` scatters ``beta`` onto the independent columns; column ``d`` of ``N`` is
    ``e_d - G K[:, d]``, one unidentifiable direction per dependent parameter.
    """
    r, p = pr.P.shape
    ind, dep = pr.independent, pr.dependent
    G = np.zeros((p, r))
    G[ind, np.arange(r)] = 1.0
    N = np.zeros((p, dep.size))
    N[dep, np.arange(dep.size)] = 1.0
    N[ind] -= pr.P[:, dep]
    return G, N


# ------------------------------------------------------------ log-Cholesky
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


_SHIFT = None


def _margin_shift() -> np.ndarray:
    """Body parameters of ``J = 1`` (4x4 identity): ``[1, 0, 0, 0, 2, 0, 2, 0, 0, 2]``."""
    global _SHIFT
    if _SHIFT is None:
        from ..consistency import parameters_from_pseudo_inertia

        _SHIFT = parameters_from_pseudo_inertia(np.eye(4))
    return _SHIFT


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
        import pinocchio as pin

        self.pin = pin
        self.pr = pr
        nb, p = pr.n_bodies, pr.p
        self.nb = nb
        self.nonneg = np.zeros(p - 10 * nb, dtype=bool)
        self.nonneg[pr.nonnegative - 10 * nb] = True
        self.shift = _margin_shift()
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
            lc = self.pin.LogCholeskyParameters(eta)
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
                Jt[sl, sl] = self.pin.LogCholeskyParameters(x[sl]).calculateJacobian()
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


def _solve_logchol(
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
        G, _ = _row_and_null_maps(pr)
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
    with np.errstate(over="ignore", invalid="ignore"):  # trial steps may overflow exp()
        return _lm(model, pr, x, max_iter, tolerance)


def _lm(model: _LogChol, pr: ConsistentProblem, x: np.ndarray, max_iter: int, tolerance: float):
    """Levenberg-Marquardt with Newton's clipped curvature and a second-order correction."""
    import scipy.linalg as sla

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


# ------------------------------------------------------- identification glue
@dataclass(frozen=True)
class StandardEstimate:
    """The standard parameters behind an identification, with their physical check.

    Attributes
    ----------
    names, units: of each standard parameter, length p.
    values: the standard parameters, shape (p,): the consistent estimate, or for
        plain least squares the minimum-norm standard vector with the LS base parameters.
    nominal: the robot's nominal (URDF) parameters, shape (p,).
    consistency: the independent eigenvalue test of ``values``.
    solver, status, time: how the consistent estimate was solved ("" for plain LS) [s].
    prior, prior_weight: the prior used.
    base_shift_std: largest ``|beta - beta_ls| / std(beta_ls)`` over the base parameters:
        how far physical consistency (and the prior) moved the fit [OLS standard deviations].
    fit, prior_distance: objective terms of the consistent solve (module docstring);
        ``fit`` in squared OLS standard deviations.
    fit_scale: ``k = max(1, f_feas / r)``: the fit of the feasibility solve against its
        expected value; the prior weight applies to the fit divided by ``k`` (1 on white
        noise; large when the residuals are correlated and the OLS covariance too small).
    prior_shift_std: largest ``|beta - beta_feas| / (sqrt(k) std(beta_ls))``: how far the
        prior moved the fit beyond what physical consistency needs [honest standard
        deviations]; the default weight keeps it below 1.
    """

    names: list[str]
    units: list[str]
    values: np.ndarray
    nominal: np.ndarray
    consistency: ConsistencyReport
    solver: str = ""
    status: str = ""
    time: float = 0.0
    prior: str = ""
    prior_weight: float = 0.0
    base_shift_std: float = 0.0
    fit: float = 0.0
    prior_distance: float = 0.0
    fit_scale: float = 1.0
    prior_shift_std: float = 0.0

    @property
    def physically_consistent(self) -> bool:
        return self.consistency.consistent

    def to_dict(self) -> dict:
        """JSON-ready: ``standard_parameters`` rows, ``physically_consistent``, the check
        (per-body minimum eigenvalues, violations) and ``consistent_solver`` (None for
        the minimum-norm vector of plain least squares)."""
        return {
            "standard_parameters": [
                {"name": n, "value": float(v), "unit": u, "nominal": float(x0)}
                for n, v, u, x0 in zip(
                    self.names, self.values, self.units, self.nominal, strict=True
                )
            ],
            "standard_parameters_kind": "consistent" if self.solver else "minimum norm",
            "physically_consistent": bool(self.consistency.consistent),
            "consistency": self.consistency.to_dict(),
            "consistent_solver": None
            if not self.solver
            else {
                "solver": self.solver,
                "status": self.status,
                "time": round(float(self.time), 6),
                "prior": self.prior,
                "prior_weight": float(self.prior_weight),
                "base_shift_std": float(self.base_shift_std),
                "fit": _finite(self.fit),
                "prior_distance": _finite(self.prior_distance),
                "fit_scale": _finite(self.fit_scale),
                "prior_shift_std": _finite(self.prior_shift_std),
            },
        }

    def summary_lines(self) -> list[str]:
        """Readable lines: the check, the per-body minimum eigenvalues and the solver."""
        c = self.consistency
        kind = (
            f"consistent estimate ({self.solver}, {self.status}, {self.time:.3g} s, prior "
            f"{self.prior}, weight {self.prior_weight:g} against the fit in units of "
            f"{self.fit_scale:.3g} x the OLS covariance; base fit moved by at most "
            f"{self.base_shift_std:.3g} OLS std, by the prior {self.prior_shift_std:.3g} "
            "of these std)"
            if self.solver
            else "minimum-norm standard parameters of the least-squares fit"
        )
        lines = [
            f"{kind}: physically consistent {'yes' if c.consistent else 'NO'}",
            "min eigenvalue of each pseudo-inertia J: "
            + ", ".join(
                f"{n} {v:.3g}" for n, v in zip(c.body_names, c.min_eigenvalues, strict=True)
            ),
        ]
        return lines


def _finite(x: float) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def check_options(solver: str, prior: str, prior_weight: float) -> None:
    """Raise :class:`InputError` for an unknown solver or prior, or a bad prior weight."""
    if solver not in SOLVERS:
        raise InputError(f"solver must be one of {list(SOLVERS)}, got {solver!r}")
    if prior not in PRIORS:
        raise InputError(f"prior must be one of {list(PRIORS)}, got {prior!r}")
    try:
        w = float(prior_weight)
    except (TypeError, ValueError) as exc:
        raise InputError(f"prior_weight must be a number >= 0, got {prior_weight!r}") from exc
    if not (np.isfinite(w) and w >= 0):
        raise InputError(f"prior_weight must be a finite number >= 0, got {prior_weight!r}")


def consistent_estimate(
    robot,
    acc,
    base,
    ls,
    *,
    solver: str = "sdp",
    prior: str = "nominal",
    prior_weight: float = DEFAULT_PRIOR_WEIGHT,
    prior_parameters=None,
) -> StandardEstimate:
    """Consistent standard parameters from an accumulator of the base columns and its LS fit.

    ``acc`` is the :class:`~manip_id.estimators.InformationAccumulator` of the base
    regressor, ``ls`` its :class:`~manip_id.estimators.LeastSquaresSolution`: ordinary
    (fit measured with ``C^-1 = A / sigma^2``) or weighted (``ls.weights``: the
    weighted sums, ``C^-1 = A_w``). Raises :class:`SolverError` on a solver failure or
    an infeasible problem, :class:`PhysicalConsistencyError` for a non-physical prior.

    Two solves with ``solver``. The scale solve (prior at :data:`SCALE_WEIGHT`, nearly
    feasibility alone) gives the least fit ``f_feas`` any physical model reaches and
    its base parameters ``beta_feas``; the fit scale is ``k = max(1, f_feas / r)`` for
    the ``r`` identified base directions. ``f_feas`` is a chi-square with at most ``r``
    degrees of freedom when the covariance is honest and the robot physical (it is
    near 0 on white noise); far above ``r`` it says by how much ``C`` is too small at
    least. The estimate then solves with the prior weight ``w k``: the prior counts
    ``w`` against the fit in honest standard deviations, whatever the residuals'
    correlation. ``prior="none"``: one solve, ``k`` reported only.
    """
    check_options(solver, prior, prior_weight)
    if ls.weights is None:
        A, b, zz, variance = acc.A, acc.b, acc.zz, ls.sigma2
    else:
        A, b, zz = acc.weighted(ls.weights)
        variance = 1.0
    w = float(prior_weight)
    problem = build_problem(
        robot,
        base,
        A,
        b,
        variance=variance,
        prior=prior,
        prior_weight=SCALE_WEIGHT if prior != "none" else 0.0,
        prior_parameters=prior_parameters,
        n_rows=acc.n_rows,
        zz=zz,
    )
    feas = solve_consistent(robot, problem, solver=solver)
    scale = max(1.0, feas.fit / max(int(problem.W.shape[0]), 1))  # k = max(1, f_feas / r)
    sol, elapsed = feas, feas.time
    if prior != "none":
        problem = replace(problem, weight=w * scale)
        sol = solve_consistent(robot, problem, solver=solver)
        elapsed += sol.time
    std = np.sqrt(np.maximum(np.diag(ls.covariance), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.abs(sol.beta - ls.estimate) / std
        moved = np.abs(sol.beta - feas.beta) / (np.sqrt(scale) * std)
    shift = shift[np.isfinite(shift)]
    moved = moved[np.isfinite(moved)]
    return StandardEstimate(
        names=list(robot.parameter_names),
        units=list(robot.parameter_units),
        values=sol.theta,
        nominal=np.array(robot.nominal_parameters, dtype=float),
        consistency=sol.consistency,
        solver=solver,
        status=sol.status,
        time=elapsed,
        prior=prior,
        prior_weight=w if prior != "none" else 0.0,
        base_shift_std=float(shift.max()) if shift.size else 0.0,
        fit=sol.fit,
        prior_distance=sol.prior_distance,
        fit_scale=scale,
        prior_shift_std=float(moved.max()) if moved.size else 0.0,
    )


def minimum_norm_standard(robot, base, beta) -> StandardEstimate:
    """The minimum-norm standard vector ``P^+ beta`` of base parameters ``beta``, checked.

    Plain least squares identifies only ``beta``; this is the standard vector a
    user gets by the pseudo-inverse, and its eigenvalue test says whether the fit
    is physical (the null space may hold a physical one: ``consistent=True`` finds it).
    """
    P = base_map(base, robot.n_parameters)
    theta = np.linalg.lstsq(P, np.asarray(beta, dtype=float), rcond=None)[0]
    return StandardEstimate(
        names=list(robot.parameter_names),
        units=list(robot.parameter_units),
        values=theta,
        nominal=np.array(robot.nominal_parameters, dtype=float),
        consistency=check_consistency(robot, theta),
        prior="minimum norm",
    )
