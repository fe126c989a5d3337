"""Drive gains ``tau_j = g_j i_j`` with the robot's and the payload's parameters, from currents.

Unloaded and loaded runs with motor currents ``i`` [A] in place of torques give the
homogeneous system ``D(i) g - Y_b beta - Y_p phi = 0``, fixed up to one common scale;
a known payload mass (and optionally its centre of mass and inertia) fixes it, its
columns moved to the right: ``[D(i), -Y_b, -Y_pu] [g; beta; psi_u] = Y_pk phi_k``.
Solved by OLS, WLS, TLS or, by default, maximum likelihood in current units
(:mod:`manip_id.payload.gain_estimators`). Gautier & Briot 2014; the math is in
:mod:`manip_id.payload`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .._checks import as_float_array
from ..errors import DataError, InputError
from ..estimators import InformationAccumulator, solve_accumulator
from ..identifiability import BaseParameters, RankAnalysis, analyze, analyze_information
from ..metrics import relative_error
from ..resources import MAX_PAYLOAD_MASS
from ..robot.model import Robot
from .gain_estimators import check_payload_present, ml_gains, tls
from .gain_uncertainty import GainUncertainty, gain_uncertainty
from .geometry import (
    PAYLOAD_NAMES,
    PayloadFrame,
    payload_frame,
    payload_identifiability,
    pseudo_inertia_eigenvalues,
    standard_from_quantities,
)
from .options import GAIN_METHODS, DriveGainOptions, resolve_options
from .result import (
    DriveGainResult,
    PayloadEstimate,
    estimate_from_base,
    known_estimate,
    record_warning,
)
from .runs import Run, accumulate_runs, as_runs, check_deadband, check_distinct, dof_factor

#: A gain of OLS, WLS or TLS this many of its standard deviations from the ML gain of the
#: same data is named in a warning.
ML_DISAGREEMENT = 3.0


@dataclass(frozen=True, eq=False)
class GainDesign:
    """Rows ``[D(i), -Y_b, -Y_pu] [g; beta; psi_u] = Y_pk phi_k`` of one chunk (picklable).

    The "torque" columns of the run hold the motor currents ``i`` [A]; unloaded runs
    have no payload columns and a zero right-hand side.
    """

    loaded: bool
    ind: np.ndarray  # the robot's base columns, (r,)
    cols: slice  # the payload's 10 columns of the parent joint
    T_u: np.ndarray  # unknown payload base columns in those, (10, k_u)
    T_k: np.ndarray  # the known payload's torque direction, (10,)
    nv: int

    @property
    def n_cols(self) -> int:
        return int(self.nv + self.ind.size + self.T_u.shape[1])

    def __call__(self, Y: np.ndarray, cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, nv, r = Y.shape[0], self.nv, self.ind.size
        diag = np.arange(nv)
        X = np.zeros((n, nv, self.n_cols))
        X[:, diag, diag] = cur
        X[:, :, nv : nv + r] = -Y[:, :, self.ind]
        if not self.loaded:
            return X, np.zeros((n, nv))
        X[:, :, nv + r :] = -(Y[:, :, self.cols] @ self.T_u)
        return X, Y[:, :, self.cols] @ self.T_k


@dataclass(frozen=True)
class _GainProblem:
    """The checked inputs of :func:`identify_drive_gains` and the payload's structure.

    The unknowns are ``[g (nv), beta (r), psi_u (k)]``: the gains, the robot's base
    parameters and the base parameters of the payload's unknown columns.
    """

    pf: PayloadFrame
    base: BaseParameters
    all_ra: RankAnalysis  # structural analysis of all 10 payload columns
    pra: RankAnalysis | None  # ... of the unknown ones (None: every one is known)
    unloaded: list[Run]
    loaded: list[Run]
    deadband: float | None
    known_cols: np.ndarray  # known payload columns among the 10
    unknown_cols: np.ndarray
    phi_k: np.ndarray  # their known values
    nv: int

    @property
    def r(self) -> int:
        return self.base.n_base

    @property
    def pind(self) -> np.ndarray:
        """Unknown payload base columns among the 10."""
        if self.pra is None:
            return np.zeros(0, dtype=np.intp)
        return self.unknown_cols[self.pra.base.independent]

    @property
    def p(self) -> int:
        return self.nv + self.r + int(self.pind.size)


@dataclass(frozen=True)
class _GainSums:
    """The accumulated information of ``[D(i), -Y_b, -Y_pu] x = Y_pk phi_k``."""

    acc: InformationAccumulator
    acc_u: InformationAccumulator
    acc_l: InformationAccumulator
    left_out: np.ndarray  # rows left out by the deadband per joint, (nv,)
    names: list[str]
    runs: dict = field(default_factory=dict)  # per kind, the runs' summaries (RunSums.runs)


#: Largest distance of a known payload's centre of mass from its frame [m].
MAX_PAYLOAD_REACH = 10.0


def _check_physical_payload(mass: float, com, inertia) -> None:
    """Magnitudes in range, and the pseudo-inertia ``J(phi)`` of a known inertia positive
    semidefinite (an inertia about the CoM whose eigenvalues obey the triangle inequality)."""
    if mass > MAX_PAYLOAD_MASS:
        raise InputError(f"the payload mass must be <= {MAX_PAYLOAD_MASS:g} [kg], got {mass:g}")
    if com is not None and float(np.linalg.norm(com)) > MAX_PAYLOAD_REACH:
        raise InputError(
            f"the payload centre of mass must lie within {MAX_PAYLOAD_REACH:g} m of the frame, "
            f"got {com.tolist()}"
        )
    if inertia is None:
        return
    eig = pseudo_inertia_eigenvalues(standard_from_quantities(mass, com, inertia))
    if eig[0] < -1e-9 * max(1.0, float(np.abs(eig).max())):
        raise InputError(
            "the payload inertia (Ixx, Ixy, Iyy, Ixz, Iyz, Izz) about its centre of mass is not "
            f"physical: its pseudo-inertia has the eigenvalue {eig[0]:.3g} < 0, got "
            f"{inertia.tolist()} [kg m^2]"
        )


def check_known_payload(payload_mass, payload_com, payload_inertia):
    """The payload's known mass [kg], centre of mass [m] and inertia [kg m^2], checked."""
    try:
        mass = float(payload_mass)
    except (TypeError, ValueError) as exc:
        raise InputError(f"payload_mass must be a number [kg], got {payload_mass!r}") from exc
    if not (math.isfinite(mass) and mass > 0):
        raise InputError(f"the payload mass must be > 0 [kg], got {payload_mass}")
    if payload_inertia is not None and payload_com is None:
        raise InputError(
            "a known payload inertia (about its centre of mass) needs its centre of mass too"
        )
    com = None
    if payload_com is not None:
        com = as_float_array(payload_com, "payload_com", ndim=1)
        if com.shape != (3,) or not np.isfinite(com).all():
            raise InputError(f"payload_com must be 3 finite numbers [m], got {com.tolist()}")
    inertia = None
    if payload_inertia is not None:
        inertia = as_float_array(payload_inertia, "payload_inertia", ndim=1)
        if inertia.shape != (6,) or not np.isfinite(inertia).all():
            raise InputError(
                "payload_inertia must be 6 finite numbers (Ixx, Ixy, Iyy, Ixz, Iyz, Izz) "
                f"[kg m^2], got {inertia.tolist()}"
            )
    _check_physical_payload(mass, com, inertia)
    return mass, com, inertia


