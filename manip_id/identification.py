"""Identification: robot + data -> base parameters with their uncertainty, streamed.

The pipeline, for N samples ``(q, dq, ddq, tau)``::

    base parameters     theta_b = theta_1 + K theta_2        (structural rank analysis)
    regressor chunks    Y_b = Y(q, dq, ddq)[..., independent]    (N, nv, r), chunk by chunk
    accumulate          A_j, b_j, zz_j per joint                (memory O(nv r^2))
    rank check          what these data excite (RankDeficiencyError otherwise)
    solve               OLS / WLS from the sums, or one online pass (RLS / gradient)
    validate            relative torque error on other data, one more streamed pass

Nothing holds the stacked regressor: memory is O(chunk nv p + nv r^2) whatever N.
The relative torque error is ``||tau - tau_hat|| / ||tau||`` over all samples and
joints, also per joint; the training one comes from the sums
(``RSS_j = zz_j - 2 b_j.theta + theta.A_j.theta``), so its floor is about 1e-8.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg.blas import dsyrk

from ._checks import as_float_array, as_int, check_finite, check_magnitude
from .errors import InputError, RankDeficiencyError
from .estimators import (
    GradientEstimator,
    InformationAccumulator,
    LeastSquaresSolution,
    OnlineHistory,
    RLSEstimator,
    solve_accumulator,
)
from .estimators.consistent import (
    DEFAULT_PRIOR_WEIGHT,
    StandardEstimate,
    consistent_estimate,
    minimum_norm_standard,
)
from .estimators.consistent import check_options as check_consistent_options
from .estimators.consistent.bounds import BoundsOptions
from .estimators.consistent.terms import missing_term_warnings
from .execution import ForkBackend
from .identifiability import BaseParameters, RankAnalysis, analyze, analyze_information
from .regressor import DEFAULT_CHUNK, check_states, iter_regressor
from .robot import Robot

METHODS: tuple[str, ...] = ("ols", "wls", "rls", "gradient")


@dataclass(frozen=True)
class RelativeError:
    """Relative torque errors ``||tau - tau_hat|| / ||tau||``, overall and per joint (nv,)."""

    train: float
    train_per_joint: np.ndarray
    validation: float | None = None
    validation_per_joint: np.ndarray | None = None
    #: per validation file ``{"file", "n_samples", "error", "per_joint"}`` when known
    validation_per_file: list[dict] | None = None
    #: the same errors of the nominal (URDF) model, ``Y_b theta_b_nominal``, when known
    nominal_train: float | None = None
    nominal_train_per_joint: np.ndarray | None = None
    nominal_validation: float | None = None
    nominal_validation_per_joint: np.ndarray | None = None


@dataclass(frozen=True)
class IdentificationResult:
    """Identified base parameters, their uncertainty and how they were obtained.

    Attributes
    ----------
    method: "ols", "wls", "rls" or "gradient"
    robot_name: name of the robot
    names: one name per base parameter (its independent column, ``R`` if regrouped)
    expressions: each base parameter in standard parameter names
    estimate: base parameters theta_b, shape (r,) [units of the independent columns]
    std: standard deviations, shape (r,); std_percent: ``100 std / |estimate|`` [%]
    covariance: shape (r, r): ``sigma2 (Y_b^T Y_b)^-1`` (OLS, and RLS/gradient at their
        final estimate), ``(Y_b^T W Y_b)^-1`` for WLS
    sigma2: residual variance [(N m)^2] (weighted, about 1, for WLS)
    noise_variance: per-joint residual variance, shape (nv,) [(N m)^2]
    condition_number: 2-norm condition number of the base regressor on these data
    rank_analysis: what these data excite (analysis of the accumulated information)
    relative_error: train / validation relative torque errors
    n_samples: number of training samples N
    timings: seconds per stage
    solver: how the estimate was computed, including any fallback
    base: the base parametrization used
    dof_names: joint names, length nv
    history: record of the online law (``rls``/``gradient``), else None
    standard: the standard parameters with their eigenvalue test
        (:class:`~manip_id.estimators.consistent.StandardEstimate`): the consistent
        estimate (``consistent=True``; then ``estimate`` holds the base parameters it
        implies, ``P theta``), or for plain OLS/WLS the minimum-norm standard vector
    warnings: e.g. the physical-consistency violations of a plain least-squares fit
    per_file: each file's own estimate (:class:`manip_id.fleet.FileEstimate`) when
        :func:`manip_id.fleet.identify_files` was asked ``per_file=True``, else None
    model: "dynamic" (tau = Y(q, dq, ddq) theta), "energy" or "momentum"
        (:mod:`manip_id.models`); the training errors, ``sigma2`` and
        ``noise_variance`` are those of the model's own equation (per output of
        ``output_names``), the validation error is always the torque error
    output_names: names of the model's outputs (default ``dof_names``; "energy"
        for the energy model's one scalar row per window)
    files: :func:`identify_datasets` only: ``{"train": [...], "validation": [...]}``,
        the :class:`~manip_id.pipeline.FileAccumulation` of each file (its
        data-quality summary, samples, rows left out by the deadband)
    """

    method: str
    robot_name: str
    names: list[str]
    expressions: list[str]
    estimate: np.ndarray
    std: np.ndarray
    std_percent: np.ndarray
    covariance: np.ndarray
    sigma2: float
    noise_variance: np.ndarray
    condition_number: float
    rank_analysis: RankAnalysis
    relative_error: RelativeError
    n_samples: int
    timings: dict[str, float]
    solver: str
    base: BaseParameters
    dof_names: list[str] = field(default_factory=list)
    history: OnlineHistory | None = None
    per_file: list | None = None
    standard: StandardEstimate | None = None
    warnings: list[str] = field(default_factory=list)
    model: str = "dynamic"
    output_names: list[str] = field(default_factory=list)
    files: dict | None = None
    units: list[str] = field(default_factory=list)
    nominal: np.ndarray | None = None
    convergence: dict | None = None
    context: dict = field(default_factory=dict)

    @property
    def standard_parameters(self) -> list[dict]:
        """``[{"name", "value", "unit", "nominal"}]`` per standard parameter (see ``standard``)."""
        if self.standard is None:
            return list(self.context.get("standard_parameters", []))
        return self.standard.to_dict()["standard_parameters"]

    @property
    def physically_consistent(self) -> bool | None:
        """The independent eigenvalue test of the standard parameters (None without them)."""
        if self.standard is None:
            return self.context.get("physically_consistent")
        return self.standard.physically_consistent

    def predict(self, robot: Robot, q, dq, ddq, *, chunk: int = DEFAULT_CHUNK) -> np.ndarray:
        """Predicted torques ``Y_b(q, dq, ddq) theta_b``, shape (N, nv) [N m or N].

        ``q`` (N, nq), ``dq`` and ``ddq`` (N, nv); streamed chunk by chunk.
        """
        if robot.n_parameters != len(self.base.names):
            raise InputError(
                f"robot.n_parameters={robot.n_parameters} but this result was "
                f"identified for {len(self.base.names)} parameters"
            )
        batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
        if not batched:
            q, dq, ddq = q[None], dq[None], ddq[None]
        out = np.empty((q.shape[0], robot.nv))
        ind = self.base.independent
        for c in iter_regressor(robot, q, dq, ddq, chunk=chunk):
            out[c.start : c.stop] = c.Y[:, :, ind] @ self.estimate
        return out if batched else out[0]

    def to_dict(
        self,
        *,
        poorly_identified: float | None = None,
        condition_limit: float | None = None,
        convergence_limit: float | None = None,
    ) -> dict:
        """The one JSON schema of a result (CLI ``--json``, a report's result.json,
        :func:`manip_id.results.load_result`); see :mod:`manip_id.results`.

        poorly_identified: std above this [%] flags a base parameter "poorly identified"
        (default 10); condition_limit: a condition number above it is a warning (default
        100); convergence_limit: an online estimate whose prediction moved by more than
        this fraction of the torque over the last 10 % of the data is "not converged"
        (default 0.01).
        """
        from .results import result_to_dict

        return result_to_dict(
            self,
            poorly_identified=poorly_identified,
            condition_limit=condition_limit,
            convergence_limit=convergence_limit,
        )

    def table(self, max_rows: int | None = None) -> str:
        """A readable text table: one row per base parameter, then the fit statistics."""
        re = self.relative_error
        lines = [
            f"{self.method.upper()} identification of {self.robot_name}: {len(self.names)} base "
            f"parameters from {self.n_samples} samples"
            + ("" if self.model == "dynamic" else f" ({self.model} model)"),
            f"solver: {self.solver}",
            f"condition number {self.condition_number:.4g}, sigma^2 {self.sigma2:.4g}, "
            f"relative torque error train {re.train:.4g}"
            + (f", validation {re.validation:.4g}" if re.validation is not None else ""),
        ]
        w = max([len("parameter")] + [len(n) for n in self.names])
        lines.append(f"{'parameter':<{w}}  {'estimate':>13}  {'std':>11}  {'std %':>8}  expression")
        rows = list(
            zip(
                self.names, self.estimate, self.std, self.std_percent, self.expressions, strict=True
            )
        )
        for n, x, s, sp, e in rows[: max_rows if max_rows is not None else len(rows)]:
            pct = f"{sp:8.3g}" if np.isfinite(sp) else f"{'inf':>8}"
            lines.append(f"{n:<{w}}  {x:13.6g}  {s:11.4g}  {pct}  {e}")
        if max_rows is not None and len(rows) > max_rows:
            lines.append(f"... {len(rows) - max_rows} more")
        per = ", ".join(
            f"{d} {v:.3g}"
            for d, v in zip(self.output_names or self.dof_names, re.train_per_joint, strict=True)
        )
        lines.append(f"train error per joint: {per}")
        if re.validation_per_joint is not None:
            per = ", ".join(
                f"{d} {v:.3g}" for d, v in zip(self.dof_names, re.validation_per_joint, strict=True)
            )
            lines.append(f"validation error per joint: {per}")
        if self.standard is not None:
            lines += self.standard.summary_lines()
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if np.isfinite(x) else None


def _check_tau(robot: Robot, tau, n: int, name: str = "tau") -> np.ndarray:
    tau = as_float_array(tau, name, ndim=2)
    if tau.shape != (n, robot.nv):
        raise InputError(
            f"{name}.shape={tau.shape} but expected ({n}, robot.nv={robot.nv}) to match the states"
        )
    check_finite(tau, name, robot.dof_names)
    check_magnitude(tau, name, robot.dof_names, kind="tau")  # |tau| <= 1e6, not all tiny
    return tau


def _states(robot: Robot, q, dq, ddq, tau, prefix: str = ""):
    batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
    if not batched:
        raise InputError(
            f"{prefix}identification takes N samples (2-D arrays), got q.shape={q.shape}"
        )
    tau = _check_tau(robot, tau, q.shape[0], prefix + "tau")
    return q, dq, ddq, tau


@dataclass(frozen=True)
class OnlineOptions:
    """Options of the online laws of :func:`identify` (``method="rls"`` or ``"gradient"``).

    ``None`` means the default. The RLS-only options (``P0``, ``forgetting``, ``p_min``,
    ``p_max``) are refused with the gradient law, and the gradient-only ones (``gamma``,
    ``normalized``) with RLS (:class:`~manip_id.estimators.RLSEstimator`,
    :class:`~manip_id.estimators.GradientEstimator`).

    Attributes
    ----------
    theta0: initial estimate, shape (r,) [units of the base parameters]; default zeros
    record_every: keep every k-th estimate in the history (0: none); default
        ``max(1, N // 1000)``, the record the convergence check reads
    bounds: ``(lower, upper)`` box on the estimate, shapes (r,); default none
    t0: time of the first sample [s]
    P0: RLS initial covariance: scalar (times I), (r,) or (r, r); default 1e6
    forgetting: RLS forgetting factor lambda in (0, 1]; default 1 (none)
    p_min, p_max: RLS bounds on trace(P)
    gamma: gradient gain: scalar, (r,) or (r, r) SPD; default 1
    normalized: normalized gradient law; default True
    """

    theta0: ArrayLike | None = None
    record_every: int | None = None
    bounds: tuple[ArrayLike, ArrayLike] | None = None
    t0: float = 0.0
    P0: ArrayLike | None = None
    forgetting: float | None = None
    p_min: float | None = None
    p_max: float | None = None
    gamma: ArrayLike | None = None
    normalized: bool | None = None

    #: options that only one law takes
    RLS_ONLY: ClassVar[tuple[str, ...]] = ("P0", "forgetting", "p_min", "p_max")
    GRADIENT_ONLY: ClassVar[tuple[str, ...]] = ("gamma", "normalized")

    @classmethod
    def from_value(cls, online: OnlineOptions | dict | None) -> OnlineOptions:
        """``online`` as options: None (the defaults), OnlineOptions, or a dict of its fields.

        Raises
        ------
        InputError: a key that is not a field, or a value that is neither.
        """
        if online is None:
            return cls()
        if isinstance(online, cls):
            return online
        if not isinstance(online, dict):
            raise InputError(
                f"online must be OnlineOptions, a dict of its fields or None, "
                f"got {type(online).__name__}"
            )
        known = [f.name for f in fields(cls)]
        unknown = [k for k in online if k not in known]
        if unknown:
            raise InputError(f"unknown online option(s) {unknown}: expected some of {known}")
        return cls(**online)

    def check_method(self, method: str) -> None:
        """Raise :class:`InputError` for an option the law ``method`` does not take."""
        other = self.GRADIENT_ONLY if method == "rls" else self.RLS_ONLY
        given = [k for k in other if getattr(self, k) is not None]
        if given:
            law = "RLS" if method == "rls" else "the gradient law"
            raise InputError(f"online option(s) {given} do not apply to {law} (method={method!r})")


def _online_estimator(method: str, r: int, options: OnlineOptions, n: int):
    """The online law of ``method`` over ``n`` samples, and a text naming it."""
    options.check_method(method)
    theta0 = np.zeros(r) if options.theta0 is None else options.theta0
    record = max(1, n // 1000) if options.record_every is None else options.record_every
    common = dict(bounds=options.bounds, record_every=record, t0=options.t0)
    if method == "rls":
        P0 = 1e6 if options.P0 is None else options.P0
        forgetting = 1.0 if options.forgetting is None else options.forgetting
        est = RLSEstimator(
            theta0, P0, forgetting=forgetting, p_min=options.p_min, p_max=options.p_max, **common
        )
        what = f"RLS (P0={P0 if np.ndim(P0) == 0 else 'given'}, forgetting {est.forgetting:g})"
    else:
        gamma = 1.0 if options.gamma is None else options.gamma
        normalized = True if options.normalized is None else options.normalized
        est = GradientEstimator(theta0, gamma, normalized=normalized, **common)
        what = ("normalized " if normalized else "") + "gradient law"
    return est, what


def _resolve_base(robot: Robot, base, timings: dict) -> BaseParameters:
    t0 = time.perf_counter()
    if base is None:
        base = analyze(robot).base
        timings["structural_analysis"] = time.perf_counter() - t0
    elif not isinstance(base, BaseParameters):
        raise InputError(f"base must be BaseParameters, got {type(base).__name__}")
    if len(base.names) != robot.n_parameters:
        raise InputError(
            f"base is for {len(base.names)} parameters but robot.n_parameters={robot.n_parameters}"
        )
    return base


def _check_method(method: str, chunk: int, workers: int) -> None:
    if method not in METHODS:
        raise InputError(f"method must be one of {list(METHODS)}, got {method!r}")
    if as_int(chunk, "chunk") < 1:
        raise InputError(f"chunk must be a positive number of samples, got {chunk}")
    if as_int(workers, "workers") < 1:
        raise InputError(f"workers must be a positive number of processes, got {workers}")


def row_supports(robot: Robot, columns, n_states: int = 16, seed: int = 12345) -> list[np.ndarray]:
    """Per joint, the positions in ``columns`` whose regressor entry is not identically zero.

    Evaluated at ``n_states`` random states within the limits: an entry that is
    a non-zero function of the state vanishes at random states with probability
    zero, while the structural zeros (bodies that are not in the joint's
    subtree, other joints' terms) are exact zeros in Pinocchio's regressor.
    Returns a list of ``nv`` sorted index arrays.
    """
    q, dq, ddq = robot.random_states(n_states, seed=seed)
    ev = robot.evaluator
    Y = np.stack([ev.regressor(q[k], dq[k], ddq[k]) for k in range(n_states)])
    nonzero = np.abs(Y[:, :, np.asarray(columns, dtype=np.intp)]).max(axis=0) > 0  # (nv, r)
    return [np.flatnonzero(row) for row in nonzero]


def _accumulate_blocks(
    robot: Robot,
    blocks,
    ind: np.ndarray,
    chunk: int,
    progress=None,
    total: int = 0,
    deadband: np.ndarray | None = None,
) -> tuple[InformationAccumulator, dict[str, float]]:
    """Accumulate the base-column information of blocks ``(q, dq, ddq, tau)``, each checked.

    Row ``j`` of the regressor is accumulated on its non-zero columns only
    (:func:`row_supports`): in a serial chain that about halves the work of the
    symmetric rank-k updates. ``deadband`` (nv,) [rad/s or m/s]: the rows of
    joint ``j`` of samples with ``|dq_j| < deadband_j`` are left out of the sums
    (standstill, where the Coulomb column sign(dq_j) is noise); the sample
    count ``n`` still counts every sample.
    """
    ev = robot.evaluator
    nv = robot.nv
    supports = row_supports(robot, ind)
    A_c = [np.zeros((sj.size, sj.size)) for sj in supports]
    b_c = [np.zeros(sj.size) for sj in supports]
    zz = np.zeros(nv)
    t_reg = t_acc = 0.0
    done = 0
    for block in blocks:
        try:
            bq, bdq, bddq, btau = block
        except (TypeError, ValueError) as exc:
            raise InputError("each data block must be a tuple (q, dq, ddq, tau)") from exc
        bq, bdq, bddq, btau = _states(
            robot, bq, bdq, bddq, btau, prefix=f"block at sample {done}: "
        )
        t0 = time.perf_counter()
        for start, stop, rows in ev.iter_row_supports(bq, bdq, bddq, ind, supports, chunk):
            t1 = time.perf_counter()
            t_reg += t1 - t0
            tau = btau[start:stop]
            if deadband is not None:  # per-joint row mask: moving samples only
                keep = np.abs(bdq[start:stop]) >= deadband
                tau = np.where(keep, tau, 0.0)
            for j in range(nv):
                rj = rows[j] if deadband is None else rows[j][keep[:, j]]
                # lower triangle of A_c[j] (C order) == upper of its Fortran view
                dsyrk(1.0, rj.T, beta=1.0, c=A_c[j].T, trans=0, lower=0, overwrite_c=1)
                b_c[j] += (tau[:, j] if deadband is None else tau[keep[:, j], j]) @ rj
            zz += np.einsum("nj,nj->j", tau, tau)
            t0 = time.perf_counter()
            t_acc += t0 - t1
            if progress is not None:
                progress(done + stop, total)
        done += bq.shape[0]
    acc = InformationAccumulator(len(ind), nv).add_sums(A_c, b_c, zz, done, supports)
    return acc, {"regressor": t_reg, "accumulate": t_acc}


def _part_accumulate(robot: Robot, func, args, ind, chunk: int):
    """One part ``(func, args)``: the blocks ``func(*args)`` accumulated (a task)."""
    return _accumulate_blocks(robot, func(*args), ind, chunk)


def _accumulate_parallel(robot: Robot, parts, ind, chunk: int, workers: int, progress=None):
    """Accumulate ``parts`` (each ``(func, args)`` with ``func(*args)`` yielding blocks) in
    ``workers`` forked processes; the accumulators merge by addition in part order."""
    parts = list(parts)

    def report(k: int, _value) -> None:
        if progress is not None:
            progress(k + 1, len(parts))

    with ForkBackend(workers) as backend:
        results = backend.map(
            _part_accumulate,
            [(robot, func, args, ind, chunk) for func, args in parts],
            on_result=report,
        )
    acc = results[0][0].copy()
    for other, _ in results[1:]:
        acc.merge(other)
    times = {
        "regressor": sum(t["regressor"] for _, t in results),
        "accumulate": sum(t["accumulate"] for _, t in results),
    }
    return acc, times


def _array_part(q, dq, ddq, tau, start: int, stop: int):
    """The one block of samples ``start:stop`` (the arrays reach the workers by fork)."""
    yield q[start:stop], dq[start:stop], ddq[start:stop], tau[start:stop]


def _accumulate_serial(robot: Robot, q, dq, ddq, tau, ind, chunk: int, progress=None):
    """Serial back-end: the samples' information in this process."""
    return _accumulate_blocks(
        robot, [(q, dq, ddq, tau)], ind, chunk, progress=progress, total=q.shape[0]
    )


def _accumulate_forked(robot: Robot, q, dq, ddq, tau, ind, chunk: int, workers: int):
    """Forked back-end: ``workers`` contiguous parts of the samples in forked processes,
    merged by addition (equal to the serial sums to round-off)."""
    t0 = time.perf_counter()
    n = q.shape[0]
    bounds = np.linspace(0, n, workers + 1).astype(int)
    parts = [
        (_array_part, (q, dq, ddq, tau, int(a), int(b)))
        for a, b in zip(bounds[:-1], bounds[1:], strict=True)
    ]
    acc, times = _accumulate_parallel(robot, parts, ind, chunk, workers)
    times["accumulate_wall"] = time.perf_counter() - t0
    return acc, times


def _accumulate_online(
    robot: Robot, q, dq, ddq, tau, ind, chunk: int, est, dt: float, progress=None
):
    """Online back-end: one pass of the law ``est`` over the samples in order, with the
    information accumulated in the same pass (for the covariance and the errors)."""
    n, nv = q.shape[0], robot.nv
    acc = InformationAccumulator(len(ind), nv)
    t_reg = t_acc = t_onl = 0.0
    t0 = time.perf_counter()
    for c in iter_regressor(robot, q, dq, ddq, chunk=chunk):
        t1 = time.perf_counter()
        t_reg += t1 - t0
        Yb = np.ascontiguousarray(c.Y[:, :, ind])
        acc.add(Yb, tau[c.start : c.stop], check=False)
        t2 = time.perf_counter()
        t_acc += t2 - t1
        step = est.step
        for i in range(c.stop - c.start):
            step(Yb[i], tau[c.start + i], dt)
        t_onl += time.perf_counter() - t2
        if progress is not None:
            progress(c.stop, n)
        t0 = time.perf_counter()
    return acc, {"regressor": t_reg, "accumulate": t_acc, "online": t_onl}


def _validation_error(robot: Robot, blocks, ind, estimate, chunk: int, nominal=None):
    """Relative torque error of ``estimate`` (and of ``nominal``, same pass) on ``blocks``:
    ``(error, per_joint)``, or with ``nominal`` ``((error, per_joint), (error, per_joint))``."""
    ev = robot.evaluator
    thetas = [estimate] if nominal is None else [estimate, nominal]
    sse = [np.zeros(robot.nv) for _ in thetas]
    zz = np.zeros(robot.nv)
    for bq, bdq, bddq, btau in blocks:
        vq, vdq, vddq, vtau = _states(robot, bq, bdq, bddq, btau, prefix="validation ")
        for c in ev.iter_regressor(vq, vdq, vddq, chunk):
            Yb = c.Y[:, :, ind]
            for k, theta in enumerate(thetas):
                err = Yb @ theta - vtau[c.start : c.stop]  # [N m]
                sse[k] += np.einsum("nj,nj->j", err, err)
            zz += np.einsum("nj,nj->j", vtau[c.start : c.stop], vtau[c.start : c.stop])
    out = []
    for s in sse:
        with np.errstate(divide="ignore", invalid="ignore"):
            per_joint = np.sqrt(s / zz)
        out.append(
            ((float(np.sqrt(s.sum() / zz.sum())) if zz.sum() > 0 else float("nan")), per_joint)
        )
    return out[0] if nominal is None else tuple(out)


def _validation_blocks(robot: Robot, validation) -> list | None:
    """``validation = (q, dq, ddq, tau)`` checked as one validation block, or None."""
    if validation is None:
        return None
    try:
        vq, vdq, vddq, vtau = validation
    except (TypeError, ValueError) as exc:
        raise InputError("validation must be a tuple (q, dq, ddq, tau)") from exc
    return [_states(robot, vq, vdq, vddq, vtau, prefix="validation ")]


def _check_equations(n: int, nv: int, r: int) -> None:
    """Raise unless ``n`` samples of ``nv`` joints give more equations than ``r`` unknowns."""
    if n * nv <= r:
        raise InputError(
            f"{n} samples give {n * nv} equations for {r} base parameters: need more samples"
        )


def identify(
    robot: Robot,
    q,
    dq,
    ddq,
    tau,
    *,
    method: str = "ols",
    validation: tuple | None = None,
    chunk: int = DEFAULT_CHUNK,
    base: BaseParameters | None = None,
    progress: Callable[[int, int], None] | None = None,
    minimum_norm: bool = False,
    online: OnlineOptions | dict | None = None,
    dt: float = 1.0,
    workers: int = 1,
    consistent: bool = False,
    solver: str = "sdp",
    prior: str = "nominal",
    prior_weight: float = DEFAULT_PRIOR_WEIGHT,
    bounds: BoundsOptions | None = None,
    model: str = "dynamic",
    window_length: float | None = None,
) -> IdentificationResult:
    """Identify the base parameters of ``robot`` from N samples, streamed.

    Parameters
    ----------
    robot: the robot (its joint terms decide the columns)
    q: positions [rad or m], shape (N, nq); dq [rad/s], ddq [rad/s^2], tau [N m], shape (N, nv)
    method: "ols" (ordinary least squares), "wls" (weighted by per-joint noise
        variances from the OLS residuals), "rls" (one pass of recursive least
        squares), "gradient" (one pass of the normalized gradient law)
    validation: optional ``(q, dq, ddq, tau)`` for the validation error
    chunk: samples per regressor chunk
    base: base parametrization; default the structural one of ``analyze(robot)``
    progress: called as ``progress(done, total)`` after every chunk
    minimum_norm: solve rank-deficient data with the minimum-norm solution
        instead of raising :class:`RankDeficiencyError`
    online: options of the online law, :class:`OnlineOptions` or a dict of its fields
        (``theta0``, ``P0``, ``forgetting``, ``p_min``, ``p_max``, ``gamma``,
        ``normalized``, ``bounds``, ``record_every``, ``t0``; an unknown key is an
        :class:`InputError`); defaults ``theta0 = 0``, ``P0 = 1e6``, ``gamma = 1``,
        normalized
    dt: sample time [s] given to the online law (the gradient law's Euler step)
    workers: processes for "ols"/"wls": the samples are cut into ``workers``
        contiguous parts accumulated in forked processes and merged by addition
        (the result equals the serial one to round-off)
    consistent: estimate physically consistent standard parameters ("ols"/"wls"):
        every body's pseudo-inertia positive definite, ``Ia, fv, fc >= 0``, the
        same (weighted) residual through the base parameters, the null space filled
        by the prior (:mod:`manip_id.estimators.consistent`)
    solver: "sdp" (cvxpy + Clarabel) or "logchol" (log-Cholesky Levenberg-Marquardt)
    prior: "nominal" (the URDF parameters, log-det divergence) or "none"
    prior_weight: weight of the prior against the fit in standard deviations
    bounds: plausibility bounds of the consistent estimate
        (:class:`~manip_id.estimators.consistent.bounds.BoundsOptions`; default: each
        body inside the bounding ellipsoid of its link)
    model: "dynamic" (needs ``ddq``), or "energy" / "momentum", which need no
        acceleration (``ddq`` may be None; ``dt`` is then the sample time [s] of
        uniformly sampled data; see :mod:`manip_id.models`); "ols"/"wls" only
    window_length: energy interval / momentum row spacing [s] (default
        :data:`manip_id.models.DEFAULT_WINDOW`); the momentum filter's bandwidth
        is ``3 / window_length`` [rad/s]
    """
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    _check_method(method, chunk, workers)
    online_options = OnlineOptions.from_value(online)
    if model != "dynamic":
        return _identify_acceleration_free(
            robot,
            q,
            dq,
            tau,
            model=model,
            dt=dt,
            window_length=window_length,
            method=method,
            validation=validation,
            base=base,
            chunk=int(chunk),
            minimum_norm=minimum_norm,
            consistent=(consistent, solver, prior, prior_weight, bounds),
            timings=timings,
            t_start=t_start,
        )
    q, dq, ddq, tau = _states(robot, q, dq, ddq, tau)
    n = q.shape[0]
    blocks = _validation_blocks(robot, validation)
    timings["checks"] = time.perf_counter() - t_start
    base = _resolve_base(robot, base, timings)
    ind = base.independent
    r, nv = base.n_base, robot.nv
    _check_equations(n, nv, r)

    est = None
    solver_online = ""
    chunk = int(chunk)
    if method in ("rls", "gradient"):
        est, solver_online = _online_estimator(method, r, online_options, n)
        acc, times = _accumulate_online(robot, q, dq, ddq, tau, ind, chunk, est, dt, progress)
    elif workers > 1 and n >= 2 * workers:
        acc, times = _accumulate_forked(robot, q, dq, ddq, tau, ind, chunk, workers)
    else:
        acc, times = _accumulate_serial(robot, q, dq, ddq, tau, ind, chunk, progress)
    timings.update(times)
    result = _finish(
        robot,
        acc,
        base,
        method,
        timings,
        t_start,
        validation=blocks,
        chunk=int(chunk),
        minimum_norm=minimum_norm,
        est=est,
        solver_online=solver_online,
        consistent=(consistent, solver, prior, prior_weight, bounds),
    )
    # an implausible consistent fit: would a joint term the model lacks lower the error?
    result.warnings.extend(
        missing_term_warnings(robot, result.standard, [(q, dq, ddq, tau)], blocks, ind, chunk)
    )
    return result


def _identify_acceleration_free(
    robot: Robot,
    q,
    dq,
    tau,
    *,
    model: str,
    dt: float,
    window_length,
    method: str,
    validation,
    base,
    chunk: int,
    minimum_norm: bool,
    consistent: tuple,
    timings: dict,
    t_start: float,
) -> IdentificationResult:
    """The energy / momentum path of :func:`identify`: their rows, the usual solve."""
    from .models import MODELS, accumulate_energy, accumulate_momentum

    if model not in MODELS:
        raise InputError(f"model must be one of {list(MODELS)}, got {model!r}")
    if method not in ("ols", "wls"):
        raise InputError(f"the {model} model is solved by least squares (ols, wls), got {method!r}")
    batched, (q, dq) = check_states(robot, q=q, dq=dq)
    if not batched:
        raise InputError(f"identification takes N samples (2-D arrays), got q.shape={q.shape}")
    tau = _check_tau(robot, tau, q.shape[0])
    validation = _validation_blocks(robot, validation)
    timings["checks"] = time.perf_counter() - t_start
    base = _resolve_base(robot, base, timings)
    t0 = time.perf_counter()
    accumulate = accumulate_energy if model == "energy" else accumulate_momentum
    acc = accumulate(
        robot, q, dq, tau, dt=dt, window_length=window_length, columns=base.independent
    )
    timings["accumulate"] = time.perf_counter() - t0
    if acc.n_rows <= base.n_base:
        raise InputError(
            f"{acc.n} {model}-model rows ({acc.n_rows} equations) for {base.n_base} base "
            "parameters: give more samples or a shorter window_length"
        )
    res = _finish(
        robot,
        acc,
        base,
        method,
        timings,
        t_start,
        validation=validation,
        chunk=chunk,
        minimum_norm=minimum_norm,
        consistent=consistent,
    )
    outputs = ["energy"] if model == "energy" else list(robot.dof_names)
    return replace(res, model=model, output_names=outputs, n_samples=q.shape[0])


def identify_chunks(
    robot: Robot,
    source,
    *,
    method: str = "ols",
    validation=None,
    chunk: int = DEFAULT_CHUNK,
    base: BaseParameters | None = None,
    progress: Callable[[int, int], None] | None = None,
    minimum_norm: bool = False,
    workers: int = 1,
    scheduler=None,
    consistent: bool = False,
    solver: str = "sdp",
    prior: str = "nominal",
    prior_weight: float = DEFAULT_PRIOR_WEIGHT,
    bounds: BoundsOptions | None = None,
) -> IdentificationResult:
    """Least-squares identification from data that arrive in blocks (files, logs, streams).

    ``source`` is either an iterable of blocks ``(q, dq, ddq, tau)`` (shapes
    (n, nq), (n, nv), (n, nv), (n, nv); processed in one process), or, with
    ``workers > 1``, a sequence of parts ``(func, args)`` where ``func(*args)``
    yields such blocks: each part is accumulated in its own forked process and
    the accumulators merge by addition. Memory stays O(chunk nv p + nv r^2)
    per process however many samples flow through. ``validation`` is an
    iterable of blocks too. Methods: "ols" and "wls" (the online laws need
    the samples in order: use :func:`identify`). With ``scheduler`` (a Dask
    scheduler spec or client, see :func:`manip_id.fleet.identify_files`) each
    part is one Dask task and the sums are added in a tree on the cluster.
    """
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    _check_method(method, chunk, workers)
    if method not in ("ols", "wls"):
        raise InputError(f"identify_chunks solves least squares (ols, wls), got {method!r}")
    base = _resolve_base(robot, base, timings)
    ind = base.independent
    t0 = time.perf_counter()
    if workers > 1 or scheduler is not None:
        parts = list(source)
        for k, part in enumerate(parts):
            if not (isinstance(part, tuple) and len(part) == 2 and callable(part[0])):
                raise InputError(
                    f"with workers > 1 or a scheduler, source must be parts (func, args); "
                    f"part {k} is {type(part).__name__}"
                )
        if scheduler is not None:
            from .fleet import accumulate_parts

            acc, times = accumulate_parts(robot, parts, ind, int(chunk), scheduler)
        else:
            acc, times = _accumulate_parallel(robot, parts, ind, int(chunk), workers, progress)
        timings["accumulate_wall"] = time.perf_counter() - t0
    else:
        acc, times = _accumulate_blocks(robot, source, ind, int(chunk), progress=progress)
    timings.update(times)
    _check_equations(acc.n, robot.nv, base.n_base)
    return _finish(
        robot,
        acc,
        base,
        method,
        timings,
        t_start,
        validation=validation,
        chunk=int(chunk),
        minimum_norm=minimum_norm,
        consistent=(consistent, solver, prior, prior_weight, bounds),
    )


def _finish(
    robot: Robot,
    acc: InformationAccumulator,
    base: BaseParameters,
    method: str,
    timings: dict,
    t_start: float,
    *,
    validation=None,
    chunk: int = DEFAULT_CHUNK,
    minimum_norm: bool = False,
    est=None,
    solver_online: str = "",
    consistent: tuple = (False, "sdp", "nominal", DEFAULT_PRIOR_WEIGHT, None),
) -> IdentificationResult:
    """Rank check, solve, errors and the result, from the accumulated information."""
    r, nv, n = base.n_base, robot.nv, acc.n
    want_consistent, c_solver, c_prior, c_weight, c_bounds = consistent
    if want_consistent:
        if method not in ("ols", "wls"):
            raise InputError(f"consistent=True applies to ols and wls, got method {method!r}")
        check_consistent_options(c_solver, c_prior, c_weight)
    t0 = time.perf_counter()
    ra = analyze_information(acc.A, base.base_names, n_rows=acc.n_rows)
    timings["rank_analysis"] = time.perf_counter() - t0
    if ra.rank < r and not minimum_norm:
        raise RankDeficiencyError(
            ra.rank,
            r,
            ra.unidentifiable,
            subject=f"these data of {robot.name}",
            what="base parameter directions",
            hint="use a more exciting trajectory, or minimum_norm=True",
        )

    t0 = time.perf_counter()
    ls_method = "wls" if method == "wls" else "ols"
    ls: LeastSquaresSolution = solve_accumulator(
        acc,
        method=ls_method,
        names=base.base_names,
        minimum_norm=minimum_norm,
        rank_rtol=ra.tolerance,
    )
    estimate, covariance, sigma2 = ls.estimate, ls.covariance, ls.sigma2
    solver = ls.solver
    rss_j = ls.rss_per_joint
    noise_var = ls.noise_variance
    if est is not None:
        estimate = est.theta
        rss_j = acc.residual_sum_of_squares(estimate)
        sigma2 = float(rss_j.sum() / max(acc.n_rows - ls.rank, 1))
        covariance = ls.covariance * (sigma2 / ls.sigma2) if ls.sigma2 > 0 else ls.covariance * 0
        noise_var = rss_j / max(n - ls.rank / nv, 1e-300)
        solver = (
            f"{solver_online}, one pass over {n} samples; covariance sigma^2 (Y^T Y)^-1 "
            f"at the final estimate ({ls.solver})"
        )
    standard, warnings_ = None, []
    if want_consistent:  # beta = P theta of consistent standard parameters
        standard = consistent_estimate(
            robot,
            acc,
            base,
            ls,
            solver=c_solver,
            prior=c_prior,
            prior_weight=c_weight,
            bounds=c_bounds,
        )
        estimate = base.to_base(standard.values)
        rss_j = acc.residual_sum_of_squares(estimate)
        solver = (
            f"physically consistent ({c_solver}, {standard.status}, prior {c_prior}) on the "
            f"{ls_method.upper()} information; covariance of the {ls_method.upper()} fit "
            f"({ls.solver})"
        )
        timings["consistent"] = standard.time
        warnings_ += standard.warnings  # implausible bodies, named
        if not standard.physically_consistent:
            warnings_.append(
                "the consistent estimate fails the eigenvalue test: "
                + "; ".join(standard.consistency.messages())
            )
        if standard.fit_scale > 10.0:  # f_feas / r: a chi-square of <= r dof would be ~1
            warnings_.append(
                f"the residuals are not white noise: the best physical model's fit is "
                f"{standard.fit_scale:.3g} times its expected chi-square, so the reported "
                f"(OLS) standard deviations are likely about {np.sqrt(standard.fit_scale):.2g} "
                "times too small (correlated residuals, filtered torques, model error); the "
                "prior was weighed against the fit in these inflated units"
            )
    elif est is None:  # plain least squares: is its minimum-norm standard vector physical?
        standard = minimum_norm_standard(robot, base, estimate)
        msgs = standard.consistency.messages()
        if msgs:
            warnings_.append(
                f"plain least squares is not physical: its minimum-norm standard parameters "
                f"break {len(msgs)} condition(s): "
                + "; ".join(msgs[:4])
                + ("; ..." if len(msgs) > 4 else "")
                + " (consistent=True, --consistent, estimates a physical model)"
            )
    timings["solve"] = time.perf_counter() - t0
    zz_j = acc.zz_joint
    with np.errstate(divide="ignore", invalid="ignore"):
        train_j = np.sqrt(rss_j / zz_j)
    train = float(np.sqrt(rss_j.sum() / zz_j.sum())) if zz_j.sum() > 0 else float("nan")

    # the nominal (URDF) model's errors on the same data, from the same sums
    nominal_b = np.asarray(base.to_base(robot.nominal_parameters), dtype=float)
    rss_nom = acc.residual_sum_of_squares(nominal_b)
    with np.errstate(divide="ignore", invalid="ignore"):
        nom_j = np.sqrt(rss_nom / zz_j)
    nom = float(np.sqrt(rss_nom.sum() / zz_j.sum())) if zz_j.sum() > 0 else float("nan")
    val = val_j = nval = nval_j = None
    if validation is not None:
        t0 = time.perf_counter()
        (val, val_j), (nval, nval_j) = _validation_error(
            robot, validation, base.independent, estimate, chunk, nominal=nominal_b
        )
        timings["validation"] = time.perf_counter() - t0
    convergence = None
    if est is not None and est.record_every and zz_j.sum() > 0:
        h = est.history
        steps = np.arange(len(h.t)) * est.record_every  # samples seen at each record
        k = int(np.searchsorted(steps, 0.9 * n))
        k = min(k, len(h.t) - 1)
        delta = estimate - h.theta[k]  # change over the last 10 % of the samples
        moved = float(np.sqrt(max(delta @ acc.A @ delta, 0.0) / zz_j.sum()))
        convergence = {
            "window": 0.1,
            "from_sample": int(steps[k]),
            "prediction_change": moved,
            "parameter_change": float(
                np.linalg.norm(delta) / max(float(np.linalg.norm(estimate)), 1e-300)
            ),
        }
    timings["total"] = time.perf_counter() - t_start

    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        std_pct = 100.0 * std / np.abs(estimate)
    std_pct = np.where(np.isnan(std_pct), np.inf, std_pct)
    return IdentificationResult(
        method=method,
        robot_name=robot.name,
        names=list(base.base_names),
        expressions=list(base.expressions),
        estimate=estimate,
        std=std,
        std_percent=std_pct,
        covariance=covariance,
        sigma2=sigma2,
        noise_variance=noise_var,
        condition_number=float(ra.condition_number),
        rank_analysis=ra,
        relative_error=RelativeError(
            train,
            train_j,
            val,
            val_j,
            nominal_train=nom,
            nominal_train_per_joint=nom_j,
            nominal_validation=nval,
            nominal_validation_per_joint=nval_j,
        ),
        n_samples=n,
        timings=timings,
        solver=solver,
        base=base,
        dof_names=list(robot.dof_names),
        history=est.history if est is not None and est.record_every else None,
        standard=standard,
        warnings=warnings_,
        units=[robot.parameter_units[i] for i in base.independent],
        nominal=nominal_b,
        convergence=convergence,
    )


def identify_dataset(
    robot: Robot, dataset, *, ddq=None, validation=None, **kwargs
) -> IdentificationResult:
    """:func:`identify` on a :class:`~manip_id.datasets.Dataset` (``ddq`` from the dataset
    unless given); ``validation`` may be another Dataset. Other keywords as :func:`identify`.
    With ``model="energy"`` or ``"momentum"`` no ddq is needed and ``dt`` defaults to the
    dataset's mean sample time."""
    if kwargs.get("model", "dynamic") != "dynamic":
        if "dt" not in kwargs:
            kwargs["dt"] = float(np.mean(np.diff(dataset.t)))
        if validation is not None and hasattr(validation, "tau"):
            if validation.ddq is None:
                raise InputError("the validation dataset has no accelerations (ddq)")
            validation = (validation.q, validation.dq, validation.ddq, validation.tau)
        return identify(
            robot, dataset.q, dataset.dq, None, dataset.tau, validation=validation, **kwargs
        )
    acc_arr = dataset.ddq if ddq is None else ddq
    if acc_arr is None:
        raise InputError(
            "the dataset has no accelerations (ddq): estimate them first "
            "(manip_id.signals) or pass ddq="
        )
    if validation is not None and hasattr(validation, "tau"):
        if validation.ddq is None:
            raise InputError("the validation dataset has no accelerations (ddq)")
        validation = (validation.q, validation.dq, validation.ddq, validation.tau)
    return identify(
        robot, dataset.q, dataset.dq, acc_arr, dataset.tau, validation=validation, **kwargs
    )


def _file_blocks(robot: Robot, files, options, scans):
    """The files' blocks ``(q, dq, ddq, tau)`` as the fit sees them, read again (one pass)."""
    from .pipeline import iter_processed  # pipeline imports this module (a cycle)

    nq, nv = robot.nq, robot.nv
    for spec in files:
        _, blocks = iter_processed(robot, spec, options, (scans or {}).get(spec))
        for b in blocks:  # packed t | q | dq | tau | ddq
            q, dq = b[:, 1 : 1 + nq], b[:, 1 + nq : 1 + nq + nv]
            tau, ddq = b[:, 1 + nq + nv : 1 + nq + 2 * nv], b[:, 1 + nq + 2 * nv :]
            yield q, dq, ddq, tau


def identify_datasets(
    robot: Robot,
    files,
    *,
    validation=None,
    options=None,
    window=None,
    method: str = "ols",
    base: BaseParameters | None = None,
    chunk: int = DEFAULT_CHUNK,
    minimum_norm: bool = False,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    consistent: bool = False,
    solver: str = "sdp",
    prior: str = "nominal",
    prior_weight: float = DEFAULT_PRIOR_WEIGHT,
    bounds: BoundsOptions | None = None,
    scans: dict | None = None,
    scheduler=None,
) -> IdentificationResult:
    """Least squares from several log files, each read in chunks and preprocessed on its own.

    Parameters
    ----------
    robot: the robot (its joint terms decide the columns)
    files: file specs (:class:`~manip_id.datasets.FileSpec` or their texts
        ``PATH``, ``PATH@START:STOP`` [s from the file's first stamp],
        ``PATH@#A:#B`` [rows]): NPZ, CSV, ROS 2 bags, Panda log folders
    validation: file specs of validation data (same options), or None
    options: :class:`~manip_id.pipeline.PreprocessOptions` (filtering, torque
        scale, velocity deadband, bad rows); default all defaults
    window: window text applied to every file (training and validation) that has none
    method: "ols" or "wls"; consistent, solver, prior, prior_weight: as :func:`identify`
    workers: several files are accumulated in up to ``workers`` forked processes
    scans: FileSpec -> :class:`~manip_id.pipeline.FileScan` of files already scanned
    progress: called as ``progress(done, total)`` [samples of the training files]
    scheduler: a Dask scheduler spec or client: each file is one task on the cluster
        and the sums are added there (:func:`manip_id.fleet.identify_files`; ``files``
        then holds :class:`~manip_id.fleet.FileInfo`, the accumulations without sums)

    Returns
    -------
    The :class:`IdentificationResult` of the information summed over the
    files (``n_samples`` their total): with accelerations in the files, the
    estimate of their concatenation. ``relative_error.validation`` is pooled
    over the validation files (every sample weighs the same),
    ``validation_per_file`` gives each file's; both leave out the deadband's rows.
    ``files`` holds every file's :class:`~manip_id.pipeline.FileAccumulation`.
    """
    from dataclasses import replace

    from .pipeline import accumulate_files, merge_accumulations, validation_errors

    if scheduler is not None:
        from .fleet import identify_files

        return identify_files(
            robot,
            files,
            scheduler=scheduler,
            validation=validation,
            options=options,
            window=window,
            method=method,
            base=base,
            chunk=chunk,
            minimum_norm=minimum_norm,
            consistent=consistent,
            solver=solver,
            prior=prior,
            prior_weight=prior_weight,
            bounds=bounds,
        )

    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    _check_method(method, chunk, workers)
    if method not in ("ols", "wls"):
        raise InputError(f"identify_datasets solves least squares (ols, wls), got {method!r}")
    base = _resolve_base(robot, base, timings)
    ind = base.independent
    t0 = time.perf_counter()
    kw = dict(window=window, chunk=chunk, workers=workers, scans=scans)
    train = accumulate_files(robot, files, options, ind, progress=progress, **kw)
    valid = None
    if validation is not None:
        valid = accumulate_files(robot, validation, options, ind, **kw)
    timings["accumulate_wall"] = time.perf_counter() - t0
    for fa in train + (valid or []):
        for k, v in fa.timings.items():
            timings[k] = timings.get(k, 0.0) + float(v)
    acc = merge_accumulations(train)
    _check_equations(acc.n, robot.nv, base.n_base)
    result = _finish(
        robot,
        acc,
        base,
        method,
        timings,
        t_start,
        chunk=int(chunk),
        minimum_norm=minimum_norm,
        consistent=(consistent, solver, prior, prior_weight, bounds),
    )
    if window is None:  # an implausible fit: would a joint term the model lacks lower the error?
        result.warnings.extend(
            missing_term_warnings(
                robot,
                result.standard,
                _file_blocks(robot, files, options, scans),
                None if validation is None else _file_blocks(robot, validation, options, scans),
                ind,
                chunk,
            )
        )
    re = result.relative_error
    if valid is not None:
        t0 = time.perf_counter()
        v = validation_errors(valid, result.estimate, list(robot.dof_names))
        vn = validation_errors(valid, result.nominal, list(robot.dof_names))
        for entry, nominal_entry in zip(v["per_file"], vn["per_file"], strict=True):
            entry["nominal_error"] = nominal_entry["error"]
            entry["nominal_per_joint"] = nominal_entry["per_joint"]
        re = replace(
            re,
            validation=v["error"],
            validation_per_joint=v["per_joint"],
            validation_per_file=v["per_file"],
            nominal_validation=vn["error"],
            nominal_validation_per_joint=vn["per_joint"],
        )
        timings["validation"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    return replace(
        result, relative_error=re, timings=timings, files={"train": train, "validation": valid}
    )
