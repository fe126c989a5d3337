"""Payload identification: unloaded and loaded runs solved jointly for ``[beta, psi]``.

Unloaded runs ``tau = Y_b beta`` and loaded runs ``tau = Y_b beta + Y_p phi`` give one
least squares in the robot's base parameters ``beta`` and the payload's base
parameters ``psi = phi[ind] + K phi[dep]``; with a known base (an earlier
identification) the loaded runs alone give ``tau - Y_b beta = Y_p psi`` and the
covariance of ``beta`` is propagated into that of ``psi``. ``consistent=True``
projects ``psi`` onto the physically consistent payloads in its covariance metric
(:func:`consistent_payload`). The math is in :mod:`manip_id.payload`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .._checks import as_float_array
from ..errors import DataError, InputError, RankDeficiencyError
from ..estimators import InformationAccumulator, LeastSquaresSolution, solve_accumulator
from ..estimators.consistent import ConsistentProblem, base_map, solve_sdp
from ..estimators.uncertainty import (
    UncertaintyOptions,
    correlations_scaled,
    inflation,
    sandwich_covariance,
    solution_uncertainty,
)
from ..identifiability import BaseParameters, RankAnalysis, analyze, analyze_information
from ..metrics import relative_error
from ..robot.model import Robot
from .geometry import (
    PAYLOAD_NAMES,
    QUANTITY_NAMES,
    PayloadFrame,
    payload_frame,
    payload_identifiability,
    pseudo_inertia_eigenvalues,
)
from .known import KnownBase, check_known_base
from .options import PAYLOAD_METHODS, PayloadOptions, resolve_options
from .result import PayloadEstimate, PayloadResult, estimate_from_base, record_warning
from .runs import (
    Run,
    accumulate_runs,
    as_runs,
    check_deadband,
    check_distinct,
    dof_factor,
    relative_errors,
    sub_accumulator,
)

#: Significance level of the test that the loaded runs show a payload at all.
PAYLOAD_SIGNIFICANCE = 1e-3
#: Margin of the pseudo-inertia LMI of the consistent payload [SI units].
CONSISTENCY_MARGIN = 1e-9


@dataclass(frozen=True, eq=False)
class PayloadDesign:
    """Rows of one chunk of the payload problem (picklable: a Dask task's argument).

    ``kind``: "unloaded" ``[Y_b, 0]``, "loaded" ``[Y_b, Y_p T]`` (unknowns ``[beta, psi]``)
    or "known" ``[Y_p T, Y_b]`` (loaded runs with a known base, unknowns ``[psi, beta]``);
    the right-hand side is the torque.
    """

    kind: str
    ind: np.ndarray  # the robot's base columns, (r,)
    cols: slice  # the payload's 10 columns of the parent joint
    T: np.ndarray  # payload base columns in those, (10, k)

    @property
    def n_cols(self) -> int:
        return int(self.ind.size + self.T.shape[1])

    def __call__(self, Y: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.kind == "unloaded":
            X = np.zeros((Y.shape[0], Y.shape[1], self.n_cols))
            X[:, :, : self.ind.size] = Y[:, :, self.ind]
            return X, tau
        Yp = Y[:, :, self.cols] @ self.T
        if self.kind == "loaded":
            return np.concatenate([Y[:, :, self.ind], Yp], axis=2), tau
        return np.concatenate([Yp, Y[:, :, self.ind]], axis=2), tau


def consistent_payload(
    psi_hat,
    cov_psi,
    payload_base: BaseParameters,
    *,
    margin: float | None = None,
) -> tuple[np.ndarray, str]:
    """The physically consistent payload closest to an estimate, in its covariance metric.

    Minimise ``(S phi - psi_hat)^T Cov^-1 (S phi - psi_hat)`` over the payload's 10
    standard parameters ``phi`` subject to ``J(phi) >= margin 1`` (one 4 x 4 LMI), ``S``
    the payload's base map (``psi = S phi``). This is the one-body case of
    :mod:`manip_id.estimators.consistent` (its SDP, cvxpy and Clarabel) without a prior:
    the unidentifiable directions of ``phi`` only have to make ``J`` feasible. The
    default margin is ``1e-8 max|eig J(phi_hat)|``. Returns ``(phi, status)``.
    """
    psi_hat = as_float_array(psi_hat, "psi_hat", ndim=1)
    k = psi_hat.size
    cov = as_float_array(cov_psi, "cov_psi", ndim=2)
    if cov.shape != (k, k) or payload_base.n_base != k:
        raise InputError(
            f"cov_psi.shape={cov.shape} and the payload base has {payload_base.n_base} "
            f"parameters, but psi_hat has {k}"
        )
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = w > max(float(w.max()), 0.0) * 1e-14
    if not keep.any():  # a noise-free fit: measure it in units of the estimate
        w, V = np.ones(k), np.eye(k)
        keep = np.ones(k, dtype=bool)
        w = w * (np.maximum(np.abs(psi_hat), 1e-12) * 1e-8) ** 2
        V = np.eye(k)
    W = (V[:, keep] / np.sqrt(w[keep])).T  # W^T W = Cov^-1 on its range
    P = base_map(payload_base, 10)
    G = np.zeros((10, k))
    G[payload_base.independent, np.arange(k)] = 1.0
    if margin is None:
        lam = np.abs(pseudo_inertia_eigenvalues(G @ psi_hat))
        margin = 1e-8 * float(lam.max()) if lam.max() > 0 else CONSISTENCY_MARGIN
    problem = ConsistentProblem(
        P=P,
        beta_ls=psi_hat,
        W=W,
        n_bodies=1,
        nonnegative=np.zeros(0, dtype=np.intp),
        theta0=G @ psi_hat,
        J0=None,
        term_scale=np.zeros(0),
        margin=np.array([float(margin)]),
        weight=0.0,
        independent=np.asarray(payload_base.independent, dtype=np.intp),
        dependent=np.asarray(payload_base.dependent, dtype=np.intp),
        names=list(PAYLOAD_NAMES),
    )
    phi, status, iters = solve_sdp(problem)
    return phi, f"Clarabel SDP ({status}, {iters} iterations, margin {float(margin):.3g})"


@dataclass(frozen=True)
class _PayloadProblem:
    """The checked inputs of :func:`identify_payload` and the payload's structure."""

    pf: PayloadFrame
    base: BaseParameters
    pra: RankAnalysis  # structural analysis of the payload's 10 columns
    unloaded: list[Run]
    loaded: list[Run]
    known: KnownBase | None
    deadband: float | None
    T: np.ndarray  # payload base columns in the frame of the parent joint, (10, k)

    @property
    def r(self) -> int:
        return self.base.n_base

    @property
    def k(self) -> int:
        return int(self.pra.base.independent.size)


@dataclass(frozen=True)
class _PayloadSums:
    """The accumulated information of the payload problem."""

    acc: InformationAccumulator  # the system solved: [beta, psi], or psi with known beta
    acc_u: InformationAccumulator | None  # unloaded runs (None with a known base)
    acc_l: InformationAccumulator  # loaded runs (with a known base: the system solved)
    full: InformationAccumulator | None  # known base: loaded sums over [psi, beta]
    left_out: np.ndarray  # rows left out by the deadband per joint, (nv,)
    names: list[str]
    runs: dict = field(default_factory=dict)  # per kind, the runs' summaries (RunSums.runs)


@dataclass(frozen=True)
class _PayloadFit:
    """The least-squares fit of the payload problem (then, optionally, made consistent)."""

    ls: LeastSquaresSolution
    ra: RankAnalysis
    f: float  # covariance correction for the rows left out
    x: np.ndarray
    beta: np.ndarray
    psi: np.ndarray
    cov_psi: np.ndarray
    cov_beta: np.ndarray
    solver: str
    phi_override: np.ndarray | None = None
    uncertainty: dict | None = None  # the covariance's method, inflation, blocks


def _payload_inputs(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    known_base,
    opts: PayloadOptions,
    timings: dict[str, float],
) -> _PayloadProblem:
    """Read and check the inputs of :func:`identify_payload`, with the structural analysis."""
    if opts.method not in PAYLOAD_METHODS:
        raise InputError(f"method must be one of {list(PAYLOAD_METHODS)}, got {opts.method!r}")
    deadband = check_deadband(opts.velocity_deadband)
    pf = payload_frame(robot, frame)
    t0 = time.perf_counter()
    base = analyze(robot).base if opts.base is None else opts.base
    pra = payload_identifiability(robot, pf)
    timings["structural_analysis"] = time.perf_counter() - t0
    if pra.rank == 0:
        raise InputError(
            f"a payload at {frame!r} (on {pf.joint_name}) enters no joint torque of {robot.name!r}"
        )
    ub, lb = as_runs(unloaded, "unloaded"), as_runs(loaded, "loaded")
    if not lb:
        raise InputError("no loaded runs: give the runs recorded with the payload mounted")
    if known_base is None and not ub:
        raise InputError("no unloaded runs: give them, or the base parameters (known_base)")
    check_distinct(ub, lb)
    known = None if known_base is None else check_known_base(robot, base, known_base)
    T = pf.transform[:, pra.base.independent]
    return _PayloadProblem(pf, base, pra, ub, lb, known, deadband, T)


def _payload_accumulate(
    robot: Robot, prob: _PayloadProblem, chunk: int, scheduler=None
) -> _PayloadSums:
    """Accumulate the joint payload problem over the runs (see the module docstring),
    one :func:`run_sums` task per run (on Dask with ``scheduler``)."""
    ind, T, cols_b = np.asarray(prob.base.independent, dtype=np.intp), prob.T, prob.pf.columns
    r = prob.r
    db = prob.deadband
    if prob.known is None:
        su, sl = accumulate_runs(
            robot,
            [
                (prob.unloaded, PayloadDesign("unloaded", ind, cols_b, T)),
                (prob.loaded, PayloadDesign("loaded", ind, cols_b, T)),
            ],
            chunk=chunk,
            deadband=db,
            scheduler=scheduler,
        )
        names = [*prob.base.base_names, *prob.pra.base.base_names]
        info = {"unloaded": su.runs, "loaded": sl.runs}
        return _PayloadSums(
            su.acc + sl.acc, su.acc, sl.acc, None, su.left_out + sl.left_out, names, info
        )

    (sk,) = accumulate_runs(
        robot,
        [(prob.loaded, PayloadDesign("known", ind, cols_b, T))],
        chunk=chunk,
        deadband=db,
        scheduler=scheduler,
    )
    full, k = sk.acc, prob.k
    known = prob.known.estimate
    acc = sub_accumulator(full, np.arange(k), offset=np.arange(k, k + r), known=known)
    names = list(prob.pra.base.base_names)
    info = {"unloaded": [], "loaded": sk.runs}
    return _PayloadSums(acc, None, acc, full, sk.left_out, names, info)


def _payload_solve(prob: _PayloadProblem, sums: _PayloadSums, method: str, nv: int):
    """Rank check and least squares; the covariance of ``psi`` (with a known base's)."""
    acc, r, k = sums.acc, prob.r, prob.k
    if acc.n_rows <= acc.p:
        raise InputError(f"{acc.n_rows} equations for {acc.p} parameters: give more samples")
    ra = analyze_information(acc.A, sums.names, n_rows=acc.n_rows)
    if ra.rank < acc.p:
        raise RankDeficiencyError(
            ra.rank,
            acc.p,
            ra.unidentifiable,
            subject="these runs",
            what="directions of the joint payload problem",
            hint="unloaded runs must excite the robot's base parameters, loaded runs the payload's",
        )
    ls = solve_accumulator(acc, method=method, names=sums.names, rank_rtol=ra.tolerance)
    f = dof_factor(acc, ls.rank, sums.left_out)
    x = ls.estimate
    if prob.known is None:
        cov, uncertainty = _honest_covariance(acc, ls, f)
    else:
        assert sums.full is not None
        cov, uncertainty = _known_base_covariance(sums.full, ls, f, prob.known.estimate)
    if prob.known is None:
        beta, psi = x[:r], x[r:]
        cov_psi = cov[r:, r:]
        cov_beta = cov[:r, :r]
    else:
        assert sums.full is not None
        psi, beta = x, prob.known.estimate
        cov_psi = cov
        # propagate the known base's covariance: psi = A_pp^-1 (b_p - A_pb beta)
        Aw = sums.full.A_joint
        wts = ls.weights if ls.weights is not None else np.ones(nv)
        A_all = np.einsum("j,jab->ab", wts, Aw)
        G = np.linalg.solve(A_all[:k, :k], A_all[:k, k:])
        cov_psi = cov_psi + G @ prob.known.covariance @ G.T
        cov_beta = prob.known.covariance
    return _PayloadFit(
        ls, ra, f, x, beta, psi, cov_psi, cov_beta, ls.solver, uncertainty=uncertainty
    )


def _honest_covariance(acc: InformationAccumulator, ls: LeastSquaresSolution, f: float):
    """``(covariance, summary)`` of the fit: the white-noise one (corrected by ``f`` for
    the rows left out) scaled to the autocorrelation-consistent standard deviations of the
    runs' per-block sums when they allow it (``auto``), never below it; ``summary`` as the
    identification's ``uncertainty``."""
    white = ls.covariance * f
    if acc.blocks is None:  # a known base: its sums are derived (no blocks)
        return white, {"method": "white", "reason": "the sums of a known base carry no blocks"}
    unc = solution_uncertainty(acc, ls, white_covariance=white)
    if unc.method != "hac":
        return white, unc.to_dict()
    # the white correlations scaled to the honest std, never below the white ones: the
    # full block-score matrix of a few runs is too noisy for the payload's Wald test (as
    # IdentificationResult.test_covariance for drift)
    return correlations_scaled(white, unc.std), unc.to_dict()


def _known_base_covariance(
    full: InformationAccumulator, ls: LeastSquaresSolution, f: float, known: np.ndarray
):
    """``(covariance, summary)`` of ``psi`` with a known base, from the blocks of the loaded
    runs' full sums (columns ``[psi (k), beta (r)]``).

    The derived problem ``z - X_b beta_known = X_p psi`` has the block scores
    ``X_pk^T W (z_k - X_bk beta_known - X_pk psi)``: the first ``k`` entries of the full
    blocks' scores at ``[psi, beta_known]``, and the bread ``A_pp^-1`` (weighted for WLS),
    so :func:`~manip_id.estimators.uncertainty.sandwich_covariance` applies with no
    derived blocks. Then as :func:`_honest_covariance`: the white correlations with the
    honest std, never below white; the known base's own covariance is added by the caller.
    """
    white = ls.covariance * f
    blocks = full.blocks
    if blocks is None or blocks.n_blocks < UncertaintyOptions().min_blocks:
        n = 0 if blocks is None else blocks.n_blocks
        reason = f"the loaded runs' sums carry {n} blocks (fewer than the minimum)"
        return white, {"method": "white", "reason": reason}
    k = ls.estimate.size
    theta = np.r_[ls.estimate, known]
    Ak = blocks.information(ls.weights)[:, :k, :k]
    Ainv = np.linalg.pinv(Ak.sum(axis=0), hermitian=True)
    hac = sandwich_covariance(blocks.scores(theta, ls.weights)[:, :k], Ainv, Ak)
    std = np.sqrt(np.clip(np.diag(hac.covariance), 0.0, None))
    sw = np.sqrt(np.clip(np.diag(white), 0.0, None))
    summary = {
        "method": "hac",
        "requested": "auto",
        "bandwidth": float(f"{hac.bandwidth:.6g}"),
        "inflation": inflation(std, sw),
        "n_blocks": int(hac.n_blocks),
        "block_samples": float(f"{blocks.counts.mean():.6g}"),
        "reason": "",
    }
    return correlations_scaled(white, std), summary


def _payload_shown(prob: _PayloadProblem, sums: _PayloadSums, fit: _PayloadFit) -> dict:
    """The test that the loaded data show a payload at all (DataError when they do not)."""
    if prob.known is None:
        test = _payload_test(fit.psi, fit.cov_psi, sums.acc_l.A[prob.r :, prob.r :], sums.acc_l.zz)
    else:
        assert sums.full is not None
        test = _payload_test(fit.psi, fit.cov_psi, sums.acc.A, sums.full.zz)
    if not test["significant"]:
        raise DataError(
            f"the loaded runs carry no payload information: the payload's torques are not "
            f"distinguishable from zero (Wald statistic {test['statistic']:.3g} for "
            f"{test['dof']} parameters, p-value {test['p_value']:.3g}, payload share of the "
            f"loaded torques {test['share']:.2e}); were the loaded runs recorded with the "
            "payload mounted, and are they other runs than the unloaded ones?"
        )
    return test


def _payload_consistent_fit(
    prob: _PayloadProblem, sums: _PayloadSums, fit: _PayloadFit
) -> _PayloadFit:
    """The fit with the payload's pseudo-inertia positive definite (``beta`` follows)."""
    pb, r = prob.pra.base, prob.r
    phi_c, status = consistent_payload(fit.psi, fit.cov_psi, pb)
    psi_c = phi_c[pb.independent] + (pb.K @ phi_c[pb.dependent] if pb.dependent.size else 0.0)
    beta = fit.beta
    if prob.known is None:  # beta follows by its conditional least squares
        acc, ls = sums.acc, fit.ls
        A = acc.A if ls.weights is None else acc.weighted(ls.weights)[0]
        beta = beta - np.linalg.solve(A[:r, :r], A[:r, r:] @ (psi_c - fit.psi))
        x = np.r_[beta, psi_c]
    else:
        x = psi_c
    solver = f"{fit.solver}; payload pseudo-inertia positive definite by {status}"
    return replace(fit, x=x, beta=beta, psi=psi_c, solver=solver, phi_override=phi_c)


def _payload_warnings(robot: Robot, pf: PayloadFrame, est: PayloadEstimate, messages) -> None:
    """Warn of a non-positive mass, a non-physical payload, and what does not show."""
    if est.identifiable[0] and est.mass <= 0:
        record_warning(
            messages,
            f"the identified payload mass is {est.mass:.4g} kg (not positive): are the "
            "unloaded and loaded runs swapped? (or use consistent=True / --consistent)",
        )
    elif est.physically_consistent is False and not est.point_mass:
        record_warning(
            messages,
            f"the identified payload is not physically consistent (smallest pseudo-inertia "
            f"eigenvalue {est.min_eigenvalue:.3g}); use consistent=True (--consistent)",
        )
    missing = [n for n, ok in zip(QUANTITY_NAMES, est.identifiable, strict=True) if not ok]
    if missing:
        record_warning(
            messages,
            f"a payload at {pf.name} (on {pf.joint_name}) does not show "
            f"{', '.join(missing)} in the joint torques of {robot.name}: not identifiable",
        )


def _payload_errors(prob: _PayloadProblem, sums: _PayloadSums, x: np.ndarray):
    """Relative torque errors ``(rel, rel_per_joint)`` per kind of run."""
    if prob.known is None:
        return relative_errors({"unloaded": sums.acc_u, "loaded": sums.acc_l}, x)
    # residual of tau - Y_b beta - Y_p psi, relative to the loaded torques
    assert sums.full is not None
    total, per_joint = relative_error(sums.acc.residual_sum_of_squares(x), sums.full.zz_joint)
    return {"loaded": total}, {"loaded": per_joint}


def identify_payload(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    *,
    known_base=None,
    options: PayloadOptions | None = None,
    **settings,
) -> PayloadResult:
    """Identify a payload rigidly attached to ``frame`` from unloaded and loaded runs.

    Parameters
    ----------
    robot
        Robot
        The robot (its joint terms decide the base columns).
    unloaded
        runs
        Runs without the payload: a Dataset (with ddq), a tuple ``(q, dq, ddq, tau)`` of
        arrays ((N, nq), (N, nv) x 3 [rad, rad/s, rad/s^2, N m]), a function of no
        argument returning an iterable of such tuples (a long log streamed block by
        block), or a list of those; may be empty/None with ``known_base``.
    loaded
        runs
        Runs with the payload mounted, the same forms.
    frame
        str
        The frame or link the payload is fixed to (e.g. ``"tool0"``).
    known_base
        KnownBase, IdentificationResult or None
        Base parameters from an earlier identification (:func:`load_known_base`), used
        instead of the unloaded runs.
    options
        PayloadOptions or None
        Method, consistency, deadband, chunk, base, scheduler.
    **settings
        Fields of :class:`PayloadOptions` given as keywords (``method="ols"``).

    Returns
    -------
    PayloadResult
        The math is in :mod:`manip_id.payload`. Raises :class:`InputError` for an unknown
        frame (listing the valid ones) or a payload that does not enter the torques,
        :class:`DataError` for loaded runs without payload information or runs of
        another robot, :class:`RankDeficiencyError` for data that do not excite the
        parameters.
    """
    opts = resolve_options(PayloadOptions, options, settings)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    prob = _payload_inputs(robot, unloaded, loaded, frame, known_base, opts, timings)
    t0 = time.perf_counter()
    sums = _payload_accumulate(robot, prob, opts.chunk, opts.scheduler)
    timings["accumulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit = _payload_solve(prob, sums, opts.method, robot.nv)
    timings["solve"] = time.perf_counter() - t0
    test = _payload_shown(prob, sums, fit)
    if opts.consistent:
        t0 = time.perf_counter()
        fit = _payload_consistent_fit(prob, sums, fit)
        timings["consistent"] = time.perf_counter() - t0
    result = _payload_result(robot, prob, sums, fit, opts, test, timings)
    timings["total"] = time.perf_counter() - t_start
    return result


def _payload_result(
    robot: Robot,
    prob: _PayloadProblem,
    sums: _PayloadSums,
    fit: _PayloadFit,
    opts: PayloadOptions,
    test: dict,
    timings: dict[str, float],
) -> PayloadResult:
    """The :class:`PayloadResult` of a finished fit: the payload's quantities with their
    uncertainty, the base parameters' standard deviations, the errors and warnings."""
    est = estimate_from_base(
        prob.pf, prob.pra, np.arange(10), fit.psi, fit.cov_psi, phi_override=fit.phi_override
    )
    messages: list[str] = []
    _payload_warnings(robot, prob.pf, est, messages)
    rel, rel_j = _payload_errors(prob, sums, fit.x)
    return PayloadResult(
        robot_name=robot.name,
        method=opts.method,
        payload=est,
        base_names=list(prob.base.base_names),
        base_expressions=list(prob.base.expressions),
        base_estimate=np.asarray(fit.beta, dtype=float),
        base_std=np.sqrt(np.maximum(np.diag(fit.cov_beta), 0.0)),
        known_base=prob.known is not None,
        consistent=bool(opts.consistent),
        sigma2=float(fit.ls.sigma2 * fit.f),
        condition_number=float(fit.ra.condition_number),
        n_samples={
            "unloaded": int(0 if sums.acc_u is None else sums.acc_u.n),
            "loaded": int(sums.acc_l.n),
        },
        relative_error=rel,
        relative_error_per_joint=rel_j,
        rows_left_out=sums.left_out,
        payload_test={k2: v for k2, v in test.items() if k2 != "significant"},
        solver=fit.solver,
        dof_names=list(robot.dof_names),
        warnings=messages,
        timings=timings,
        runs=sums.runs,
        uncertainty=fit.uncertainty,
    )


def _payload_test(psi, cov_psi, A_pp: np.ndarray, zz: float) -> dict:
    """Wald test of ``psi = 0`` and the payload's share ``||Y_p psi|| / ||tau||`` of the
    loaded torques (``A_pp = Y_p^T Y_p`` on the loaded runs, ``zz = ||tau||^2``)."""
    from scipy.stats import chi2  # scipy.stats: heavy, only for this test

    k = psi.size
    share = float(np.sqrt(max(psi @ A_pp @ psi, 0.0) / zz)) if zz > 0 else 0.0
    w, V = np.linalg.eigh(0.5 * (cov_psi + cov_psi.T))
    big = w > max(w.max(), 0.0) * 1e-14
    proj = V[:, big].T @ psi
    with np.errstate(divide="ignore", invalid="ignore"):
        stat = float(np.sum(proj**2 / w[big])) if big.any() else math.inf
    if not big.any() and np.allclose(psi, 0):
        stat = 0.0
    p_value = float(chi2.sf(stat, k)) if math.isfinite(stat) else 0.0
    significant = p_value < PAYLOAD_SIGNIFICANCE and share > 1e-9
    return {
        "statistic": stat,
        "dof": k,
        "p_value": p_value,
        "share": share,
        "significant": significant,
    }