def _gain_inputs(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    payload: tuple,
    opts: DriveGainOptions,
    timings: dict[str, float],
) -> _GainProblem:
    """Read and check the inputs of :func:`identify_drive_gains`, with the structure;
    ``payload`` is ``(mass, com, inertia)`` as :func:`check_known_payload` returns it."""
    if opts.method not in GAIN_METHODS:
        raise InputError(f"method must be one of {list(GAIN_METHODS)}, got {opts.method!r}")
    mass, com, inertia = payload
    deadband = check_deadband(opts.velocity_deadband)
    pf = payload_frame(robot, frame)
    known_cols = (
        [0]
        + ([1, 2, 3] if com is not None else [])
        + (list(range(4, 10)) if inertia is not None else [])
    )
    unknown_cols = np.array([i for i in range(10) if i not in known_cols], dtype=np.intp)
    known_cols_a = np.array(known_cols, dtype=np.intp)
    phi_full = standard_from_quantities(mass, com, inertia)
    phi_k = phi_full[known_cols_a]

    t0 = time.perf_counter()
    base = analyze(robot).base if opts.base is None else opts.base
    all_ra = payload_identifiability(robot, pf)
    if unknown_cols.size:
        pra = payload_identifiability(robot, pf, columns=unknown_cols)
    else:
        pra = None
    timings["structural_analysis"] = time.perf_counter() - t0
    rank_u = 0 if pra is None else pra.rank
    if all_ra.rank <= rank_u:
        raise InputError(
            f"the known payload parameters ({', '.join(PAYLOAD_NAMES[i] for i in known_cols)}) "
            f"at {frame!r} do not enter the torques of {robot.name!r} apart from the unknown "
            "ones, so they cannot fix the scale of the gains (give more of the payload, e.g. "
            "its centre of mass, or attach it elsewhere)"
        )
    ub, lb = as_runs(unloaded, "unloaded"), as_runs(loaded, "loaded")
    if not lb or not ub:
        raise InputError("drive gains need both unloaded and loaded runs")
    check_distinct(ub, lb)
    return _GainProblem(
        pf, base, all_ra, pra, ub, lb, deadband, known_cols_a, unknown_cols, phi_k, robot.nv
    )


