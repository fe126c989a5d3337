"""The standard parameters behind an identification: the consistent estimate and its check.

:func:`consistent_estimate` runs the scale solve and the estimate of
:mod:`manip_id.estimators.consistent` on an accumulator and its least-squares fit;
:func:`minimum_norm_standard` is what plain least squares gives. Both return a
:class:`StandardEstimate` carrying the independent eigenvalue test of its values.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...metrics import finite_or_none
from ...physics.consistency import (
    ConsistencyReport,
    PlausibilityReport,
    check_consistency,
    check_plausibility,
)
from .bounds import BodyBounds, BoundsOptions, body_bounds
from .covariance import active_constraints, sensitivity
from .problem import (
    DEFAULT_PRIOR_WEIGHT,
    SCALE_WEIGHT,
    PriorOptions,
    base_map,
    build_problem,
    check_options,
)
from .provenance import parameter_sources
from .solve import solve_consistent


@dataclass(frozen=True)
class StandardEstimate:
    """The standard parameters behind an identification, with their physical check.

    Attributes
    ----------
    names, units
        of each standard parameter, length p.
    values
        the standard parameters, shape (p,): the consistent estimate, or for
        plain least squares the minimum-norm standard vector with the LS base parameters.
    nominal
        the robot's nominal (URDF) parameters, shape (p,).
    consistency
        the independent eigenvalue test of ``values``.
    solver, status, time
        how the consistent estimate was solved ("" for plain LS) [s].
    prior, prior_weight
        the prior used.
    base_shift_std
        largest ``|beta - beta_ls| / std(beta_ls)`` over the base parameters:
        how far physical consistency (and the prior) moved the fit [OLS standard deviations].
    fit, prior_distance
        objective terms of the consistent solve (module docstring);
        ``fit`` in squared OLS standard deviations.
    fit_scale
        ``k = max(1, f_feas / r)``: the fit of the feasibility solve against its
        expected value; the prior weight applies to the fit divided by ``k`` (1 on white
        noise; large when the residuals are correlated and the OLS covariance too small).
    prior_shift_std
        largest ``|beta - beta_feas| / (sqrt(k) std(beta_ls))``: how far the
        prior moved the fit beyond what physical consistency needs [honest standard
        deviations]; the default weight keeps it below 1.
    bounds
        the plausibility bounds the estimate was solved with (None for none).
    plausibility
        per body, mass against nominal and position against its bounding
        ellipsoid (:func:`manip_id.physics.consistency.check_plausibility`); None for plain LS.
    warnings
        what the user should know about these values (implausible bodies).
    sensitivity
        ``G = d theta / d beta_ls`` at the solution, shape (p, r)
        (:mod:`manip_id.estimators.consistent.covariance`); None for plain LS.
    active
        the bodies and joint terms whose constraints are active at the solution (their
        std hold on the constraints' tangent).
    std, std_white
        the honest and the white-noise std of ``values``, shape (p,), once
        :meth:`with_covariance` gave the base covariances (None before).
    sources
        where each value comes from, length p: "data", "prior", "bound" or "not
        determined" (:mod:`manip_id.estimators.consistent.provenance`); only "data"
        values have a std in :meth:`to_dict` (None when not known).
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
    bounds: BodyBounds | None = None
    plausibility: PlausibilityReport | None = None
    warnings: list[str] = field(default_factory=list)
    sensitivity: np.ndarray | None = None
    active: list[str] = field(default_factory=list)
    std: np.ndarray | None = None
    std_white: np.ndarray | None = None
    sources: list[str] | None = None

    def with_covariance(self, honest, white) -> StandardEstimate:
        """The estimate with ``std`` and ``std_white`` from the base covariances ``honest``
        and ``white`` of ``beta_ls`` (r, r): ``sqrt(diag(G C G^T))``."""
        if self.sensitivity is None:
            return self
        G = self.sensitivity

        def std(C):
            return np.sqrt(np.clip(np.einsum("ia,ab,ib->i", G, np.asarray(C, float), G), 0, None))

        return replace(self, std=std(honest), std_white=std(white))

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
                | self._std_entries(k)
                for k, (n, v, u, x0) in enumerate(
                    zip(self.names, self.values, self.units, self.nominal, strict=True)
                )
            ],
            "constraints_active": list(self.active),
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
                "fit": finite_or_none(self.fit),
                "prior_distance": finite_or_none(self.prior_distance),
                "fit_scale": finite_or_none(self.fit_scale),
                "prior_shift_std": finite_or_none(self.prior_shift_std),
            },
            "plausibility": self._plausibility_dict(),
        }

    def _std_entries(self, k: int) -> dict:
        source = {} if self.sources is None else {"source": self.sources[k]}
        if self.std is None or self.std_white is None:
            return source
        if source and source["source"] != "data":  # the prior's or the bound's: no data std
            return source | {"std": None, "std_white": None}
        return source | {
            "std": finite_or_none(float(self.std[k])),
            "std_white": finite_or_none(float(self.std_white[k])),
        }

    def _plausibility_dict(self) -> dict | None:
        if self.plausibility is None:
            return None
        out = self.plausibility.to_dict()
        out["bounds"] = None if self.bounds is None else self.bounds.to_dict()
        return out


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
    bounds: BoundsOptions | None = None,
) -> StandardEstimate:
    """Consistent standard parameters from an accumulator of the base columns and its LS fit.

    ``acc`` is the :class:`~manip_id.estimators.InformationAccumulator` of the base
    regressor, ``ls`` its :class:`~manip_id.estimators.LeastSquaresSolution`: ordinary
    (fit measured with ``C^-1 = A / sigma^2``) or weighted (``ls.weights``: the
    weighted sums, ``C^-1 = A_w``). ``bounds``: the plausibility bounds
    (:class:`~manip_id.estimators.consistent.bounds.BoundsOptions`; default: each body
    inside the bounding ellipsoid of its link). Raises :class:`SolverError` on a solver
    failure or an infeasible problem, :class:`PhysicalConsistencyError` for a
    non-physical prior.

    Two solves with ``solver``. The scale solve (prior at :data:`SCALE_WEIGHT`, nearly
    feasibility alone) gives the least fit ``f_feas`` any physical model reaches and
    its base parameters ``beta_feas``; the fit scale is ``k = max(1, f_feas / r)`` for
    the ``r`` identified base directions. ``f_feas`` is a chi-square with at most ``r``
    degrees of freedom when the covariance is honest and the robot physical (it is
    near 0 on white noise); far above ``r`` it says by how much ``C`` is too small at
    least. The estimate then solves with the prior weight ``w k``. The result carries
    its plausibility (masses against nominal, bodies against their ellipsoids) and a
    warning naming each implausible body.
    """
    check_options(solver, prior, prior_weight)
    bounds = BoundsOptions() if bounds is None else bounds
    if ls.weights is None:
        A, b, zz, variance = acc.A, acc.b, acc.zz, ls.sigma2
    else:
        A, b, zz = acc.weighted(ls.weights)
        variance = 1.0
    problem = build_problem(
        robot,
        base,
        A,
        b,
        variance=variance,
        n_rows=acc.n_rows,
        zz=zz,
        prior=PriorOptions(
            prior, SCALE_WEIGHT if prior != "none" else 0.0, parameters=prior_parameters
        ),
    )
    problem = replace(problem, bounds=body_bounds(robot, bounds))
    feas = solve_consistent(robot, problem, solver=solver)
    scale = max(1.0, feas.fit / max(int(problem.W.shape[0]), 1))  # k = max(1, f_feas / r)
    sol, elapsed = feas, feas.time
    if prior != "none":
        sol = solve_consistent(robot, replace(problem, weight=prior_weight * scale), solver=solver)
        elapsed += sol.time
    final = replace(problem, weight=prior_weight * scale) if prior != "none" else problem
    est = _estimate(robot, problem, ls, feas, sol, scale, elapsed, prior_weight)
    names = [robot.parameter_names[10 * i].split(".")[0] for i in range(problem.n_bodies)]
    held = active_constraints(final, sol.theta)
    return replace(
        est,
        sensitivity=sensitivity(final, sol.theta),
        active=[names[i] for i in held.bodies] + [robot.parameter_names[t] for t in held.terms],
        sources=parameter_sources(problem.P, held.rows, prior=prior != "none"),
    )


