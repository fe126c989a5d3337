"""Problem -> result: rank check, least squares (or the online law's estimate), errors.

From the accumulated sums of a :class:`~manip_id.identification.Problem`::

    rank check       what these data excite (RankDeficiencyError otherwise)
    solve            theta_b = (sum_j A_j)^-1 sum_j b_j           (OLS; WLS re-weighted)
    covariance       sigma^2 (Y_b^T Y_b)^-1,  sigma^2 = RSS / (n_rows - r)
    train error      RSS_j = zz_j - 2 b_j.theta + theta.A_j.theta (floor about 1e-8)
    validation       the same from each validation file's sums, or one more streamed pass

The nominal (URDF) model's errors come from the same sums at
``theta_b_nominal = base.to_base(robot.nominal_parameters)``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, RankDeficiencyError
from ..estimators import InformationAccumulator, LeastSquaresSolution, solve_accumulator
from ..estimators.consistent import StandardEstimate, consistent_estimate, minimum_norm_standard
from ..estimators.uncertainty import Uncertainty, solution_uncertainty
from ..identifiability import RankAnalysis, analyze_information
from ..metrics import finite_or_none, relative_error
from ..robot.model import Robot
from ..robot.sidecar import model_structure
from .options import LEAST_SQUARES, ConsistentOptions, UncertaintyOptions, check_method
from .problem import FileSums, Problem, block_temperature, check_samples
from .result import IdentificationResult, RelativeError


@dataclass(frozen=True)
class FitUncertainty:
    """The covariance of an estimate and the residual variances behind it.

    Attributes
    ----------
    honest : Uncertainty
        The covariance of the requested method and the white-noise one beside it
        (:class:`~manip_id.estimators.uncertainty.Uncertainty`: ``"hac"`` holds for
        correlated residuals; ``"auto"`` picks it when the sums carry enough blocks).
    sigma2 : float
        Residual variance [(N m)^2] (weighted, about 1, for WLS).
    noise_variance : numpy.ndarray
        Per-joint residual variance, shape (nv,) [(N m)^2].
    """

    honest: Uncertainty
    sigma2: float
    noise_variance: np.ndarray

    @property
    def covariance(self) -> np.ndarray:
        """The honest covariance, shape (r, r) [units of the base parameters squared]."""
        return self.honest.covariance

    @property
    def std(self) -> np.ndarray:
        """Honest standard deviations, shape (r,)."""
        return self.honest.std


def fit_uncertainty(
    acc: InformationAccumulator,
    ls: LeastSquaresSolution,
    estimate: np.ndarray | None = None,
    options: UncertaintyOptions | None = None,
) -> FitUncertainty:
    """The covariance of the least-squares fit ``ls`` on the sums ``acc`` (``options``:
    its method, default ``"auto"``; :mod:`manip_id.estimators.uncertainty`).

    ``estimate``: another estimate on the same data (an online law's final one): the
    white-noise covariance ``sigma^2 (Y_b^T Y_b)^-1`` is then taken at its residual,
    ``sigma^2 = RSS(estimate) / (n_rows - rank)``, and the block scores at it.
    """
    if estimate is None:
        honest = solution_uncertainty(acc, ls, options)
        return FitUncertainty(honest, ls.sigma2, ls.noise_variance)
    rss_j = acc.residual_sum_of_squares(estimate)
    sigma2 = float(rss_j.sum() / max(acc.n_rows - ls.rank, 1))
    cov = ls.covariance * (sigma2 / ls.sigma2) if ls.sigma2 > 0 else ls.covariance * 0
    honest = solution_uncertainty(acc, ls, options, estimate=estimate, white_covariance=cov)
    return FitUncertainty(honest, sigma2, rss_j / max(acc.n - ls.rank / acc.nv, 1e-300))


def _rss(acc: InformationAccumulator, still: InformationAccumulator | None, theta):
    """Per-joint residual and torque sums of squares over all rows (fit and deadband rows)."""
    rss, zz = acc.residual_sum_of_squares(theta), acc.zz_joint.copy()
    if still is not None:
        rss, zz = rss + still.residual_sum_of_squares(theta), zz + still.zz_joint
    return rss, zz


def _file_entry(fs: FileSums, estimate, nominal, joints) -> dict:
    rec = fs.record
    err = relative_error(*_rss(fs.accumulator, fs.still, estimate))
    nom = relative_error(*_rss(fs.accumulator, fs.still, nominal))
    entry = {
        "file": str(rec.spec.path),
        "window": None if rec.spec.window is None else str(rec.spec.window),
        "n_samples": int(rec.n_samples),
        "error": finite_or_none(err.total),
        "per_joint": dict(zip(joints, map(finite_or_none, err.per_joint), strict=True)),
        "nominal_error": finite_or_none(nom.total),
        "nominal_per_joint": dict(zip(joints, map(finite_or_none, nom.per_joint), strict=True)),
    }
    if fs.still is not None:
        moving = relative_error(
            fs.accumulator.residual_sum_of_squares(estimate), fs.accumulator.zz_joint
        )
        entry["error_moving"] = finite_or_none(moving.total)
    return entry


def validation_errors(files: list[FileSums], estimate, nominal, joints) -> RelativeError:
    """Pooled and per-file validation errors of ``estimate`` and ``nominal``, from sums.

    ``||tau_j - Y_j theta||^2 = zz_j - 2 b_j.theta + theta.A_j.theta`` per file, over all
    rows (the rows inside a velocity deadband predicted with the same deadband); the
    pooled error is ``sqrt(sum_files SSE / sum_files ||tau||^2)`` (every sample weighs the
    same). With a deadband, ``validation_moving`` is the same over the moving rows only.
    Returns a :class:`RelativeError` holding only the validation fields (train NaN).
    """
    nv = len(joints)
    sse, sse_nom, zz = np.zeros(nv), np.zeros(nv), np.zeros(nv)
    sse_mov, zz_mov = np.zeros(nv), np.zeros(nv)
    for fs in files:
        s, z = _rss(fs.accumulator, fs.still, estimate)
        s0, _ = _rss(fs.accumulator, fs.still, nominal)
        sse, sse_nom, zz = sse + s, sse_nom + s0, zz + z
        sse_mov += fs.accumulator.residual_sum_of_squares(estimate)
        zz_mov += fs.accumulator.zz_joint
    val, nom = relative_error(sse, zz), relative_error(sse_nom, zz)
    moving = any(fs.still is not None for fs in files)
    return RelativeError(
        float("nan"),
        np.full(nv, np.nan),
        val.total,
        val.per_joint,
        validation_per_file=[_file_entry(fs, estimate, nominal, joints) for fs in files],
        nominal_validation=nom.total,
        nominal_validation_per_joint=nom.per_joint,
        validation_moving=relative_error(sse_mov, zz_mov).total if moving else None,
    )


def raw_errors(problem: Problem, estimate, nominal) -> RelativeError | None:
    """The errors against the raw (unfiltered) torques, from the raw-torque sums of the
    training rows and of the validation files (None when they were not read)."""
    if problem.raw is None:
        return None
    train = relative_error(problem.raw.residual_sum_of_squares(estimate), problem.raw.zz_joint)
    nom = relative_error(problem.raw.residual_sum_of_squares(nominal), problem.raw.zz_joint)
    val = nval = None
    vfiles = problem.validation_files
    if vfiles and all(fs.raw is not None for fs in vfiles):
        nv = problem.robot.nv
        sse, sse0, zz = np.zeros(nv), np.zeros(nv), np.zeros(nv)
        for fs in vfiles:
            assert fs.raw is not None
            sse += fs.raw.residual_sum_of_squares(estimate)
            sse0 += fs.raw.residual_sum_of_squares(nominal)
            zz += fs.raw.zz_joint
        val, nval = relative_error(sse, zz), relative_error(sse0, zz)
    return RelativeError(
        train.total,
        train.per_joint,
        None if val is None else val.total,
        None if val is None else val.per_joint,
        nominal_train=nom.total,
        nominal_train_per_joint=nom.per_joint,
        nominal_validation=None if nval is None else nval.total,
        nominal_validation_per_joint=None if nval is None else nval.per_joint,
    )


def stream_validation(robot: Robot, blocks, ind, estimate, nominal, chunk: int) -> RelativeError:
    """Validation errors of ``estimate`` and ``nominal`` by one pass over ``blocks``
    ``(q, dq, ddq, tau[, None, temp])`` (exact, no round-off floor). Validation fields only."""
    ev = robot.evaluator
    blocks = ev.sequential(blocks)  # one path: the hysteresis state carries
    thetas = [estimate, nominal]
    sse = [np.zeros(robot.nv) for _ in thetas]
    zz = np.zeros(robot.nv)
    for block in blocks:
        bq, bdq, bddq, btau = block[:4]
        vq, vdq, vddq, vtau = check_samples(robot, bq, bdq, bddq, btau, prefix="validation ")
        for c in ev.iter_regressor(vq, vdq, vddq, chunk, block_temperature(block)):
            Yb = c.Y[:, :, ind]
            for k, theta in enumerate(thetas):
                err = Yb @ theta - vtau[c.start : c.stop]  # [N m]
                sse[k] += np.einsum("nj,nj->j", err, err)
            zz += np.einsum("nj,nj->j", vtau[c.start : c.stop], vtau[c.start : c.stop])
    val, nom = relative_error(sse[0], zz), relative_error(sse[1], zz)
    return RelativeError(
        float("nan"),
        np.full(robot.nv, np.nan),
        val.total,
        val.per_joint,
        nominal_validation=nom.total,
        nominal_validation_per_joint=nom.per_joint,
    )


def _consistent(
    problem: Problem,
    ls: LeastSquaresSolution,
    opts: ConsistentOptions,
    method: str,
    honest: Uncertainty,
):
    """The consistent standard parameters, their base estimate, solver text and warnings
    (``honest``: the covariance the result reports, named in the fit-scale warning)."""
    acc, base = problem.accumulator, problem.base
    standard = consistent_estimate(
        problem.robot,
        acc,
        base,
        ls,
        solver=opts.solver,
        prior=opts.prior,
        prior_weight=opts.prior_weight,
        bounds=opts.bound_options(),
    )
    kind = "wls" if method == "wls" else "ols"
    solver = (
        f"physically consistent ({opts.solver}, {standard.status}, prior {opts.prior}) on the "
        f"{kind.upper()} information; covariance of the {kind.upper()} fit ({ls.solver})"
    )
    warnings_ = list(standard.warnings)  # implausible bodies, named
    if not standard.physically_consistent:
        warnings_.append(
            "the consistent estimate fails the eigenvalue test: "
            + "; ".join(standard.consistency.messages())
        )
    if standard.fit_scale > 10.0:  # f_feas / r: a chi-square of <= r dof would be ~1
        if honest.method == "hac":
            told = (
                "the reported standard deviations are the autocorrelation-consistent ones "
                f"({honest.inflation:.3g} times the white-noise ones)"
            )
        else:
            told = (
                f"the reported (white-noise) standard deviations are likely about "
                f"{np.sqrt(standard.fit_scale):.2g} times too small"
                + (f" ({honest.reason})" if honest.reason else "")
            )
        warnings_.append(
            f"the residuals are not white noise (correlated residuals, filtered torques, model "
            f"error): the best physical model's fit is {standard.fit_scale:.3g} times its "
            f"expected chi-square, so {told}; the prior was weighed against the fit in these "
            "inflated units"
        )
    standard = standard.with_covariance(honest.covariance, honest.covariance_white)
    return standard, base.to_base(standard.values), solver, warnings_


def _minimum_norm_check(problem: Problem, estimate):
    """Plain least squares: its minimum-norm standard vector and whether it is physical."""
    standard = minimum_norm_standard(problem.robot, problem.base, estimate)
    msgs = standard.consistency.messages()
    if not msgs:
        return standard, []
    return standard, [
        f"plain least squares is not physical: its minimum-norm standard parameters "
        f"break {len(msgs)} condition(s): "
        + "; ".join(msgs[:4])
        + ("; ..." if len(msgs) > 4 else "")
        + " (consistent=True, --consistent, estimates a physical model)"
    ]


def _convergence(problem: Problem, estimate) -> dict | None:
    """How far an online estimate's prediction moved over the last 10 % of the samples."""
    run, acc = problem.online, problem.accumulator
    if run is None or not run.estimator.record_every or acc.zz_joint.sum() <= 0:
        return None
    est, n = run.estimator, problem.accumulator.n
    h = est.history
    steps = np.arange(len(h.t)) * est.record_every  # samples seen at each record
    k = min(int(np.searchsorted(steps, 0.9 * n)), len(h.t) - 1)
    delta = estimate - h.theta[k]  # change over the last 10 % of the samples
    moved = float(np.sqrt(max(delta @ acc.A @ delta, 0.0) / acc.zz_joint.sum()))
    return {
        "window": 0.1,
        "from_sample": int(steps[k]),
        "prediction_change": moved,
        "parameter_change": float(
            np.linalg.norm(delta) / max(float(np.linalg.norm(estimate)), 1e-300)
        ),
    }


def _validation(problem: Problem, estimate, nominal, chunk: int) -> RelativeError | None:
    robot = problem.robot
    if problem.validation_files is not None:
        return validation_errors(problem.validation_files, estimate, nominal, robot.dof_names)
    if problem.validation_blocks is not None:
        ind = problem.base.independent
        return stream_validation(robot, problem.validation_blocks, ind, estimate, nominal, chunk)
    return None


def solve(
    problem: Problem,
    method: str | None = None,
    *,
    consistent: ConsistentOptions | None = None,
    minimum_norm: bool | None = None,
    chunk: int | None = None,
    uncertainty: UncertaintyOptions | str | dict | None = None,
) -> IdentificationResult:
    """The identification result of an accumulated problem (module docstring).

    Every option left None is the problem's own (``problem.settings``, set by
    :func:`~manip_id.identification.build_problem`); the problem's ``context`` joins the
    result's, and its ``post`` steps run last.

    Parameters
    ----------
    problem : Problem
        The sums, counts and records of the data.
    method : str or None
        "ols", "wls", or the online law "rls" / "gradient" whose pass
        ``problem.online`` holds (its final estimate, the least-squares covariance at it).
    consistent : ConsistentOptions or None
        A physically consistent estimate (``ols`` / ``wls``).
    minimum_norm : bool or None
        Solve rank-deficient data with the minimum-norm solution instead of raising.
    chunk : int or None
        Samples per regressor chunk of a streamed validation pass (default the problem's).
    uncertainty : UncertaintyOptions, str, dict or None
        The covariance: ``"auto"`` (default: autocorrelation-consistent from the sums'
        blocks when they hold enough, else white), ``"white"`` or ``"hac"``
        (:mod:`manip_id.estimators.uncertainty`). ``std``, ``std_percent`` and
        ``covariance`` are that one; ``std_white`` the white-noise std.

    Raises
    ------
    RankDeficiencyError
        These data do not excite every base parameter (and not ``minimum_norm``).
    """
    settings = problem.settings
    method = settings.method if method is None else method
    consistent = settings.consistent if consistent is None else consistent
    minimum_norm = settings.minimum_norm if minimum_norm is None else minimum_norm
    uncertainty = settings.uncertainty if uncertainty is None else uncertainty
    copts = consistent if consistent is not None else ConsistentOptions(enabled=False)
    check_method(method)
    if copts.enabled and method not in LEAST_SQUARES:
        raise InputError(f"consistent=True applies to ols and wls, got method {method!r}")
    if (method in LEAST_SQUARES) == (problem.online is not None):
        raise InputError(f"method {method!r} does not match the problem's online pass")
    robot, base, timings = problem.robot, problem.base, problem.timings
    uopts = UncertaintyOptions.from_value(uncertainty)
    fit = _fit(problem, method, copts, minimum_norm, uopts)
    nominal_b = np.asarray(base.to_base(robot.nominal_parameters), dtype=float)
    errors = _errors(problem, fit.estimate, nominal_b, int(chunk or problem.chunk))
    std = fit.uncertainty.std
    with np.errstate(divide="ignore", invalid="ignore"):
        std_pct = 100.0 * std / np.abs(fit.estimate)
    std_pct = np.where(np.isnan(std_pct), np.inf, std_pct)
    timings["total"] = time.perf_counter() - problem.t_start
    est_online = None if problem.online is None else problem.online.estimator
    result = IdentificationResult(
        method=method,
        robot_name=robot.name,
        names=list(base.base_names),
        expressions=list(base.expressions),
        estimate=fit.estimate,
        std=std,
        std_percent=std_pct,
        covariance=fit.uncertainty.covariance,
        std_white=fit.uncertainty.honest.std_white,
        covariance_white=fit.uncertainty.honest.covariance_white,
        uncertainty=fit.uncertainty.honest.to_dict(),
        sigma2=fit.uncertainty.sigma2,
        noise_variance=fit.uncertainty.noise_variance,
        condition_number=float(fit.rank_analysis.condition_number),
        rank_analysis=fit.rank_analysis,
        relative_error=errors,
        n_samples=int(problem.n_samples),
        timings=timings,
        solver=fit.solver,
        base=base,
        dof_names=list(robot.dof_names),
        history=est_online.history if est_online is not None and est_online.record_every else None,
        standard=fit.standard,
        warnings=fit.warnings,
        units=[robot.parameter_units[i] for i in base.independent],
        nominal=nominal_b,
        convergence=_convergence(problem, fit.estimate),
        model=problem.model,
        output_names=[] if problem.model == "dynamic" else _outputs(robot, problem.model),
        files=problem.files,
        raw_error=raw_errors(problem, fit.estimate, nominal_b),
        context={"model_structure": model_structure(robot), **problem.context},
    )
    for step in problem.post:
        result = step(result)
    return result


@dataclass
class _Fit:
    """The estimate of a problem and how it was obtained."""

    estimate: np.ndarray
    solver: str
    uncertainty: FitUncertainty
    rank_analysis: RankAnalysis
    standard: StandardEstimate | None
    warnings: list[str]


def _fit(
    problem: Problem,
    method: str,
    copts: ConsistentOptions,
    minimum_norm: bool,
    uopts: UncertaintyOptions,
) -> _Fit:
    """Rank check, least squares (or the online law's estimate), the consistent estimate."""
    robot, acc, base, timings = problem.robot, problem.accumulator, problem.base, problem.timings
    t0 = time.perf_counter()
    ra = analyze_information(acc.A, base.base_names, n_rows=acc.n_rows)
    timings["rank_analysis"] = time.perf_counter() - t0
    if ra.rank < base.n_base and not minimum_norm:
        raise RankDeficiencyError(
            ra.rank,
            base.n_base,
            ra.unidentifiable,
            subject=f"these data of {robot.name}",
            what="base parameter directions",
            hint="use a more exciting trajectory, or minimum_norm=True",
        )
    t0 = time.perf_counter()
    ls = solve_accumulator(
        acc,
        method="wls" if method == "wls" else "ols",
        names=base.base_names,
        minimum_norm=minimum_norm,
        rank_rtol=ra.tolerance,
    )
    estimate, solver = ls.estimate, ls.solver
    online = problem.online
    if online is not None:
        estimate = online.estimator.theta
        solver = (
            f"{online.description}, one pass over {acc.n} samples; covariance at the final "
            f"estimate ({ls.solver})"
        )
    unc = fit_uncertainty(acc, ls, None if online is None else estimate, uopts)
    standard: StandardEstimate | None = None
    warnings_: list[str] = []
    if copts.enabled:  # beta = P theta of consistent standard parameters
        standard, estimate, solver, warnings_ = _consistent(problem, ls, copts, method, unc.honest)
        timings["consistent"] = standard.time
    elif online is None:
        standard, warnings_ = _minimum_norm_check(problem, estimate)
    timings["solve"] = time.perf_counter() - t0
    return _Fit(estimate, solver, unc, ra, standard, warnings_)


def _errors(problem: Problem, estimate, nominal, chunk: int) -> RelativeError:
    """Training errors from the sums over all rows (identified and nominal model; with a
    deadband also over the moving rows), and the validation errors."""
    acc, still = problem.accumulator, problem.still
    train = relative_error(*_rss(acc, still, estimate))
    nom = relative_error(*_rss(acc, still, nominal))
    moving = None
    if still is not None:
        moving = relative_error(acc.residual_sum_of_squares(estimate), acc.zz_joint).total
    t0 = time.perf_counter()
    val = _validation(problem, estimate, nominal, chunk)
    if val is not None:
        problem.timings["validation"] = time.perf_counter() - t0
    return RelativeError(
        train.total,
        train.per_joint,
        None if val is None else val.validation,
        None if val is None else val.validation_per_joint,
        validation_per_file=None if val is None else val.validation_per_file,
        nominal_train=nom.total,
        nominal_train_per_joint=nom.per_joint,
        nominal_validation=None if val is None else val.nominal_validation,
        nominal_validation_per_joint=None if val is None else val.nominal_validation_per_joint,
        train_moving=moving,
        validation_moving=None if val is None else val.validation_moving,
    )


def _outputs(robot: Robot, model: str) -> list[str]:
    return ["energy"] if model == "energy" else list(robot.dof_names)


__all__ = [
    "FitUncertainty",
    "fit_uncertainty",
    "raw_errors",
    "solve",
    "stream_validation",
    "validation_errors",
]
