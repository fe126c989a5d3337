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

where ``J_i`` is body i's pseudo-inertia (:mod:`manip_id.physics.consistency`) and

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

Modules: :mod:`~manip_id.estimators.consistent.problem` (the problem and its pieces),
:mod:`~manip_id.estimators.consistent.sdp` and
:mod:`~manip_id.estimators.consistent.logchol` (the two solvers),
:mod:`~manip_id.estimators.consistent.solve` (one entry, projection, independent check),
:mod:`~manip_id.estimators.consistent.estimate` (the estimate of an identification).
"""

from ...errors import SolverError
from .estimate import StandardEstimate, consistent_estimate, minimum_norm_standard
from .logchol import log_cholesky, solve_logchol
from .problem import (
    DEFAULT_PRIOR_WEIGHT,
    MARGIN,
    PRIORS,
    SCALE_WEIGHT,
    SOLVERS,
    VARIANCE_FLOOR,
    ConsistentProblem,
    ConsistentSolution,
    PriorOptions,
    base_map,
    build_problem,
    check_options,
    nonnegative_terms,
    row_and_null_maps,
)
from .sdp import OBJECTIVE_SCALES, solve_sdp
from .solve import project, solve_consistent

__all__ = [
    "DEFAULT_PRIOR_WEIGHT",
    "MARGIN",
    "OBJECTIVE_SCALES",
    "PRIORS",
    "SCALE_WEIGHT",
    "SOLVERS",
    "VARIANCE_FLOOR",
    "ConsistentProblem",
    "ConsistentSolution",
    "PriorOptions",
    "SolverError",
    "StandardEstimate",
    "base_map",
    "build_problem",
    "check_options",
    "consistent_estimate",
    "log_cholesky",
    "minimum_norm_standard",
    "nonnegative_terms",
    "project",
    "row_and_null_maps",
    "solve_consistent",
    "solve_logchol",
    "solve_sdp",
]