def _estimate(robot, problem, ls, feas, sol, scale: float, elapsed: float, weight: float):
    """The :class:`StandardEstimate` of a solved problem: shifts, plausibility, warnings."""
    std = np.sqrt(np.maximum(np.diag(ls.covariance), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.abs(sol.beta - ls.estimate) / std
        moved = np.abs(sol.beta - feas.beta) / (np.sqrt(scale) * std)
    shift = shift[np.isfinite(shift)]
    moved = moved[np.isfinite(moved)]
    bounds = problem.bounds
    ellipsoids = None if bounds is None else bounds.ellipsoids
    plausibility = check_plausibility(robot, sol.theta, ellipsoids)
    prior = "none" if problem.J0 is None else "nominal"
    return StandardEstimate(
        names=list(robot.parameter_names),
        units=list(robot.parameter_units),
        values=sol.theta,
        nominal=np.array(robot.nominal_parameters, dtype=float),
        consistency=sol.consistency,
        solver=sol.solver,
        status=sol.status,
        time=elapsed,
        prior=prior,
        prior_weight=float(weight) if prior != "none" else 0.0,
        base_shift_std=float(shift.max()) if shift.size else 0.0,
        fit=sol.fit,
        prior_distance=sol.prior_distance,
        fit_scale=scale,
        prior_shift_std=float(moved.max()) if moved.size else 0.0,
        bounds=bounds,
        plausibility=plausibility,
        warnings=plausibility_warnings(plausibility, bounds),
    )


def plausibility_warnings(report: PlausibilityReport, bounds: BodyBounds | None = None):
    """One warning naming each implausible body (none when every body is plausible); a
    body whose mass sits on its ``mass_range`` bound is said to be held there."""
    if report.plausible:
        return []
    lo, hi = 1.0 / report.ratio_limit, report.ratio_limit
    held = set()
    if bounds is not None and bounds.mass_range is not None:
        for b, (m_lo, m_hi) in zip(report.bodies, bounds.mass_range, strict=True):
            if min(abs(b.mass - m_lo), abs(b.mass - m_hi)) <= 1e-4 * max(abs(b.mass), 1e-12):
                held.add(b.name)
    texts = [
        b.message()
        + (" (held at its mass bound: the data push it further)" if b.name in held else "")
        for b in report.implausible
    ]
    return [
        f"implausible link parameters (physically consistent, but outside {lo:.2g}-{hi:.2g}x "
        "the nominal mass or the link's bounding ellipsoid): "
        + "; ".join(texts)
        + " (check the model's joint terms, e.g. --armature or --friction; or bound the "
        "masses: --mass-range, --total-mass)"
    ]


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
        sources=parameter_sources(P, prior=False),
    )
