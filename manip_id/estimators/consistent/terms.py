"""Joint terms a model lacks: would armature or friction lower the error of the fit?

An implausible consistent estimate (a link of 3x its nominal mass) is often the rigid
bodies standing in for a joint term the model does not have: a rotor inertia
(armature, column ``ddq_j``) looks like link inertia, friction like gravity. For each
term of :data:`CANDIDATES` the robot does not model, the least-squares fit of the
robot's base columns ``Y_b`` is compared with the fit of ``[Y_b, C_t]``, ``C_t`` the
term's columns (row ``j``: ``c_t(q_j, dq_j, ddq_j)``, :mod:`manip_id.robot.parameters`),
on the same accumulated sums (one accumulator over ``[Y_b, C]`` for every candidate
at once; a candidate fit is the sub-problem of its columns)::

    e = sqrt( sum_j RSS_j / sum_j ZZ_j )          (manip_id.metrics.relative_error)

on the training sums and, when given, on validation sums accumulated the same way.
A term is suggested when it lowers the error (validation when there is some, else
training) by at least :data:`MIN_GAIN` of it. Only least squares is compared: whether
the extended model's consistent estimate is plausible needs its own solve (run it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...metrics import relative_error
from ...robot.parameters import JOINT_TERM
from ..accumulator import InformationAccumulator
from ..batch import solve_accumulator

#: Terms a model may lack: (term, what it is, the command-line option that adds it).
CANDIDATES: tuple[tuple[str, str, str], ...] = (
    ("Ia", "armature", "--armature"),
    ("fv", "viscous friction", "--friction viscous"),
    ("fc", "Coulomb friction", "--friction coulomb"),
    ("fo", "a torque offset", "--friction offset"),
)
#: Relative decrease of the error for which a missing term is suggested.
MIN_GAIN = 0.05


@dataclass(frozen=True)
class TermComparison:
    """The fit with and without one joint term, on the same sums.

    Attributes
    ----------
    term, what, option
        str
        The term (``"Ia"``), its name and the option that adds it.
    train_without, train_with
        float
        Training relative error without and with the term [-].
    validation_without, validation_with
        float or None
        The same on the validation data (None without any).
    """

    term: str
    what: str
    option: str
    train_without: float
    train_with: float
    validation_without: float | None = None
    validation_with: float | None = None

    @property
    def on(self) -> str:
        """Which error decides: "validation" when there is one, else "training"."""
        return "training" if self.validation_without is None else "validation"

    @property
    def deciding(self) -> tuple[float, float]:
        """``(without, with)``: the validation errors when there are some, else training."""
        if self.validation_without is None or self.validation_with is None:
            return self.train_without, self.train_with
        return self.validation_without, self.validation_with

    @property
    def lowers(self) -> bool:
        """Whether the term lowers the deciding error by at least :data:`MIN_GAIN` of it."""
        without, with_ = self.deciding
        return bool(with_ <= (1.0 - MIN_GAIN) * without)

    def message(self) -> str:
        """``"--armature lowers the validation error from 0.82 % to 0.61 %"``."""
        a, b = self.deciding
        return (
            f"{self.option} ({self.what}) lowers the {self.on} error from {100 * a:.3g} % to "
            f"{100 * b:.3g} %"
        )

    def to_dict(self) -> dict:
        return {
            "term": self.term,
            "option": self.option,
            "train_without": self.train_without,
            "train_with": self.train_with,
            "validation_without": self.validation_without,
            "validation_with": self.validation_with,
            "lowers": self.lowers,
        }


def missing_terms(robot) -> list[tuple[str, str, str]]:
    """The :data:`CANDIDATES` the robot does not model."""
    enabled = set(robot.terms.enabled)
    return [c for c in CANDIDATES if c[0] not in enabled]


def candidate_rows(terms, q, dq, ddq) -> np.ndarray:
    """Columns of the joint ``terms`` (names), shape (n, nv, len(terms) nv): term ``t`` of
    joint ``j`` is column ``t nv + j``, non-zero on row ``j`` only."""
    dq = np.asarray(dq, dtype=float)
    n, nv = dq.shape
    out = np.zeros((n, nv, len(terms) * nv))
    diag = np.arange(nv)
    for k, t in enumerate(terms):
        out[:, diag, k * nv + diag] = JOINT_TERM[t].column(q, dq, ddq)
    return out


def accumulate_candidates(robot, blocks, ind, terms, chunk: int) -> InformationAccumulator:
    """One accumulator over ``[Y_b, C]`` (``Y_b`` the regressor columns ``ind``, ``C`` the
    candidate terms' columns) of blocks ``(q, dq, ddq, tau[, None, temp])`` (one pass)."""
    ind = np.asarray(ind, dtype=np.intp)
    acc = InformationAccumulator(ind.size + len(terms) * robot.nv, robot.nv)
    for block in blocks:
        q, dq, ddq, tau = block[:4]
        temp = block[5] if len(block) > 5 else None  # (the temperature law's)
        for c in robot.evaluator.iter_regressor(q, dq, ddq, int(chunk), temp):
            s = slice(c.start, c.stop)
            C = candidate_rows(terms, None if q is None else q[s], dq[s], ddq[s])
            acc.add(np.concatenate([c.Y[:, :, ind], C], axis=2), tau[s], check=False)
    return acc


def compare_terms(
    robot, train: InformationAccumulator, n_base: int, validation=None
) -> list[TermComparison]:
    """Each missing term's fit against the robot's own, on accumulators over ``[Y_b, C]``
    (:func:`accumulate_candidates` with the :func:`missing_terms`, in their order)."""
    cands = missing_terms(robot)
    nv = robot.nv
    if train.p != n_base + len(cands) * nv:
        raise InputError(
            f"the accumulator has {train.p} columns, expected {n_base} base + "
            f"{len(cands)} x {nv} candidate columns"
        )
    own = np.arange(n_base)
    x0 = _fit(train, own)
    out = []
    for k, (term, what, option) in enumerate(cands):
        cols = np.r_[own, n_base + k * nv + np.arange(nv)]
        x = _fit(train, cols)
        v0 = v1 = None
        if validation is not None:
            v0, v1 = _error(validation, x0), _error(validation, x)
        out.append(TermComparison(term, what, option, _error(train, x0), _error(train, x), v0, v1))
    return out


def _fit(acc: InformationAccumulator, cols: np.ndarray) -> np.ndarray:
    """Least squares on the columns ``cols`` of ``acc`` (minimum norm where they are
    dependent), as a full-length vector (zero elsewhere)."""
    sub = InformationAccumulator(cols.size, acc.nv).add_sums(
        [a[np.ix_(cols, cols)] for a in acc.A_joint],
        [b[cols] for b in acc.b_joint],
        acc.zz_joint,
        acc.n,
    )
    x = np.zeros(acc.p)
    x[cols] = solve_accumulator(sub, minimum_norm=True).estimate
    return x


def _error(acc: InformationAccumulator, x: np.ndarray) -> float:
    return float(relative_error(acc.residual_sum_of_squares(x), acc.zz_joint).total)


def term_warnings(comparisons: list[TermComparison]) -> list[str]:
    """The suggestion, one warning, for the terms that lower the error (none otherwise)."""
    good = [c for c in comparisons if c.lowers]
    if not good:
        return []
    return [
        "the implausible links may stand in for joint terms the model lacks: "
        + "; ".join(c.message() for c in good)
        + " (least squares on the same data; identify again with the option)"
    ]


def missing_term_warnings(robot, standard, train_blocks, validation_blocks, ind, chunk: int):
    """For an implausible consistent estimate (``standard``, a
    :class:`~manip_id.estimators.consistent.StandardEstimate`) of a robot that lacks some
    of the :data:`CANDIDATES`: the terms that lower the error, as one warning; else none.

    One more pass over the blocks ``(q, dq, ddq, tau)`` (train, and validation when
    given) accumulates ``[Y_b, C]``; :func:`compare_terms` decides on those sums.
    """
    pl = getattr(standard, "plausibility", None)
    cands = missing_terms(robot)
    if pl is None or pl.plausible or not cands:
        return []
    terms = [c[0] for c in cands]
    train = accumulate_candidates(robot, train_blocks, ind, terms, chunk)
    valid = None
    if validation_blocks:
        valid = accumulate_candidates(robot, validation_blocks, ind, terms, chunk)
    return term_warnings(compare_terms(robot, train, len(ind), valid))
