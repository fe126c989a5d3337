"""The result of an identification: estimate, uncertainty, errors; the schema read back.

:class:`IdentificationResult` is what every entry point returns (through
:func:`~manip_id.identification.solve`); :meth:`~IdentificationResult.to_dict` is the
one JSON schema (:mod:`manip_id.identification.document`), :func:`load_result` reads it
back, :meth:`~IdentificationResult.table` renders it as text. The relative torque error
is ``||tau - tau_hat|| / ||tau||`` over all stacked samples and joints, also per joint.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError, InputError, shorten
from ..estimators import OnlineHistory
from ..estimators.consistent import StandardEstimate
from ..identifiability import BaseParameters, RankAnalysis
from ..robot.model import Robot
from ..robot.regressor import DEFAULT_CHUNK, check_states, iter_regressor
from .document import OWN_KEYS, read_result_json, result_to_dict
from .document_text import result_text
from .nominal_check import WORSE_PREFIX
from .result_schema import check_covariance, check_result_document, rows_in_base_order


def _array(x, dtype=float):
    return np.asarray([np.nan if v is None else v for v in x], dtype=dtype)


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
    #: with a velocity deadband: the errors over the moving rows only (``|dq_j| >= eps``);
    #: ``train`` and ``validation`` are always over all rows
    train_moving: float | None = None
    validation_moving: float | None = None


@dataclass(frozen=True)
class IdentificationResult:
    """Identified base parameters, their uncertainty and how they were obtained.

    Attributes
    ----------
    method
        "ols", "wls", "rls" or "gradient"
    robot_name
        name of the robot
    names
        one name per base parameter (its independent column, ``R`` if regrouped)
    expressions
        each base parameter in standard parameter names
    estimate
        base parameters theta_b, shape (r,) [units of the independent columns]
    std
        standard deviations, shape (r,); std_percent: ``100 std / |estimate|`` [%]: the
        honest ones (``uncertainty["method"]``: "hac", which holds for correlated
        residuals, or "white"; :mod:`manip_id.estimators.uncertainty`)
    covariance
        shape (r, r): the covariance behind ``std``; for "white" ``sigma2 (Y_b^T
        Y_b)^-1`` (OLS, and RLS/gradient at their final estimate), ``(Y_b^T W Y_b)^-1``
        for WLS; for "hac" the sandwich of the block scores
    std_white
        the white-noise standard deviations, shape (r,) (None when not known)
    uncertainty
        how ``std`` was made: ``{method, requested, bandwidth, inflation, n_blocks,
        block_samples, reason}`` (inflation: median ``std / std_white``)
    sigma2
        residual variance [(N m)^2] (weighted, about 1, for WLS)
    noise_variance
        per-joint residual variance, shape (nv,) [(N m)^2]
    condition_number
        2-norm condition number of the base regressor on these data
    rank_analysis
        what these data excite (analysis of the accumulated information)
    relative_error
        train / validation relative torque errors
    n_samples
        number of training samples N
    timings
        seconds per stage
    solver
        how the estimate was computed, including any fallback
    base
        the base parametrization used
    dof_names
        joint names, length nv
    history
        record of the online law (``rls``/``gradient``), else None
    standard
        the standard parameters with their eigenvalue test
        (:class:`~manip_id.estimators.consistent.StandardEstimate`): the consistent
        estimate (``consistent=True``; then ``estimate`` holds the base parameters it
        implies, ``P theta``), or for plain OLS/WLS the minimum-norm standard vector
    warnings
        e.g. the physical-consistency violations of a plain least-squares fit
    per_file
        each file's own estimate (:class:`manip_id.identification.fleet.FileEstimate`) when
        :func:`manip_id.identification.fleet.identify` was asked ``per_file=True``, else None
    model
        "dynamic" (tau = Y(q, dq, ddq) theta), "energy" or "momentum"
        (:mod:`manip_id.models`); the training errors, ``sigma2`` and
        ``noise_variance`` are those of the model's own equation (per output of
        ``output_names``), the validation error is always the torque error
    output_names
        names of the model's outputs (default ``dof_names``; "energy"
        for the energy model's one scalar row per window)
    files
        :func:`identify` only: ``{"train": [...], "validation": [...]}``,
        the :class:`~manip_id.identification.FileAccumulation` of each file (its
        data-quality summary, samples, rows left out by the deadband)
    rollout
        a file run's rollout validation (``FileOptions(rollout=RolloutOptions(...))``):
        the :class:`~manip_id.identification.RolloutReport` with its traces (for the
        report's figure); its figures are ``context["rollout"]`` (the JSON's ``rollout``)
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
    #: the errors against the raw (unfiltered) torques, when they could be read again
    raw_error: RelativeError | None = None
    std_white: np.ndarray | None = None
    uncertainty: dict | None = None
    #: the white-noise covariance beside the honest ``covariance``, shape (r, r)
    covariance_white: np.ndarray | None = None
    rollout: Any = None  # RolloutReport (not imported: rollout imports this layer)

    def test_covariance(self) -> np.ndarray:
        """The covariance for tests on the base parameters (drift, monitor bounds), shape
        (r, r): the white-noise correlations scaled to the honest standard deviations,
        ``D C_white D`` with ``D = diag(max(1, std / std_white))``.

        The honest (autocorrelation-consistent) covariance comes from some 60-130 block
        scores: its diagonal is good, but as a full matrix with r near the number of blocks
        it is ill-conditioned, and a chi-square ``d^T S^-1 d`` grows far beyond its
        distribution. The white-noise matrix holds the correlations the regressor implies;
        the honest std scale them, never below the white ones (an inflation under 1 is the
        block estimate's own noise, about 10 % on a 10 s file). Without the white
        covariance (an older JSON) it is ``covariance`` as given.
        """
        cov = np.asarray(self.covariance, float)
        if self.covariance_white is None or self.std_white is None:
            return cov
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        sw = np.asarray(self.std_white, float)
        scale = np.maximum(np.divide(std, sw, out=np.ones_like(std), where=sw > 0), 1.0)
        return np.asarray(self.covariance_white, float) * np.outer(scale, scale)

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

    def predict(
        self, robot: Robot, q, dq, ddq, *, chunk: int = DEFAULT_CHUNK, temp=None
    ) -> np.ndarray:
        """Predicted torques ``Y_b(q, dq, ddq) theta_b``, shape (N, nv) [N m or N].

        ``q`` (N, nq), ``dq`` and ``ddq`` (N, nv); streamed chunk by chunk; ``temp`` the
        temperature [degC or K] of the ``temperature`` law, (N, nv) or (N, 1).
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
        if temp is not None and not batched:
            temp = np.asarray(temp, dtype=float)[None]
        for c in iter_regressor(robot, q, dq, ddq, chunk=chunk, temp=temp):
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
        :func:`load_result`); see :mod:`manip_id.identification.document`.

        poorly_identified: std above this [%] flags a base parameter "poorly identified"
        (default 10); condition_limit: a condition number above it is a warning (default
        100); convergence_limit: an online estimate whose prediction moved by more than
        this fraction of the torque over the last 10 % of the data is "not converged"
        (default 0.01).
        """
        return result_to_dict(
            self,
            poorly_identified=poorly_identified,
            condition_limit=condition_limit,
            convergence_limit=convergence_limit,
        )

    def table(self, max_rows: int | None = None) -> str:
        """The result as text (:func:`~manip_id.identification.document_text.result_text` of
        :meth:`to_dict`): headline figures, errors per joint, parameters, warnings."""
        return result_text(self.to_dict(), max_rows=max_rows)