def _gain_accumulate(robot: Robot, prob: _GainProblem, chunk: int, scheduler=None) -> _GainSums:
    """Accumulate ``[D(i), -Y_b, -Y_pu] [g; beta; psi_u] = Y_pk phi_k`` over the runs,
    one :func:`run_sums` task per run (on Dask with ``scheduler``)."""
    ind, cols_b = np.asarray(prob.base.independent, dtype=np.intp), prob.pf.columns
    T_u = prob.pf.transform[:, prob.pind]
    T_k = prob.pf.transform[:, prob.known_cols] @ prob.phi_k
    su, sl = accumulate_runs(
        robot,
        [
            (prob.unloaded, GainDesign(False, ind, cols_b, T_u, T_k, prob.nv)),
            (prob.loaded, GainDesign(True, ind, cols_b, T_u, T_k, prob.nv)),
        ],
        chunk=chunk,
        deadband=prob.deadband,
        scheduler=scheduler,
    )
    gain_names = [f"{d}.gain" for d in robot.dof_names]
    pnames = [] if prob.pra is None else prob.pra.base.base_names
    names = [*gain_names, *prob.base.base_names, *pnames]
    info = {"unloaded": su.runs, "loaded": sl.runs}
    return _GainSums(su.acc + sl.acc, su.acc, sl.acc, su.left_out + sl.left_out, names, info)


