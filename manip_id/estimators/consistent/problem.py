"""The consistent problem: the fit of the base parameters, the prior, the margins.

``f(theta) = ||W (P theta - beta_ls)||^2`` (``W^T W = C^-1``) measures a standard
vector against the least-squares base estimate; the prior is the log-det divergence
of each body's pseudo-inertia from the nominal one plus scaled squares of the joint
terms. :func:`build_problem` builds both from the streamed information ``A, b`` of
the base regressor; the math is in :mod:`manip_id.estimators.consistent`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..._checks import as_float_array
from ...errors import InputError, PhysicalConsistencyError
from ...physics.consistency import (
    NONNEGATIVE_TERMS,
    ConsistencyReport,
    Violation,
    check_consistency,
    pseudo_inertia,
)
from .bounds import BodyBounds

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


@dataclass(frozen=True)
class PriorOptions:
    """The prior of a consistent problem.

    Attributes
    ----------
    prior : str
        "nominal" (the log-det divergence from ``parameters``) or "none".
    weight : float
        Its weight ``w >= 0`` against the fit.
    parameters : array_like of shape (p,) or None
        Standard parameters to use as the prior instead of the robot's nominal ones.
    """

    prior: str = "nominal"
    weight: float = DEFAULT_PRIOR_WEIGHT
    parameters: ArrayLike | None = None


@dataclass(frozen=True)
class ConsistentProblem:
    """The fit and the prior of a consistent estimate (see the module docstring).

    Attributes
    ----------
    P
        base map, shape (r, p): ``beta = P theta``.
    beta_ls
        unconstrained least-squares base parameters, shape (r,).
    W
        whitening, shape (r, r): ``f(theta) = ||W (P theta - beta_ls)||^2`` (``W^T W = C^-1``).
    n_bodies
        bodies; the first ``10 n_bodies`` entries of theta are theirs.
    nonnegative
        indices of the joint terms constrained ``>= 0``.
    theta0
        the prior's standard parameters (or the reference point when none), (p,).
    J0
        prior pseudo-inertias less their margins, ``J0_i - eps_i 1``, shape
        (n_bodies, 4, 4) (None without a prior).
    term_scale
        ``s_t`` of each joint term, shape (p - 10 n_bodies,).
    margin
        ``eps_i`` per body, shape (n_bodies,).
    weight
        prior weight ``w`` (0 for no prior).
    independent, dependent
        the base parametrization's column indices.
    names
        standard parameter names.
    bounds
        the plausibility bounds (:class:`~manip_id.estimators.consistent.bounds.BodyBounds`:
        bounding ellipsoids, mass ranges, total mass), linear in theta; None for none.
    linear
        rows ``G`` (m, p) of the linear constraints ``G theta >= 0`` of the temperature
        law (:func:`temperature_rows`); None for none.
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
    bounds: BodyBounds | None = None
    linear: np.ndarray | None = None

    def linear_violations(self, theta: np.ndarray, tol: float = 1e-9) -> list[str]:
        """The rows of :attr:`linear` that ``theta`` breaks by more than ``tol`` times
        the largest coefficient of the row's terms, as text."""
        if self.linear is None:
            return []
        g = self.linear @ theta
        scale = np.abs(self.linear) @ np.abs(theta) + 1e-300
        return [
            f"{TEMPERATURE_ROW_TEXT} row {k}: {g[k]:.3g}" for k in np.flatnonzero(g < -tol * scale)
        ]

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
    theta
        standard parameters, shape (p,).
    beta
        base parameters implied, ``P theta``, shape (r,).
    solver
        "sdp" or "logchol"; status: the solver's status; iterations; time [s].
    fit
        ``f(theta)`` [squared standard deviations of the LS base estimate].
    prior_distance
        the unweighted prior term at theta; objective: ``fit + w prior``.
    consistency
        the independent eigenvalue test of theta (not the solver's word).
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
    n_rows: int | None = None,
    zz: float | None = None,
    prior: PriorOptions | None = None,
) -> ConsistentProblem:
    """The consistent problem of ``robot`` from the information of its base regressor.

    Parameters
    ----------
    robot
        the robot (its parameter layout and nominal parameters).
    base
        :class:`~manip_id.identifiability.BaseParameters` of the accumulated columns.
    A
        ``Y_b^T W Y_b``, shape (r, r) [(N m)^2 / units of beta^2]; may be singular
        (directions the data do not excite are then left to the prior).
    b
        ``Y_b^T W tau``, shape (r,).
    variance
        the residual variance ``s`` with ``C^-1 = A / s`` (1 for weighted least
        squares whose weights are inverse variances) [(N m)^2]; floored at
        ``VARIANCE_FLOOR^2 zz / n_rows`` when ``zz`` and ``n_rows`` are given.
    n_rows
        number of stacked equations; zz: ``tau^T W tau`` [(N m)^2].
    prior
        the prior (:class:`PriorOptions`: kind, weight ``w`` >= 0, parameters instead
        of the robot's nominal ones); default the nominal prior of weight
        :data:`DEFAULT_PRIOR_WEIGHT`.

    Raises
    ------
    InputError
        unknown prior, bad weight or shapes.
    PhysicalConsistencyError
        the prior itself is not physical (names the body).
    """
    prior = PriorOptions() if prior is None else prior
    w = _prior_weight(prior.prior, prior.weight)
    p = robot.n_parameters
    A, b = _checked_information(robot, base, A, b)
    beta_ls, W = _whitened_fit(A, b, variance, zz, n_rows)
    P = base_map(base, p)
    nb = robot.n_bodies
    nonneg = nonnegative_terms(robot)
    theta0 = (
        np.array(robot.nominal_parameters, dtype=float)
        if prior.parameters is None
        else as_float_array(prior.parameters, "prior_parameters", ndim=1).copy()
    )
    if theta0.shape != (p,):
        raise InputError(f"prior_parameters.shape={theta0.shape} but robot has p={p}")
    J0, margin = _prior_margins(robot, theta0, prior.prior, nonneg)
    term_scale = _term_scales(P, 0.5 * (A + A.T), nb, beta_ls, theta0, zz)
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
        names=list(robot.parameter_names),
        linear=temperature_rows(robot),
    )


