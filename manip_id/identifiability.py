"""Identifiability: rank, base parameters, unidentifiable and unexcited directions.

The regressor ``Y`` (stacked, shape (M, p)) maps parameters to torques,
``tau = Y theta``. What any data can identify is its row space; what no data
of this robot can identify is the null space of the *structural* regressor
(Y stacked over generic states). Every quantity here depends on ``Y`` only
through its Gram matrix ``A = Y^T Y`` (the information matrix), so the
analysis runs on any factor ``R`` with ``R^T R = A``: a ``(p, p)`` triangular
factor accumulated chunk by chunk (``R <- qr([R; Y_chunk])``), never the
stacked ``Y`` of a million samples.

Column scaling. Parameters have different units, so rank decisions are made on
the column-scaled regressor ``Y_s = Y S^-1``, ``S = diag(||y_j||)``; a column
with ``||y_j|| <= tol * max_k ||y_k||`` counts as zero (the parameter never
enters the data).

Tolerance ``tol`` (relative, dimensionless). The numerical rank is the number
of singular values of ``Y_s`` above ``tol * sigma_max(Y_s)``. Default for a
regressor or a robot: ``max(max(M, p) * eps, 1e-8)`` (:func:`default_tolerance`;
``eps`` = 2.2e-16). The round-off part is ``numpy.linalg.matrix_rank``'s; the
floor :data:`TOLERANCE_FLOOR` = 1e-8 catches couplings that exist only through
rounded numbers of a URDF (``rpy="1.5708"`` for pi/2, offsets of 1e-7 m): on
kinova and bravo7 they give columns of relative size 1e-7..1e-10 that column
scaling would otherwise promote to "identifiable" parameters no data could
resolve (a scaled condition number of 1e8 leaves no digit of a double). For an
information matrix the default is ``p * sqrt(eps)`` (1e-6 for p = 70): forming
``Y^T Y`` squares the condition number, so singular values below about
``sqrt(eps) * sigma_max`` are lost in round-off.

Base parameters (Gautier's QR method). The columns of ``Y_s`` are processed in
parameter order with a Gram-Schmidt QR; a column whose diagonal element
``|R_jj|`` (its distance to the span of the columns kept so far) is at most
``tol * sigma_max`` is pivoted to the end: it is *dependent*. The kept columns
are the *independent* ones, ``Y = [Y_1 Y_2] P``, and ``Y_2 = Y_1 K`` with
``K = R_11^-1 R_12``, so::

    Y theta = Y_1 (theta_1 + K theta_2) = Y_1 theta_base

Keeping the earliest independent columns is deterministic (no ties) and
regroups later bodies' parameters into earlier ones, the way the symbolic
rules do (``panda_joint2.Izz + 0.0841*panda_joint3.m``). Should this ordered
selection disagree with the SVD rank, the first ``rank`` pivots of LAPACK's
column-pivoted QR (``dgeqp3``, first maximum wins ties) are used instead.

Unidentifiable directions: the columns of ``N = P^T [-K; I]``, one per
dependent parameter: moving ``theta`` along ``e_d - K[:, d] theta_1`` leaves
every torque unchanged. This basis is sparse and readable by construction.

Clean-up. A scaled regrouping coefficient ``|K_id| ||y_d|| / ||y_i||`` below
:data:`ROUNDOFF_THRESHOLD` (1e-10) is round-off of the solve and is set to zero
in ``K``; expressions also drop terms below :data:`COEFFICIENT_THRESHOLD`
(1e-6: such couplings come from URDF angles like ``1.5708`` for pi/2) and print
four significant digits. ``K`` and ``null_space`` keep those small terms, so
``Y @ null_space`` vanishes to round-off.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from ._checks import as_float_array
from .errors import InputError, RankDeficiencyError

#: Scaled coefficients below this are dropped from the printed expressions (K keeps them).
COEFFICIENT_THRESHOLD = 1e-6
#: Scaled coefficients below this are round-off of the least-squares solve: zeroed in K.
ROUNDOFF_THRESHOLD = 1e-10
#: Relative singular value of the scaled base regressor below which a structurally
#: identifiable direction counts as not excited by the data (unless ``tolerance`` is larger).
EXCITATION_TOLERANCE = 1e-6
#: States drawn for a structural analysis: at least this many ...
MIN_SAMPLES = 100
#: ... and at least this many stacked rows per parameter.
ROWS_PER_PARAMETER = 20
#: Smallest default rank tolerance (relative, on the column-scaled regressor).
TOLERANCE_FLOOR = 1e-8
_EPS = float(np.finfo(float).eps)
_CHUNK = 256


def default_tolerance(n_rows: int, n_parameters: int) -> float:
    """Default rank tolerance of a regressor: ``max(max(M, p) * eps, TOLERANCE_FLOOR)``."""
    return max(max(int(n_rows), int(n_parameters)) * _EPS, TOLERANCE_FLOOR)


# ----------------------------------------------------------------- results
@dataclass(frozen=True)
class BaseParameters:
    """A base (minimal, identifiable) parametrization of ``theta`` (p,).

    Attributes
    ----------
    independent: indices of the kept columns, shape (r,), ascending.
    dependent: indices of the regrouped columns, shape (p - r,), ascending.
    K: regrouping matrix, shape (r, p - r): ``theta_base = theta[independent] + K theta[dependent]``
        and ``Y[:, dependent] = Y[:, independent] K``.
    names: the standard parameter names, length p.
    base_names: one name per base parameter: the name of its independent
        parameter, with a trailing ``R`` (regrouped) when other parameters join it.
    expressions: each base parameter in parameter names, e.g.
        ``panda_joint2.Izz + 0.0841*panda_joint3.m``.
    """

    independent: np.ndarray
    dependent: np.ndarray
    K: np.ndarray
    names: list[str]
    base_names: list[str]
    expressions: list[str]

    @property
    def n_base(self) -> int:
        """Number of base parameters r."""
        return int(self.independent.size)

    def to_base(self, theta) -> np.ndarray:
        """Base parameters of a standard parameter vector: (p,) -> (r,), or (..., p) -> (..., r)."""
        theta = as_float_array(theta, "theta")
        if theta.ndim == 0 or theta.shape[-1] != len(self.names):
            raise InputError(f"theta.shape={theta.shape} but n_parameters={len(self.names)}")
        return theta[..., self.independent] + theta[..., self.dependent] @ self.K.T

    def regressor(self, Y) -> np.ndarray:
        """The base regressor ``Y[..., independent]``: ``Y theta == Y_base theta_base``."""
        Y = np.asarray(Y)
        if Y.ndim == 0 or Y.shape[-1] != len(self.names):
            raise InputError(f"Y.shape={Y.shape} but n_parameters={len(self.names)}")
        return Y[..., self.independent]

    def to_dict(self) -> list[dict]:
        """``[{"name", "expression", "index"}]``, one per base parameter."""
        return [
            {"name": n, "expression": e, "index": int(i)}
            for n, e, i in zip(self.base_names, self.expressions, self.independent, strict=True)
        ]


@dataclass(frozen=True)
class RankAnalysis:
    """What a regressor can and cannot identify (see the module docstring for the math).

    Attributes
    ----------
    names: parameter names, length p.
    n_parameters: p.
    n_rows: number of stacked rows M the analysis saw.
    rank: numerical rank r (= number of base parameters).
    tolerance: the relative tolerance used (module docstring).
    singular_values: of the raw regressor Y, shape (p,), descending [units of Y].
    singular_values_scaled: of the column-scaled regressor, shape (p,), descending.
    condition_number: sigma_max / sigma_min of the base regressor Y[:, independent].
    condition_number_scaled: the same with unit-norm columns.
    base: the base parameters.
    null_space: shape (p, p - r), one unidentifiable direction per column
        (``Y @ null_space == 0``), unit coefficient on its dependent parameter.
    unidentifiable: each null-space column as an expression in parameter names.
    unexcited: directions these data fail to excite although they are structurally
        identifiable (only when a structural analysis was given), each a vector that
        is zero on the structurally dependent parameters.
    unexcited_vectors: those directions, shape (p, n_unexcited).
    information_eigenvalues: eigenvalues of the information matrix of the base
        regressor, ``Y_1^T Y_1`` with ``Y_1 = Y[:, independent]``, ascending, shape (r,)
        [units of Y squared]; with a structural analysis given, its independent
        columns are used, so that only what the data fail to excite shows.
    notes: explanations (why some parameters never enter the dynamics, fallbacks).
    source: where the regressor came from.
    """

    names: list[str]
    n_parameters: int
    n_rows: int
    rank: int
    tolerance: float
    singular_values: np.ndarray
    singular_values_scaled: np.ndarray
    condition_number: float
    condition_number_scaled: float
    base: BaseParameters
    null_space: np.ndarray
    unidentifiable: list[str]
    unexcited: list[str] = field(default_factory=list)
    unexcited_vectors: np.ndarray | None = None
    information_eigenvalues: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    source: str = ""

    @property
    def n_base(self) -> int:
        """Number of base parameters (= rank)."""
        return self.rank

    @property
    def nullity(self) -> int:
        """Dimension of the null space, p - rank."""
        return self.n_parameters - self.rank

    def raise_if_deficient(self) -> None:
        """Raise :class:`~manip_id.errors.RankDeficiencyError` unless every column is identifiable.

        The error carries the rank, the number of columns and the unidentifiable
        (and unexcited) directions by name.
        """
        directions = [*self.unidentifiable, *self.unexcited]
        if self.rank < self.n_parameters or self.unexcited:
            shown = "; ".join(directions[:5]) + (" ..." if len(directions) > 5 else "")
            raise RankDeficiencyError(
                f"the regressor has rank {self.rank} for {self.n_parameters} parameters: "
                f"{len(directions)} direction(s) not identifiable: {shown}",
                self.rank,
                self.n_parameters,
                directions,
            )

    def to_dict(self) -> dict:
        """A JSON-ready summary."""
        return {
            "source": self.source,
            "n_parameters": self.n_parameters,
            "n_rows": self.n_rows,
            "rank": self.rank,
            "tolerance": self.tolerance,
            "condition_number": _finite_or_none(self.condition_number),
            "condition_number_scaled": _finite_or_none(self.condition_number_scaled),
            "base_parameters": self.base.to_dict(),
            "unidentifiable": list(self.unidentifiable),
            "unexcited": list(self.unexcited),
            "singular_values": self.singular_values.tolist(),
            "singular_values_scaled": self.singular_values_scaled.tolist(),
            "information_eigenvalues": (
                None
                if self.information_eigenvalues is None
                else self.information_eigenvalues.tolist()
            ),
            "notes": list(self.notes),
            "names": list(self.names),
        }

    def report(self, max_rows: int | None = None, *, details: bool = True) -> str:
        """A readable table: rank, conditioning, base parameters, unidentifiable directions.

        ``max_rows`` caps each list; ``details=False`` leaves the base parameters and the
        unidentifiable directions out (the summary, eigenvalues, unexcited directions and
        notes remain).
        """
        lines = []
        if self.source:
            lines.append(f"rank analysis of {self.source}")
        lines += [
            f"  parameters           {self.n_parameters}",
            f"  rows                 {self.n_rows}",
            f"  rank (base params)   {self.rank}   (tolerance {self.tolerance:.3g}, relative, "
            "column-scaled)",
            f"  null space dimension {self.nullity}",
            f"  condition number     {self.condition_number:.4g} (base regressor), "
            f"{self.condition_number_scaled:.4g} (columns scaled)",
        ]
        sv = self.singular_values_scaled
        if sv.size:
            lines.append(
                f"  scaled singular values: largest {sv[0]:.4g}, "
                f"smallest kept {sv[self.rank - 1]:.4g}, "
                f"largest dropped {sv[self.rank]:.3g}"
                if self.rank < sv.size
                else f"  scaled singular values: largest {sv[0]:.4g}, smallest {sv[-1]:.4g}"
            )
        if details:
            width = max((len(n) for n in self.base.base_names), default=4)
            lines.append("")
            lines.append(f"base parameters ({self.rank}):")
            rows = list(zip(self.base.base_names, self.base.expressions, strict=True))
            for name, expr in rows[:max_rows]:
                lines.append(f"  {name:<{width}s} = {expr}")
            if max_rows is not None and len(rows) > max_rows:
                lines.append(f"  ... {len(rows) - max_rows} more")
            lines.append("")
            lines.append(
                f"unidentifiable directions ({self.nullity}; moving theta along one "
                "changes no torque):"
            )
            for expr in self.unidentifiable[:max_rows]:
                lines.append(f"  {expr}")
            if max_rows is not None and len(self.unidentifiable) > max_rows:
                lines.append(f"  ... {len(self.unidentifiable) - max_rows} more")
        if self.information_eigenvalues is not None:
            ev = self.information_eigenvalues
            lines.append("")
            lines.append(
                "smallest eigenvalues of the information matrix: "
                + ", ".join(f"{v:.3g}" for v in ev[:5])
            )
        if self.unexcited:
            lines.append("")
            lines.append(
                f"structurally identifiable but not excited by these data ({len(self.unexcited)}):"
            )
            lines += [f"  {e}" for e in self.unexcited]
        if self.notes:
            lines.append("")
            lines.append("notes:")
            lines += [f"  - {n}" for n in self.notes]
        return "\n".join(lines)


def _finite_or_none(x: float):
    return float(x) if math.isfinite(x) else None


# ---------------------------------------------------------------- streaming
class RFactorAccumulator:
    """Accumulates a (p, p) factor ``R`` with ``R^T R = Y^T Y`` over regressor chunks.

    ``add(Y)`` takes a chunk of shape (n, nv, p) or (M, p); memory is O(p^2)
    whatever the number of rows. ``information`` is ``A = Y^T Y`` (p, p).
    """

    def __init__(self, n_parameters: int, names: Sequence[str] | None = None):
        self.p = int(n_parameters)
        self.names = list(names) if names is not None else None
        self.R = np.zeros((0, self.p))
        self.n_rows = 0
        self._n_samples = 0

    def add(self, Y) -> None:
        """Add the rows of one chunk (checked for shape and NaN/Inf)."""
        Y = as_float_array(Y, "Y", ndim=(2, 3))
        if Y.shape[-1] != self.p:
            raise InputError(f"Y.shape={Y.shape} but n_parameters={self.p}")
        _check_finite_regressor(Y, self.names, offset=self._n_samples)
        self._n_samples += Y.shape[0]
        rows = Y.reshape(-1, self.p)
        if rows.shape[0] == 0:
            return
        self.n_rows += rows.shape[0]
        stacked = np.vstack([self.R, rows])
        self.R = sla.qr(stacked, mode="r", check_finite=False)[0][: self.p]

    @property
    def information(self) -> np.ndarray:
        """The information matrix ``A = Y^T Y``, shape (p, p)."""
        return self.R.T @ self.R


def _check_finite_regressor(Y: np.ndarray, names, offset: int = 0) -> None:
    if np.isfinite(Y).all():
        return
    bad = np.argwhere(~np.isfinite(Y))[0]
    value = Y[tuple(bad)]
    col = int(bad[-1])
    label = names[col] if names is not None and col < len(names) else f"column {col}"
    if Y.ndim == 3:
        where = f"sample {int(bad[0]) + offset}, joint row {int(bad[1])}"
    else:
        where = f"row {int(bad[0]) + offset}"
    raise InputError(f"the regressor holds {value} at {where}, {label}")


# --------------------------------------------------------------- core math
def _ordered_selection(Rs: np.ndarray, threshold: float) -> list[int]:
    """Gram-Schmidt QR in column order; columns with |R_jj| <= threshold are pivoted out."""
    k, p = Rs.shape
    Q = np.zeros((k, min(k, p)))
    kept: list[int] = []
    for j in range(p):
        v = Rs[:, j].copy()
        if not np.any(v):
            continue
        if kept:
            Qk = Q[:, : len(kept)]
            v -= Qk @ (Qk.T @ v)
            v -= Qk @ (Qk.T @ v)  # re-orthogonalize: twice is enough
        norm = float(np.linalg.norm(v))
        if norm > threshold and len(kept) < Q.shape[1]:
            Q[:, len(kept)] = v / norm
            kept.append(j)
    return kept


def _format_terms(terms: list[tuple[float, str]]) -> str:
    """``[(1, 'a'), (-0.5, 'b')]`` -> ``'a - 0.5*b'``."""
    out = ""
    for i, (c, name) in enumerate(terms):
        mag = abs(c)
        coef = "" if math.isclose(mag, 1.0, rel_tol=1e-9) else f"{mag:.4g}*"
        sign = "-" if c < 0 else "+"
        if i == 0:
            out = f"{'-' if c < 0 else ''}{coef}{name}"
        else:
            out += f" {sign} {coef}{name}"
    return out or "0"


def _vector_expression(v: np.ndarray, names: Sequence[str], lead: int, scale: np.ndarray) -> str:
    """Direction v (p,) as a readable sum, ``lead`` first; negligible terms dropped."""
    ref = abs(v[lead]) * scale[lead]
    idx = [lead] + [
        int(i)
        for i in np.flatnonzero(v)
        if i != lead and abs(v[i]) * scale[i] > COEFFICIENT_THRESHOLD * max(ref, 1e-300)
    ]
    return _format_terms([(float(v[i]), names[i]) for i in idx])


def _scaled(R: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Column norms, a zero-column mask and the column-scaled factor."""
    norms = np.linalg.norm(R, axis=0)
    top = float(norms.max()) if norms.size else 0.0
    zero = norms <= tol * top
    safe = np.where(zero, 1.0, norms)
    Rs = R / safe
    Rs[:, zero] = 0.0
    return norms, zero, Rs


