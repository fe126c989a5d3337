"""Drift: which robot (which log) has dynamics beyond the noise of a reference identification.

Each file (or each group of files: one robot's logs) is identified on its own with the
reference's base parametrization (on the fleet path, one task per file:
:func:`manip_id.identification.fleet.identify`), and
its base parameters ``theta_f`` are compared with the reference's ``theta_r``, both with
their covariances (independent data)::

    d = theta_f - theta_r,   S = Sigma_f + Sigma_r
    chi2 = d^T S^+ d  on  rank(S)  degrees of freedom,   p = P(chi2_rank > chi2)

and, per joint-level term that is a base parameter of its own (viscous and Coulomb friction,
offset, armature, spring), ``z = d_i / sqrt(S_ii)``, two-sided ``p_i = 2 Phi(-|z|)``, with
the relative change ``d_i / theta_r,i``. A file is ``changed`` when ``p < alpha``; a term
when ``p_i < alpha / n_terms`` (Bonferroni over the file's terms, so that an unchanged file
flags some term with probability at most ``alpha``).

The covariances are :func:`test_covariance` of the results: the honest standard deviations
(autocorrelation-consistent, so that filtered real data do not flag every file) with the
white-noise correlations. On data whose noise is of different size per joint, identify
with ``method="wls"``: the pooled OLS variance misstates each parameter's.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import chdtrc, ndtr

from ..errors import InputError, ModelMismatchError, RankDeficiencyError
from ..identification import (
    FileOptions,
    PartitionOptions,
    PreprocessOptions,
    RunOptions,
    identify,
)
from ..identification.document import single_standard
from ..robot.model import Robot, available_robots
from ..robot.parameters import JOINT_TERM
from . import covariance_kind

#: Default significance level of the tests.
DEFAULT_ALPHA = 0.05
#: Eigenvalues of ``S`` below this fraction of the largest are left out of the chi-square.
RANK_TOLERANCE = 1e-10


@dataclass(frozen=True)
class TermDrift:
    """One joint-level term of one file against the reference.

    name: the standard parameter (``panda_joint3.fv``); text: ``"panda_joint3 viscous
    friction"``; reference, value: the two estimates; change: ``(value - reference) /
    |reference|`` (None when the reference is 0); p_value: two-sided; changed: below the
    Bonferroni level.
    """

    name: str
    text: str
    reference: float
    value: float
    change: float | None
    p_value: float
    changed: bool

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "text": self.text,
            "reference": self.reference,
            "value": self.value,
            "change": self.change,
            "p_value": self.p_value,
            "changed": self.changed,
        }

    def sentence(self) -> str:
        """``"panda_joint3 viscous friction +31 % (p < 1e-06)"``."""
        pct = "n/a" if self.change is None else f"{100 * self.change:+.0f} %"
        p = self.p_value
        ptxt = "p < 1e-06" if p < 1e-6 else f"p = {p:.2g}"
        return f"{self.text} {pct} ({ptxt})"


@dataclass(frozen=True)
class FileDrift:
    """One file against the reference: ``chi2`` on ``dof`` degrees of freedom, ``p_value``,
    ``changed``, its ``terms``; ``error`` when the file alone could not be identified."""

    file: str
    n_samples: int
    chi2: float | None
    dof: int
    p_value: float | None
    changed: bool | None
    terms: list[TermDrift] = field(default_factory=list)
    error: str | None = None

    def to_dict(self) -> dict:
        return {
            "file": self.file,
            "n_samples": self.n_samples,
            "chi2": self.chi2,
            "dof": self.dof,
            "p_value": self.p_value,
            "changed": self.changed,
            "terms": [t.to_dict() for t in self.terms],
            "error": self.error,
        }


@dataclass(frozen=True)
class DriftReport:
    """Every file's :class:`FileDrift`, the level ``alpha`` and the covariance kind."""

    files: list[FileDrift]
    alpha: float
    covariance_kind: str
    reference: str = ""

    def to_dict(self) -> dict:
        """The ``drift`` object of the JSON: ``{alpha, covariance_kind, reference, files}``."""
        return {
            "alpha": self.alpha,
            "covariance_kind": self.covariance_kind,
            "reference": self.reference,
            "files": [f.to_dict() for f in self.files],
        }

    def lines(self) -> list[str]:
        """A readable summary, one line per file then one per changed term."""
        out = []
        for f in self.files:
            if f.error is not None:
                out.append(f"{f.file}: not identified alone ({f.error})")
                continue
            verdict = "CHANGED" if f.changed else "unchanged"
            out.append(f"{f.file}: {verdict} (chi2 {f.chi2:.4g} on {f.dof}, p = {f.p_value:.3g})")
            out += [f"  {t.sentence()}" for t in f.terms if t.changed]
        return out


def _term_text(name: str) -> str | None:
    joint, _, short = name.rpartition(".")
    term = JOINT_TERM.get(short)
    if term is None:
        return None
    what = f"{term.flag} friction" if short in ("fv", "fc") else term.flag
    return f"{joint} {what}"


def _check_same_base(reference, estimate) -> None:
    rb, eb = reference.base, estimate.base
    same = list(rb.names) == list(eb.names) and np.array_equal(rb.independent, eb.independent)
    if not same:
        raise ModelMismatchError(
            "the compared base parameters",
            f"the reference's {len(rb.independent)} ({reference.robot_name!r})",
            f"{len(eb.independent)} of another parametrization ({estimate.robot_name!r})",
        )