def _prior_weight(prior: str, prior_weight) -> float:
    """The prior's weight ``w`` (0 for ``prior="none"``), checked."""
    if prior not in PRIORS:
        raise InputError(f"prior must be one of {list(PRIORS)}, got {prior!r}")
    w = float(prior_weight)
    if not (np.isfinite(w) and w >= 0):
        raise InputError(f"prior_weight must be a finite number >= 0, got {prior_weight!r}")
    return 0.0 if prior == "none" else w


def _checked_information(robot, base, A, b) -> tuple[np.ndarray, np.ndarray]:
    """``A`` (r, r) and ``b`` (r,) as arrays, checked against ``base`` and the robot."""
    p, r = robot.n_parameters, base.n_base
    if len(base.names) != p:
        raise InputError(f"base is for {len(base.names)} parameters but robot has {p}")
    A = as_float_array(A, "A", ndim=2)
    b = as_float_array(b, "b", ndim=1)
    if A.shape != (r, r) or b.shape != (r,):
        raise InputError(f"A.shape={A.shape}, b.shape={b.shape} but the base has r={r}")
    return A, b


def nonnegative_terms(robot) -> np.ndarray:
    """Indices of the joint terms that must be ``>= 0`` (``Ia, fv, fc``) in ``theta``."""
    nb10 = 10 * robot.n_bodies
    terms = [n.rsplit(".", 1)[1] for n in robot.parameter_names[nb10:]]
    return np.array(
        [nb10 + k for k, t in enumerate(terms) if t in NONNEGATIVE_TERMS], dtype=np.intp
    )


#: What a row of :func:`temperature_rows` keeps non-negative.
TEMPERATURE_ROW_TEXT = "fv(T) or fc(T) >= 0 at the training temperature range's ends"