def _condition(sv: np.ndarray) -> float:
    if sv.size == 0:
        return float("nan")
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def _analyze_factor(
    R: np.ndarray,
    names: list[str],
    n_rows: int,
    tolerance: float,
    *,
    structural: RankAnalysis | None = None,
    notes: Sequence[str] = (),
    source: str = "",
) -> RankAnalysis:
    p = R.shape[1]
    tol = float(tolerance)
    norms, zero, Rs = _scaled(R, tol)
    sv = np.linalg.svd(R, compute_uv=False)
    sv = np.concatenate([sv, np.zeros(p - sv.size)])
    svs = np.linalg.svd(Rs, compute_uv=False)
    svs = np.concatenate([svs, np.zeros(p - svs.size)])
    if svs[0] == 0.0:
        raise InputError("the regressor is all zero (or below the tolerance): nothing is excited")
    threshold = tol * svs[0]
    rank = int(np.sum(svs > threshold))
    kept = _ordered_selection(Rs, threshold)
    notes = list(notes)
    if len(kept) != rank:
        _, _, piv = sla.qr(Rs, mode="economic", pivoting=True)
        kept = sorted(int(j) for j in piv[:rank])
        notes.append(
            f"the ordered QR found {len(kept)} independent columns where the SVD finds "
            f"{rank}: base columns taken from the column-pivoted QR instead"
        )
    ind = np.array(kept, dtype=int)
    dep = np.array([j for j in range(p) if j not in set(kept)], dtype=int)
    # Scaled regrouping: Rs_1 Ks = Rs_2, then K = S_1^-1 Ks S_2.
    Ks = np.linalg.lstsq(Rs[:, ind], Rs[:, dep], rcond=None)[0] if dep.size else np.zeros((rank, 0))
    Ks[np.abs(Ks) < ROUNDOFF_THRESHOLD] = 0.0
    s_ind = np.where(zero[ind], 1.0, norms[ind])
    s_dep = np.where(zero[dep], 0.0, norms[dep])
    K = Ks / s_ind[:, None] * s_dep[None, :]
    scale = np.where(zero, 0.0, norms)

    null = np.zeros((p, dep.size))
    for n, d in enumerate(dep):
        null[d, n] = 1.0
        null[ind, n] = -K[:, n]
    unidentifiable = [
        _vector_expression(null[:, n], names, int(d), scale) for n, d in enumerate(dep)
    ]
    expressions, base_names = [], []
    for i, j in enumerate(ind):
        v = np.zeros(p)
        v[j] = 1.0
        v[dep] = K[i]
        expressions.append(_vector_expression(v, names, int(j), scale))
        regrouped = bool(np.any(np.abs(Ks[i]) >= COEFFICIENT_THRESHOLD))
        base_names.append(names[j] + ("R" if regrouped else ""))
    base = BaseParameters(ind, dep, K, list(names), base_names, expressions)

    cond = _condition(np.linalg.svd(R[:, ind], compute_uv=False))
    cond_s = _condition(np.linalg.svd(Rs[:, ind], compute_uv=False))

    unexcited: list[str] = []
    unexcited_vectors = None
    if structural is not None:
        if list(structural.names) != list(names):
            raise InputError("the structural analysis has other parameter names than these data")
        notes += [f"structural: {n}" for n in structural.notes]
        s_ind_cols = structural.base.independent
        eig = np.linalg.svd(R[:, s_ind_cols], compute_uv=False) ** 2
        info_eig = np.sort(np.concatenate([eig, np.zeros(s_ind_cols.size - eig.size)]))
        ex_tol = max(tol, EXCITATION_TOLERANCE)
        sub = R[:, s_ind_cols]
        sub_norms, sub_zero, sub_s = _scaled(sub, 0.0)
        top = np.linalg.svd(sub_s, compute_uv=False)[0] if sub_s.any() else 0.0
        kept_sub = _ordered_selection(sub_s, ex_tol * top) if top > 0 else []
        dep_sub = [k for k in range(s_ind_cols.size) if k not in set(kept_sub)]
        vecs = []
        if dep_sub:
            Kd = (
                np.linalg.lstsq(sub_s[:, kept_sub], sub_s[:, dep_sub], rcond=None)[0]
                if kept_sub
                else np.zeros((0, len(dep_sub)))
            )
            Kd[np.abs(Kd) < ROUNDOFF_THRESHOLD] = 0.0
            ks = np.where(sub_zero, 1.0, sub_norms)
            for n, d in enumerate(dep_sub):
                v = np.zeros(p)
                v[s_ind_cols[d]] = 1.0
                for m, k in enumerate(kept_sub):
                    v[s_ind_cols[k]] = -Kd[m, n] * ks[d] / ks[k]
                vecs.append(v)
                unexcited.append(
                    _vector_expression(
                        v, names, int(s_ind_cols[d]), np.where(norms > 0, norms, 1.0)
                    )
                )
        unexcited_vectors = np.array(vecs).T if vecs else np.zeros((p, 0))
    else:
        info_eig = np.sort(np.linalg.svd(R[:, ind], compute_uv=False) ** 2)
    return RankAnalysis(
        names=list(names),
        n_parameters=p,
        n_rows=int(n_rows),
        rank=rank,
        tolerance=tol,
        singular_values=sv,
        singular_values_scaled=svs,
        condition_number=cond,
        condition_number_scaled=cond_s,
        base=base,
        null_space=null,
        unidentifiable=unidentifiable,
        unexcited=unexcited,
        unexcited_vectors=unexcited_vectors,
        information_eigenvalues=info_eig,
        notes=notes,
        source=source,
    )