def _gains_determined(
    robot: Robot, acc: InformationAccumulator, ra: RankAnalysis, p: int, messages: list[str]
) -> np.ndarray:
    """Which gains the data fix, shape (nv,) bool; warns of the others and of unexcited
    base/payload directions."""
    nv = robot.nv
    determined = np.ones(nv, dtype=bool)
    if ra.rank < p:
        d = np.sqrt(np.maximum(np.diag(acc.A), 0.0))  # column norms; a zero column (a
        d = np.where(d > 0, d, d.max() if d.max() > 0 else 1.0)  # current never seen) counts
        N = ra.null_space * d[:, None]
        N = N / np.maximum(np.linalg.norm(N, axis=0), 1e-300)
        involved = np.abs(N[:nv]).max(axis=1) > 1e-6 if N.size else np.zeros(nv, bool)
        determined = ~involved
        others = [
            e
            for e, col in zip(ra.unidentifiable, N.T, strict=True)
            if np.abs(col[:nv]).max() <= 1e-6
        ]
        if involved.any():
            bad = [robot.dof_names[j] for j in np.flatnonzero(involved)]
            record_warning(
                messages,
                f"the data do not determine the drive gain of {', '.join(bad)}: its current "
                "is not tied to the payload's known torque (e.g. a vertical axis the payload's "
                "gravity never loads, or a joint that never moves); excite that joint with "
                "the payload mounted",
            )
        if others:
            record_warning(
                messages,
                f"these runs leave {len(others)} base/payload direction(s) unexcited: "
                + "; ".join(others[:4]),
            )
    return determined


@dataclass(frozen=True)
class _GainFit:
    """The solved drive-gain system: estimate, covariance, what the data determine."""

    ra: RankAnalysis
    determined: np.ndarray  # per joint, whether the data fix its gain, (nv,)
    x: np.ndarray  # [g, beta, psi_u]
    uncertainty: GainUncertainty  # honest and white covariance of x
    sigma2: float
    solver: str

    @property
    def cov(self) -> np.ndarray:
        """The honest covariance of ``x``."""
        return self.uncertainty.covariance


def _gains_solve(
    sums: _GainSums,
    ra: RankAnalysis,
    method: str,
    nv: int,
    p: int,
    determined: np.ndarray,
    messages: list[str],
) -> _GainFit:
    """OLS/WLS with the known columns on the right, then TLS or ML from it, with the
    honest covariance (:mod:`manip_id.payload.gain_uncertainty`)."""
    acc, left_out = sums.acc, sums.left_out
    ls = solve_accumulator(
        acc,
        method="wls" if method == "wls" else "ols",
        names=sums.names,
        minimum_norm=ra.rank < p,
        rank_rtol=ra.tolerance,
    )
    f = dof_factor(acc, ls.rank, left_out)
    x, cov, sigma2 = ls.estimate, ls.covariance * f, ls.sigma2 * f
    solver = f"{'WLS' if method == 'wls' else 'OLS'} with the known payload columns on the "
    solver += "right-hand side; " + ls.solver
    if method == "tls":
        if ra.rank < p:
            record_warning(
                messages,
                "TLS needs a full-rank system: kept the minimum-norm OLS solution",
            )
        else:
            x = tls(acc)
            rss = acc.residual_sum_of_squares(x)
            sigma2_t = float(rss.sum() / max(acc.n_rows - int(left_out.sum()) - p, 1))
            cov = cov * (sigma2_t / sigma2) if sigma2 > 0 else cov
            sigma2 = sigma2_t
            solver = (
                "TLS: smallest right singular vector of the column-scaled [W, -y], scaled to "
                "the known payload; covariance sigma^2 (W^T W)^-1 at the TLS estimate"
            )
    n_rows = acc.n - left_out
    if method == "ml":  # damped steps leave the unexcited directions where OLS put them
        x, cov, sigma2, what = ml_gains(acc, nv, x, n_rows, determined)
        solver = f"{what}, started from OLS ({ls.solver})"
    unc = gain_uncertainty(acc, ls, f, method, x, cov, n_rows, determined)
    if method != "ml":  # the ML gains from the same sums: a check of the errors in variables
        x_ml = ml_gains(acc, nv, ls.estimate, n_rows, determined)[0]
        _warn_ml_disagreement(sums, method, x, unc.covariance, x_ml, determined, messages)
    return _GainFit(ra, determined, x, unc, float(sigma2), solver)