def errors_from_dict(e: dict) -> RelativeError:
    """A :class:`RelativeError` from its schema section (:func:`document.errors_to_dict`)."""

    def arr(key):
        return None if e.get(key) is None else _array(e[key])

    return RelativeError(
        train=np.nan if e.get("train") is None else float(e["train"]),
        train_per_joint=arr("train_per_joint"),
        validation=e.get("validation"),
        validation_per_joint=arr("per_joint_validation"),
        validation_per_file=e.get("validation_per_file"),
        nominal_train=e.get("nominal_train"),
        nominal_train_per_joint=arr("nominal_train_per_joint"),
        nominal_validation=e.get("nominal_validation"),
        nominal_validation_per_joint=arr("nominal_per_joint_validation"),
        train_moving=e.get("train_moving"),
        validation_moving=e.get("validation_moving"),
    )


#: The keys every saved result has (:func:`result_from_dict` refuses a document without one).
REQUIRED_KEYS = (
    "method",
    "robot",
    "base_parameters",
    "relative_error",
    "base",
    "rank_analysis",
    "covariance",
)


def result_from_dict(doc: dict) -> IdentificationResult:
    """An :class:`~manip_id.identification.IdentificationResult` from :func:`result_to_dict`'s
    dictionary. What the schema does not model (standard parameters, files, per-file
    results, the caller's keys) is kept in ``context`` and written back by ``to_dict``."""
    if not isinstance(doc, dict):
        raise DataError(f"an identification result is a JSON object, got {type(doc).__name__}")
    check_result_document(doc)
    missing = [k for k in REQUIRED_KEYS if k not in doc]
    if missing:
        raise DataError(
            f"not an identification result of this schema: missing {missing} (write it with "
            "manip-id identify --json or IdentificationResult.to_dict())"
        )
    try:
        rows = rows_in_base_order(doc)
        doc = {**doc, "base_parameters": rows}
        b = doc["base"]
        names = [str(r["name"]) for r in rows]
        base = BaseParameters(
            independent=np.asarray(b["independent"], dtype=np.intp),
            dependent=np.asarray(b["dependent"], dtype=np.intp),
            K=np.asarray(b["K"], dtype=float).reshape(len(rows), len(b["dependent"])),
            names=list(b["names"]),
            base_names=names,
            expressions=[str(r["expression"]) for r in rows],
        )
        estimate = _array([r["value"] for r in rows])
        std = _array([r["std"] for r in rows])
        std_pct = _array([np.inf if r["std_percent"] is None else r["std_percent"] for r in rows])
        cov = _array([v for row in doc["covariance"] for v in row]).reshape(len(rows), len(rows))
        check_covariance(cov, "covariance")
        ra = _rank_from_dict(doc, base, names)
        joints = list(doc.get("joints", []))
        outputs = list(doc.get("outputs", joints))
        re = errors_from_dict(doc["relative_error"])
        raw = doc.get("relative_error_raw")
        nominal = [r.get("nominal") for r in rows]
        own_warnings = _recomputed_warnings(doc)
        context = {k: v for k, v in doc.items() if k not in OWN_KEYS}
        context["thresholds"] = doc.get("thresholds") or {}
        context["warnings"] = [w for w in doc.get("warnings", []) if w not in own_warnings]
        return IdentificationResult(
            method=str(doc["method"]),
            robot_name=str(doc["robot"]),
            names=names,
            expressions=list(base.expressions),
            estimate=estimate,
            std=std,
            std_percent=std_pct,
            covariance=cov,
            sigma2=np.nan if doc.get("sigma2") is None else float(doc["sigma2"]),
            noise_variance=_array(list(doc.get("noise_variance", {}).values())),
            condition_number=ra.condition_number,
            rank_analysis=ra,
            relative_error=re,
            n_samples=int(doc["n_samples"]),
            timings={k: float(v) for k, v in doc.get("timings", {}).items()},
            solver=str(doc.get("solver", "")),
            base=base,
            dof_names=joints,
            model=str(doc.get("model", "dynamic")),
            output_names=outputs if outputs != joints else [],
            units=[str(r.get("unit", "")) for r in rows],
            nominal=None if any(x is None for x in nominal) else np.asarray(nominal, dtype=float),
            convergence=doc.get("convergence"),
            context=context,
            raw_error=None if not raw else errors_from_dict(raw),
            std_white=_std_white(rows),
            uncertainty=doc.get("uncertainty"),
            covariance_white=_matrix(doc.get("covariance_white"), len(rows)),
        )
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise DataError(f"a malformed identification result: {type(exc).__name__}: {exc}") from exc