# ------------------------------------------------------------ explanations
def _robot_notes(robot, analysis_zero: Sequence[int]) -> list[str]:
    """Why whole blocks of parameters never enter: bodies moved by prismatic joints only."""
    model = robot.model
    notes = []
    zero = {int(j) for j in analysis_zero}
    explained: set[int] = set()
    for i in range(1, model.njoints):
        path, k = [], i
        while k > 0:
            path.append(k)
            k = model.parents[k]
        prismatic = all(
            "Prismatic" in model.joints[k].shortname()
            or model.joints[k].shortname().startswith("JointModelP")
            for k in path
        )
        rot = {10 * (i - 1) + c for c in range(1, 10)}
        if prismatic and rot <= zero:
            explained |= rot
            notes.append(
                f"{model.names[i]}: every joint between the base and this body is prismatic, so "
                "the body never rotates; its first moments (mcx, mcy, mcz) and rotational "
                "inertia (Ixx ... Izz) never enter the dynamics: only its mass is identifiable"
            )
    rest = sorted(zero - explained)
    if rest:
        shown = ", ".join(robot.parameter_names[j] for j in rest[:8])
        more = f" and {len(rest) - 8} more" if len(rest) > 8 else ""
        notes.append(
            f"{len(rest)} parameters never enter the dynamics at all "
            f"(zero regressor column): {shown}{more}"
        )
    return notes