def temperature_rows(robot) -> np.ndarray | None:
    """Rows ``G`` (m, p) with ``G theta >= 0`` the temperature law's physical friction over
    the training range: per DoF ``j`` that carries ``fvt`` (``fct``), at ``T`` the ends
    ``temperature_low_j``, ``temperature_high_j`` of the shapes::

        fv_j + fvt_j (T - T0_j) >= 0        fc_j + fct_j (T - T0_j) >= 0

    (``fv_j`` absent: its coefficient 0). None when the robot has no such term or its
    shapes no range."""
    layout, shapes = robot.layout, robot.layout.shapes
    if not layout.needs_temperature or shapes is None or shapes.temperature_low is None:
        return None
    t0 = shapes.values("temperature_reference", 0.0) * np.ones(robot.nv)
    ends = (np.asarray(shapes.temperature_low), np.asarray(shapes.temperature_high))
    mask = np.ones((robot.nv, len(layout.terms)), bool) if layout.mask is None else layout.mask
    rows = []
    for base_term, slope in (("fv", "fvt"), ("fc", "fct")):
        if slope not in layout.terms:
            continue
        cols_s = layout.joint_columns(slope)
        cols_b = layout.joint_columns(base_term) if base_term in layout.terms else None
        for j in np.flatnonzero(mask[:, layout.terms.index(slope)]):
            for end in ends:
                g = np.zeros(robot.n_parameters)
                g[cols_s[j]] = end[j] - t0[j]
                if cols_b is not None and mask[j, layout.terms.index(base_term)]:
                    g[cols_b[j]] = 1.0
                rows.append(g)
    return np.array(rows) if rows else None


def _whitened_fit(A, b, variance, zz, n_rows) -> tuple[np.ndarray, np.ndarray]:
    """``(beta_ls, W)``: the least-squares base estimate (minimum norm on a singular ``A``)
    and the whitening ``W`` (k, r) with ``W^T W = A / s`` on the range of ``A``; ``s`` is
    the variance floored at ``VARIANCE_FLOOR^2 zz / n_rows``."""
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
    return beta_ls, W


def _prior_margins(robot, theta0, prior: str, nonneg) -> tuple[np.ndarray, np.ndarray]:
    """``(J0, eps)``: the prior's pseudo-inertias (n_bodies, 4, 4) and each body's margin.

    With the nominal prior, ``eps_i = min(MARGIN lambda_max(J0_i), lambda_min(J0_i) / 2)``
    and a non-physical prior raises :class:`PhysicalConsistencyError` naming the body;
    without one, ``eps_i = MARGIN max|lambda(J0_i)|``.
    """
    nb, p = robot.n_bodies, robot.n_parameters
    names = robot.parameter_names
    J0 = pseudo_inertia(theta0[: 10 * nb].reshape(nb, 10))
    lam0 = np.linalg.eigvalsh(J0)
    if prior == "nominal":
        report = check_consistency(robot, np.where(np.isin(np.arange(p), nonneg), 0, theta0))
        bad = [v for v in report.violations if "." not in v.name]
        neg = [Violation(names[k], ">= 0", float(theta0[k])) for k in nonneg if theta0[k] < 0]
        if bad or neg:
            named = list(dict.fromkeys(v.name for v in bad))
            hint = (
                f" (bodies {', '.join(named)}; 'manip-id repair ROBOT OUT.urdf' writes the "
                "nearest physical model to identify from, or prior='none' / --prior none)"
                if named
                else " (prior='none' / --prior none does without it)"
            )
            raise PhysicalConsistencyError(f"the prior (nominal parameters){hint}", bad + neg)
        return J0, np.minimum(MARGIN * lam0[:, -1], 0.5 * lam0[:, 0])
    scale = np.abs(lam0).max(axis=1)
    fallback = float(scale[scale > 0].mean()) if np.any(scale > 0) else 1.0
    return J0, MARGIN * np.where(scale > 0, scale, fallback)


def _term_scales(P, A, nb: int, beta_ls, theta0, zz) -> np.ndarray:
    """Joint-term scales ``s_t = sqrt(zz / H_tt)``, ``H = P^T A P``: the value that alone
    would explain all the (weighted) torque, in parameter units, so that the prior
    weighs the same whatever the noise level (``|theta0_t|`` or 1 where undefined)."""
    H_tt = np.einsum("it,ij,jt->t", P[:, 10 * nb :], A, P[:, 10 * nb :])
    zz_eff = float(zz) if zz is not None else float(beta_ls @ A @ beta_ls)
    ref = np.abs(theta0[10 * nb :])
    with np.errstate(divide="ignore", invalid="ignore"):
        term_scale = np.sqrt(zz_eff / H_tt)
    return np.where(
        np.isfinite(term_scale) & (term_scale > 0), term_scale, np.where(ref > 0, ref, 1.0)
    )


def row_and_null_maps(pr: ConsistentProblem) -> tuple[np.ndarray, np.ndarray]:
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