def _warn_ml_disagreement(
    sums: _GainSums,
    method: str,
    x: np.ndarray,
    cov: np.ndarray,
    x_ml: np.ndarray,
    determined: np.ndarray,
    messages: list[str],
) -> None:
    """Warn, naming each joint, where a gain of ``method`` is more than
    :data:`ML_DISAGREEMENT` of its own standard deviations from the ML gain."""
    nv = determined.size
    std = np.sqrt(np.maximum(np.diag(cov)[:nv], 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(x[:nv] - x_ml[:nv]) / std
    bad = [j for j in range(nv) if determined[j] and not z[j] <= ML_DISAGREEMENT]
    if not bad:
        return
    shown = "; ".join(
        f"{sums.names[j].removesuffix('.gain')} {x[j]:.4g} +- {std[j]:.2g} against {x_ml[j]:.4g}"
        f" ({z[j]:.3g} std)"
        for j in bad
    )
    record_warning(
        messages,
        f"the {method.upper()} drive gain differs from the maximum-likelihood gain of the "
        f"same data by more than {ML_DISAGREEMENT:g} of its standard deviations: {shown}; "
        f"{method.upper()} holds the noisy currents in the regressor (errors in variables: "
        "a gain shrinks where its current is small against its noise), ML does not "
        "(method='ml', --method ml)",
    )


def _gains_uncertainty(
    robot: Robot, x: np.ndarray, cov: np.ndarray, determined: np.ndarray, messages: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(gains, gains_std, std)``: the gains and their standard deviations (NaN where the
    data do not fix them), and every parameter's; warns of gains that came out <= 0."""
    nv = robot.nv
    gains = x[:nv].copy()
    std_all = np.sqrt(np.maximum(np.diag(cov), 0.0))
    gains_std = std_all[:nv].copy()
    gains[~determined] = np.nan
    gains_std[~determined] = np.nan
    neg = [robot.dof_names[j] for j in range(nv) if determined[j] and gains[j] <= 0]
    if neg:
        record_warning(
            messages,
            f"the drive gain of {', '.join(neg)} came out <= 0: check the current's sign "
            "convention of that joint",
        )
    return gains, gains_std, std_all


def _gain_payload(prob: _GainProblem, x: np.ndarray, cov: np.ndarray) -> PayloadEstimate:
    """The payload: its known part and, when some is unknown, the estimate of the rest."""
    nv, r = prob.nv, prob.r
    phi_known = np.zeros(10)
    phi_known[prob.known_cols] = prob.phi_k
    if prob.pra is None:
        return known_estimate(prob.pf, phi_known, prob.all_ra)
    return estimate_from_base(
        prob.pf,
        prob.pra,
        prob.unknown_cols,
        x[nv + r :],
        cov[nv + r :, nv + r :],
        phi_known=phi_known,
        known_cols=prob.known_cols,
    )


def _gain_errors(sums: _GainSums, x: np.ndarray, nv: int, p: int) -> tuple[dict, dict]:
    """Relative errors in torque units: residuals over ``||g i||``, per kind of run."""
    rel, rel_j = {}, {}
    for key, a in (("unloaded", sums.acc_u), ("loaded", sums.acc_l)):
        rss = a.residual_sum_of_squares(x)
        xg = np.zeros(p)
        xg[:nv] = x[:nv]
        tt = np.maximum(np.einsum("a,jab,b->j", xg, a.A_joint, xg), 0.0)  # ||g_j i_j||^2
        rel[key], rel_j[key] = relative_error(rss, tt)
    return rel, rel_j


def identify_drive_gains(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    payload_mass: float,
    *,
    payload_com=None,
    payload_inertia=None,
    options: DriveGainOptions | None = None,
    **settings,
) -> DriveGainResult:
    """Drive gains ``g`` (``tau_j = g_j i_j``), base and payload parameters from currents.

    Parameters
    ----------
    robot
        Robot
        The robot.
    unloaded, loaded
        runs
        As in :func:`~manip_id.payload.identify_payload`, with motor currents [A] in the
        torque columns.
    frame
        str
        The frame the payload is fixed to.
    payload_mass
        float
        The payload's known mass [kg], > 0 (it fixes the scale).
    payload_com
        array_like or None
        Its centre of mass in ``frame`` [m], shape (3,), when known.
    payload_inertia
        array_like or None
        Its inertia about the CoM in ``frame`` axes [kg m^2], (Ixx, Ixy, Iyy, Ixz, Iyz,
        Izz), when known (needs ``payload_com``).
    options
        DriveGainOptions or None
        Method ("ml" by default), deadband, chunk, base, scheduler.
    **settings
        Fields of :class:`DriveGainOptions` given as keywords (``method="tls"``).

    Returns
    -------
    DriveGainResult
        A joint whose gain the data do not fix gets a :class:`PayloadWarning` naming it
        and ``determined=False``.
    """
    opts = resolve_options(DriveGainOptions, options, settings)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    payload = check_known_payload(payload_mass, payload_com, payload_inertia)
    prob = _gain_inputs(robot, unloaded, loaded, frame, payload, opts, timings)
    t0 = time.perf_counter()
    sums = _gain_accumulate(robot, prob, opts.chunk, opts.scheduler)
    timings["accumulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    messages: list[str] = []
    fit = _gain_fit(robot, prob, sums, opts.method, messages)
    timings["solve"] = time.perf_counter() - t0
    result = _gain_result(robot, prob, sums, fit, opts.method, messages, timings)
    timings["total"] = time.perf_counter() - t_start
    return result


def _gain_fit(
    robot: Robot, prob: _GainProblem, sums: _GainSums, method: str, messages: list[str]
) -> _GainFit:
    """Check the accumulated system, find what it determines and solve it by ``method``."""
    nv, p = prob.nv, prob.p
    acc = sums.acc
    if acc.n_rows <= p:
        raise InputError(f"{acc.n_rows} equations for {p} parameters: give more samples")
    if acc.zz == 0:
        raise DataError(
            "the payload's known part produces no torque on these loaded runs: nothing fixes "
            "the scale of the gains"
        )
    ra = analyze_information(acc.A, sums.names, n_rows=acc.n_rows)
    determined = _gains_determined(robot, acc, ra, p, messages)
    check_payload_present(acc, nv, determined, robot.dof_names)
    return _gains_solve(sums, ra, method, nv, p, determined, messages)


def _gain_result(
    robot: Robot,
    prob: _GainProblem,
    sums: _GainSums,
    fit: _GainFit,
    method: str,
    messages: list[str],
    timings: dict[str, float],
) -> DriveGainResult:
    """The :class:`DriveGainResult` of a solved system: gains, payload, errors, warnings."""
    nv, r, p, x = prob.nv, prob.r, prob.p, fit.x
    gains, gains_std, std_all = _gains_uncertainty(robot, x, fit.cov, fit.determined, messages)
    gains_std_white = np.where(fit.determined, fit.uncertainty.std_white[:nv], np.nan)
    est = _gain_payload(prob, x, fit.cov)
    rel, rel_j = _gain_errors(sums, x, nv, p)
    return DriveGainResult(
        robot_name=robot.name,
        method=method,
        dof_names=list(robot.dof_names),
        gains=gains,
        gains_std=gains_std,
        gains_std_white=gains_std_white,
        uncertainty=fit.uncertainty.summary,
        determined=fit.determined,
        payload=est,
        base_names=list(prob.base.base_names),
        base_expressions=list(prob.base.expressions),
        base_estimate=x[nv : nv + r],
        base_std=std_all[nv : nv + r],
        sigma2=fit.sigma2,
        condition_number=float(fit.ra.condition_number),
        n_samples={"unloaded": int(sums.acc_u.n), "loaded": int(sums.acc_l.n)},
        relative_error=rel,
        relative_error_per_joint=rel_j,
        rows_left_out=sums.left_out,
        solver=fit.solver,
        warnings=messages,
        timings=timings,
        runs=sums.runs,
    )