def _matrix(value, n: int) -> np.ndarray | None:
    """An (n, n) matrix of the JSON (rows of numbers), or None when absent."""
    if value is None:
        return None
    return _array([v for row in value for v in row]).reshape(n, n)


def _std_white(rows: list[dict]) -> np.ndarray | None:
    """The white-noise std of the parameter rows (None in documents written without it)."""
    if rows and all("std_white" in r for r in rows):
        return _array([r["std_white"] for r in rows])
    return None


def _rank_from_dict(doc: dict, base: BaseParameters, names: list[str]) -> RankAnalysis:
    """The :class:`RankAnalysis` of a saved result (its ``rank_analysis`` section)."""
    rows = doc["base_parameters"]
    rd = doc["rank_analysis"]
    ns = np.asarray(rd["null_space"], dtype=float).reshape(len(rows), -1)
    ra = RankAnalysis(
        names=names,
        n_parameters=len(rows),
        n_rows=int(rd["n_rows"]),
        rank=int(doc["rank"]),
        tolerance=float(rd["tolerance"]),
        singular_values=_array(rd["singular_values"]),
        singular_values_scaled=_array(rd["singular_values_scaled"]),
        condition_number=np.inf
        if doc["condition_number"] is None
        else float(doc["condition_number"]),
        condition_number_scaled=np.inf
        if rd["condition_number_scaled"] is None
        else float(rd["condition_number_scaled"]),
        base=base,
        null_space=ns,
        unidentifiable=list(rd["unidentifiable"]),
        unexcited=list(rd["unexcited"]),
        notes=list(rd["notes"]),
        source=str(rd["source"]),
    )
    return ra


def _recomputed_warnings(doc: dict) -> set[str]:
    """The warnings :func:`result_to_dict` derives itself (recomputed on writing again)."""
    starts = ("non-physical values: ", "the condition number ", WORSE_PREFIX)
    undetermined = "base parameter(s) not determined by these data"
    return {
        w
        for w in doc.get("warnings", [])
        if w.startswith(starts)
        or (w.startswith("the ") and "has not converged" in w)
        or undetermined in w
    }


def load_result(path) -> IdentificationResult:
    """Read a saved identification result (``manip-id identify --json``, a report's
    result.json) back into an :class:`~manip_id.identification.IdentificationResult`.

    Raises :class:`~manip_id.errors.DataError` for a missing, unreadable or foreign file,
    :class:`~manip_id.errors.InputError` for a ``path`` that is no path.
    """
    if not isinstance(path, str | os.PathLike) or not str(path):
        raise InputError(f"load_result takes the path of a result file, got {path!r}")
    path = Path(path)
    doc = read_result_json(path)
    command = doc.get("command")
    if isinstance(command, str) and command != "identify":  # payload, drive-gains
        raise DataError(
            f"{path} is the JSON of manip-id {shorten(command)}, not an identification result"
        )
    try:
        return result_from_dict(doc)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from exc


__all__ = [
    "IdentificationResult",
    "RelativeError",
    "errors_from_dict",
    "load_result",
    "result_from_dict",
]