def test_covariance(result) -> np.ndarray:
    """The covariance of ``result`` the tests use (:meth:`IdentificationResult.test_covariance`;
    a result object without that method: its ``covariance``)."""
    method = getattr(result, "test_covariance", None)
    return np.asarray(method() if callable(method) else result.covariance, float)


def compare(reference, estimate, *, alpha: float = DEFAULT_ALPHA, file: str = "") -> FileDrift:
    """One estimate against the reference (module docstring); both
    :class:`~manip_id.identification.IdentificationResult` s of the same base parameters."""
    _check_same_base(reference, estimate)
    d = np.asarray(estimate.estimate, float) - np.asarray(reference.estimate, float)
    S = test_covariance(reference) + test_covariance(estimate)
    if not (np.isfinite(S).all() and np.isfinite(d).all()):
        raise InputError(f"{file or 'the estimate'}: non-finite estimates or covariances")
    w, V = np.linalg.eigh(0.5 * (S + S.T))
    keep = w > RANK_TOLERANCE * max(float(w.max()), 0.0)
    proj = V[:, keep].T @ d
    chi2 = float(np.sum(proj**2 / w[keep]))
    dof = int(keep.sum())
    p = float(chdtrc(dof, chi2))
    base = reference.base
    rows = [(i, n) for i in range(len(d)) if (n := single_standard(base, i)) and _term_text(n)]
    level = alpha / max(len(rows), 1)
    terms = []
    for i, name in rows:
        sd = float(np.sqrt(max(S[i, i], 0.0)))
        pi = float(2.0 * ndtr(-abs(d[i]) / sd)) if sd > 0 else (0.0 if d[i] else 1.0)
        ref = float(reference.estimate[i])
        terms.append(
            TermDrift(
                name=name,
                text=_term_text(name) or name,
                reference=ref,
                value=float(estimate.estimate[i]),
                change=None if ref == 0 else float(d[i] / abs(ref)),
                p_value=pi,
                changed=bool(pi < level),
            )
        )
    return FileDrift(
        file=file,
        n_samples=int(estimate.n_samples),
        chi2=chi2,
        dof=dof,
        p_value=p,
        changed=bool(p < alpha),
        terms=terms,
    )


def drift_files(
    robot: Robot,
    reference,
    files: Sequence[str | os.PathLike] | Mapping[str, Sequence[str | os.PathLike]],
    *,
    alpha: float = DEFAULT_ALPHA,
    scheduler=None,
    options: PreprocessOptions | Mapping | None = None,
    window=None,
) -> DriftReport:
    """Test every file (or every group of files) against the reference (module docstring).

    Parameters
    ----------
    robot: the robot, with the reference's joint terms
    reference: the reference :class:`~manip_id.identification.IdentificationResult`
        (e.g. :func:`~manip_id.identification.load_result` of ``manip-id identify --json``)
    files: data files (file specs as :func:`~manip_id.identification.fleet.identify` takes them),
        each tested alone; or a mapping ``group -> files`` (e.g. one robot's logs), each
        group identified from all its files and tested as one
    alpha: significance level in (0, 1)
    scheduler, options, window: as :func:`~manip_id.identification.fleet.identify` (one task per
        file; with groups, one map-reduce per group: give a running scheduler or a
        ``distributed.Client`` rather than ``"local"``, which starts a cluster per group)

    Returns
    -------
    :class:`DriftReport`; a file (group) that cannot be identified alone has ``error`` set.
    """
    if not 0.0 < float(alpha) < 1.0:
        raise InputError(f"alpha must be a level in (0, 1), got {alpha}")
    if reference.robot_name != robot.name and {reference.robot_name, robot.name} <= set(
        available_robots()
    ):  # two robots known by name (a URDF loaded by path is checked by its parameters)
        raise ModelMismatchError(
            "the reference", f"a reference of {robot.name!r}", f"one of {reference.robot_name!r}"
        )
    if list(reference.base.names) != list(robot.parameter_names):
        raise ModelMismatchError(
            "the reference's parameters",
            f"the {robot.n_parameters} parameters of {robot.name!r}",
            f"{len(reference.base.names)} parameters of {reference.robot_name!r}",
        )
    method = reference.method if reference.method in ("ols", "wls") else "ols"
    kw = dict(
        run=RunOptions(scheduler=scheduler),
        method=method,
        base=reference.base,
    )
    pre = (
        options if isinstance(options, PreprocessOptions) else PreprocessOptions(**(options or {}))
    )
    plain = FileOptions(preprocess=pre, window=window, audit=False)
    out = []
    if isinstance(files, Mapping):
        for group, members in files.items():
            try:
                res = identify(robot, list(members), files=plain, **kw)
            except RankDeficiencyError as exc:
                out.append(FileDrift(str(group), 0, None, 0, None, None, [], str(exc)))
                continue
            out.append(compare(reference, res, alpha=float(alpha), file=str(group)))
    else:
        pooled = identify(
            robot,
            list(files),
            files=replace(plain, partition=PartitionOptions(per_file=True)),
            **kw,
        )
        for fe in pooled.per_file or []:
            if fe.result is None:
                out.append(FileDrift(fe.path, int(fe.n_samples), None, 0, None, None, [], fe.error))
            else:
                out.append(compare(reference, fe.result, alpha=float(alpha), file=fe.path))
    return DriftReport(files=out, alpha=float(alpha), covariance_kind=covariance_kind(reference))