def _zero_columns(R: np.ndarray, tol: float) -> np.ndarray:
    norms = np.linalg.norm(R, axis=0)
    return np.flatnonzero(norms <= tol * (norms.max() if norms.size else 0.0))


# ------------------------------------------------------------------ public
def _check_names(names, p: int) -> list[str]:
    if names is None:
        raise InputError("give the parameter names (names=...) or the robot (robot=...)")
    names = [str(n) for n in names]
    if len(names) != p:
        raise InputError(f"the regressor has {p} columns but {len(names)} names were given")
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InputError(f"parameter names must be unique; {dup!r} repeats")
    return names


def _check_tolerance(tolerance) -> float | None:
    if tolerance is None:
        return None
    tol = float(tolerance)
    if not (math.isfinite(tol) and 0.0 < tol < 1.0):
        raise InputError(f"tolerance must be a relative value in (0, 1), got {tolerance}")
    return tol


def _check_rows(n_rows: int, p: int) -> None:
    if n_rows == 0:
        raise InputError("the regressor is empty (0 rows)")
    if n_rows < p:
        raise InputError(
            f"fewer rows than parameters: {n_rows} rows for {p} parameters; "
            f"a rank analysis needs at least {p} rows (more samples)"
        )


def structural_analysis(
    robot, *, seed: int = 0, n_samples: int | None = None, tolerance: float | None = None
) -> RankAnalysis:
    """What no data of this robot can identify: Y stacked over random states within the limits.

    ``n_samples`` defaults to ``max(MIN_SAMPLES, ceil(ROWS_PER_PARAMETER * p / nv))`` states
    from ``robot.random_states(n_samples, seed)``, streamed through
    :func:`manip_id.regressor.iter_regressor` into a (p, p) factor.
    """
    from .regressor import iter_regressor

    p, nv = robot.n_parameters, robot.nv
    if n_samples is None:
        n_samples = max(MIN_SAMPLES, math.ceil(ROWS_PER_PARAMETER * p / nv))
    n_samples = int(n_samples)
    if n_samples * nv < p:
        raise InputError(
            f"n_samples={n_samples} gives {n_samples * nv} rows for {p} parameters; "
            f"need at least {math.ceil(p / nv)} samples"
        )
    tol = _check_tolerance(tolerance)
    q, dq, ddq = robot.random_states(n_samples, seed)
    acc = RFactorAccumulator(p, robot.parameter_names)
    for chunk in iter_regressor(robot, q, dq, ddq, chunk=_CHUNK):
        acc.add(chunk.Y)
    tol = tol if tol is not None else default_tolerance(acc.n_rows, p)
    zero = _zero_columns(acc.R, tol)
    return _analyze_factor(
        acc.R,
        robot.parameter_names,
        acc.n_rows,
        tol,
        notes=_robot_notes(robot, zero),
        source=f"{robot.name} (structural: {n_samples} random states, seed {seed})",
    )


def analyze(
    source,
    *,
    names: Sequence[str] | None = None,
    robot=None,
    structural: RankAnalysis | None = None,
    seed: int = 0,
    n_samples: int | None = None,
    tolerance: float | None = None,
) -> RankAnalysis:
    """Rank analysis of a robot (structural) or of a regressor (what these data excite).

    Parameters
    ----------
    source: a :class:`~manip_id.robot.Robot` (structural analysis, see
        :func:`structural_analysis`; ``seed`` and ``n_samples`` apply), or a
        regressor ``Y`` of shape (M, p) or (N, nv, p) (sample-major).
    names: parameter names, length p (for an array; taken from ``robot`` when given).
    robot: the robot the array belongs to; then the structural analysis is run too
        (unless ``structural`` is given) and the unexcited directions are reported.
    structural: a structural :class:`RankAnalysis` to compare the data with.
    tolerance: relative rank tolerance (module docstring); default
        :func:`default_tolerance`, ``max(max(M, p) * eps, 1e-8)``.

    Returns
    -------
    :class:`RankAnalysis`. A regressor with NaN/Inf, no rows, fewer rows than
    columns, all zeros, or a width other than ``len(names)`` raises :class:`InputError`.
    """
    from .robot import Robot

    if isinstance(source, Robot):
        return structural_analysis(source, seed=seed, n_samples=n_samples, tolerance=tolerance)
    Y = as_float_array(source, "Y", ndim=(2, 3))
    p = Y.shape[-1]
    if robot is not None:
        if names is None:
            names = robot.parameter_names
        if p != robot.n_parameters:
            raise InputError(f"Y.shape={Y.shape} but robot.n_parameters={robot.n_parameters}")
    names = _check_names(names, p)
    tol = _check_tolerance(tolerance)
    acc = RFactorAccumulator(p, names)
    step = max(1, (64 * 1024) // max(p * (Y.shape[1] if Y.ndim == 3 else 1), 1))
    for start in range(0, Y.shape[0], step):
        acc.add(Y[start : start + step])
    _check_rows(acc.n_rows, p)
    if robot is not None and structural is None:
        structural = structural_analysis(robot, seed=seed)
    tol = tol if tol is not None else default_tolerance(acc.n_rows, p)
    what = f"{robot.name} data" if robot is not None else "a regressor"
    return _analyze_factor(
        acc.R,
        names,
        acc.n_rows,
        tol,
        structural=structural,
        source=f"{what} ({acc.n_rows} rows x {p} columns)",
    )


def analyze_trajectory(
    robot,
    q,
    dq,
    ddq,
    *,
    structural: RankAnalysis | None = None,
    tolerance: float | None = None,
    chunk: int = _CHUNK,
) -> RankAnalysis:
    """What a trajectory excites, streamed: Y(q, dq, ddq) is never stacked.

    ``q`` (N, nq) [rad or m], ``dq``, ``ddq`` (N, nv); the structural analysis
    of ``robot`` is computed when not given, and the unexcited directions reported.
    """
    from .regressor import iter_regressor

    tol = _check_tolerance(tolerance)
    acc = RFactorAccumulator(robot.n_parameters, robot.parameter_names)
    for c in iter_regressor(robot, q, dq, ddq, chunk=chunk):
        acc.add(c.Y)
    _check_rows(acc.n_rows, robot.n_parameters)
    if structural is None:
        structural = structural_analysis(robot)
    tol = tol if tol is not None else default_tolerance(acc.n_rows, robot.n_parameters)
    n = acc.n_rows // robot.nv
    return _analyze_factor(
        acc.R,
        robot.parameter_names,
        acc.n_rows,
        tol,
        structural=structural,
        source=f"{robot.name} trajectory ({n} samples, {acc.n_rows} rows)",
    )


def analyze_information(
    A,
    names: Sequence[str],
    *,
    n_rows: int,
    structural: RankAnalysis | None = None,
    tolerance: float | None = None,
) -> RankAnalysis:
    """Rank analysis from an accumulated information matrix ``A = Y^T Y``, shape (p, p).

    ``n_rows`` is the number of stacked rows M that built ``A``. The factor
    ``R = diag(sqrt(w)) V^T`` of the eigendecomposition ``A = V diag(w) V^T``
    of the column-scaled ``A`` (then unscaled) has the same Gram matrix, so the
    analysis is the one of ``Y``, up to the round-off of forming ``A``: hence the
    default tolerance ``p * sqrt(eps)``.
    With ``structural``, the directions these data fail to excite although they
    are structurally identifiable are reported in ``unexcited``, and
    ``information_eigenvalues`` are those of ``A`` on the structural base columns.
    """
    A = as_float_array(A, "A", ndim=2)
    if A.shape[0] != A.shape[1]:
        raise InputError(f"an information matrix is square (p, p), got A.shape={A.shape}")
    p = A.shape[0]
    names = _check_names(names, p)
    if not np.isfinite(A).all():
        i, j = np.argwhere(~np.isfinite(A))[0]
        raise InputError(f"A holds {A[i, j]} at ({names[i]}, {names[j]})")
    scale = float(np.abs(A).max()) if A.size else 0.0
    if not np.allclose(A, A.T, rtol=1e-10, atol=1e-12 * scale):
        raise InputError("A must be symmetric (an information matrix Y^T Y)")
    _check_rows(int(n_rows), p)
    tol = _check_tolerance(tolerance)
    tol = tol if tol is not None else p * math.sqrt(_EPS)
    d = np.sqrt(np.clip(np.diag(A), 0.0, None))  # column norms of Y
    if np.any(np.diag(A) < 0):
        raise InputError("A has a negative diagonal entry: not an information matrix Y^T Y")
    safe = np.where(d > 0, d, 1.0)
    As = A / safe[:, None] / safe[None, :]
    w, V = np.linalg.eigh(0.5 * (As + As.T))
    if w.size and w[0] < -tol * max(w[-1], 0.0):
        raise InputError(
            f"A is not positive semi-definite (smallest scaled eigenvalue "
            f"{w[0]:.3g}): not an information matrix Y^T Y"
        )
    R = (np.sqrt(np.clip(w, 0.0, None))[:, None] * V.T) * safe[None, :]
    return _analyze_factor(
        R,
        names,
        int(n_rows),
        tol,
        structural=structural,
        source=f"an information matrix ({n_rows} rows x {p} columns)",
    )


def analyze_dataset(robot, dataset, *, ddq=None, structural=None, tolerance=None) -> RankAnalysis:
    """What a measured dataset excites (``dataset.q``, ``dq``, and ``ddq`` or the given ``ddq``)."""
    acc_arr = dataset.ddq if ddq is None else ddq
    if acc_arr is None:
        raise InputError(
            "the dataset has no accelerations (ddq): estimate them first "
            "(manip_id.signals) or pass ddq="
        )
    out = analyze_trajectory(
        robot, dataset.q, dataset.dq, acc_arr, structural=structural, tolerance=tolerance
    )
    return out
