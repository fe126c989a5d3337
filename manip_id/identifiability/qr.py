"""The QR math on a factor R (R^T R = Y^T Y): rank, base columns, regrouping, directions.

Gautier's ordered QR on the column-scaled factor selects the independent
columns; the regrouping matrix ``K`` and the null space follow; against a
structural analysis, the structurally identifiable directions these data do not
excite are found the same way on the structural base columns. See the package
docstring for the formulas and tolerances.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..errors import InputError, format_direction
from .results import BaseParameters, RankAnalysis

#: Scaled coefficients below this are dropped from the printed expressions (K keeps them).
COEFFICIENT_THRESHOLD = 1e-6
#: Scaled coefficients below this are round-off of the least-squares solve: zeroed in K.
ROUNDOFF_THRESHOLD = 1e-10
#: Relative singular value of the scaled base regressor below which a structurally
#: identifiable direction counts as not excited by the data (unless ``tolerance`` is larger).
EXCITATION_TOLERANCE = 1e-6
#: Smallest default rank tolerance (relative, on the column-scaled regressor).
TOLERANCE_FLOOR = 1e-8
EPS = float(np.finfo(float).eps)
#: The suffix of a regrouped base parameter's name, and what it means in words (printed
#: under every table of base parameters that holds one).
REGROUPED_SUFFIX = "R"
REGROUPED_NOTE = (
    "a name ending in R is a regrouped base parameter: that standard parameter plus the "
    "others the data cannot tell apart from it (its expression)"
)


def has_regrouped(names) -> bool:
    """Whether one of the base-parameter ``names`` is regrouped (ends in ``R``: no standard
    parameter's name does)."""
    return any(str(n).endswith(REGROUPED_SUFFIX) for n in names)


def default_tolerance(n_rows: int, n_parameters: int) -> float:
    """Default rank tolerance of a regressor: ``max(max(M, p) * eps, TOLERANCE_FLOOR)``."""
    return max(max(int(n_rows), int(n_parameters)) * EPS, TOLERANCE_FLOOR)


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


def _vector_expression(v: np.ndarray, names: Sequence[str], lead: int, scale: np.ndarray) -> str:
    """Direction v (p,) as a readable sum, ``lead`` first; negligible terms dropped."""
    return format_direction(v, names, lead=lead, scale=scale, threshold=COEFFICIENT_THRESHOLD)


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


@dataclass(frozen=True)
class _Selection:
    """Rank and base columns of a column-scaled factor."""

    rank: int
    independent: np.ndarray
    dependent: np.ndarray
    Ks: np.ndarray  # scaled regrouping, (r, p - r)
    notes: list[str]


def _select_columns(Rs: np.ndarray, svs: np.ndarray, tol: float) -> _Selection:
    """Ordered QR selection of the independent columns, LAPACK's pivoting when it disagrees."""
    p = Rs.shape[1]
    threshold = tol * svs[0]
    rank = int(np.sum(svs > threshold))
    kept = _ordered_selection(Rs, threshold)
    notes = []
    if len(kept) != rank:
        _, _, piv = sla.qr(Rs, mode="economic", pivoting=True)
        kept = sorted(int(j) for j in piv[:rank])
        notes.append(
            f"the ordered QR found {len(kept)} independent columns where the SVD finds "
            f"{rank}: base columns taken from the column-pivoted QR instead"
        )
    ind = np.array(kept, dtype=int)
    dep = np.array([j for j in range(p) if j not in set(kept)], dtype=int)
    # Scaled regrouping: Rs_1 Ks = Rs_2
    Ks = np.linalg.lstsq(Rs[:, ind], Rs[:, dep], rcond=None)[0] if dep.size else np.zeros((rank, 0))
    Ks[np.abs(Ks) < ROUNDOFF_THRESHOLD] = 0.0
    return _Selection(rank, ind, dep, Ks, notes)


def _base_parameters(
    sel: _Selection, names: list[str], norms: np.ndarray, zero: np.ndarray
) -> tuple[BaseParameters, np.ndarray, list[str]]:
    """Base parameters ``K = S_1^-1 Ks S_2``, the null space ``P^T [-K; I]`` and its text."""
    p = len(names)
    ind, dep, Ks = sel.independent, sel.dependent, sel.Ks
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
        base_names.append(names[j] + (REGROUPED_SUFFIX if regrouped else ""))
    base = BaseParameters(ind, dep, K, list(names), base_names, expressions)
    return base, null, unidentifiable


def _unexcited(
    R: np.ndarray, names: list[str], norms: np.ndarray, tol: float, structural: RankAnalysis
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Structurally identifiable directions these data do not excite.

    The same ordered selection on the structural base columns of ``R`` (tolerance at
    least :data:`EXCITATION_TOLERANCE`); returns their text, the vectors (p, k) and the
    information eigenvalues on the structural base columns, ascending.
    """
    p = len(names)
    cols = structural.base.independent
    sub = R[:, cols]
    eig = np.linalg.svd(sub, compute_uv=False) ** 2
    info_eig = np.sort(np.concatenate([eig, np.zeros(cols.size - eig.size)]))
    ex_tol = max(tol, EXCITATION_TOLERANCE)
    sub_norms, sub_zero, sub_s = _scaled(sub, 0.0)
    top = np.linalg.svd(sub_s, compute_uv=False)[0] if sub_s.any() else 0.0
    kept_sub = _ordered_selection(sub_s, ex_tol * top) if top > 0 else []
    dep_sub = [k for k in range(cols.size) if k not in set(kept_sub)]
    texts, vecs = [], []
    if dep_sub:
        Kd = (
            np.linalg.lstsq(sub_s[:, kept_sub], sub_s[:, dep_sub], rcond=None)[0]
            if kept_sub
            else np.zeros((0, len(dep_sub)))
        )
        Kd[np.abs(Kd) < ROUNDOFF_THRESHOLD] = 0.0
        ks = np.where(sub_zero, 1.0, sub_norms)
        scale = np.where(norms > 0, norms, 1.0)
        for n, d in enumerate(dep_sub):
            v = np.zeros(p)
            v[cols[d]] = 1.0
            for m, k in enumerate(kept_sub):
                v[cols[k]] = -Kd[m, n] * ks[d] / ks[k]
            vecs.append(v)
            texts.append(_vector_expression(v, names, int(cols[d]), scale))
    vectors = np.array(vecs).T if vecs else np.zeros((p, 0))
    return texts, vectors, info_eig


def analyze_factor(
    R: np.ndarray,
    names: list[str],
    n_rows: int,
    tolerance: float,
    *,
    structural: RankAnalysis | None = None,
    notes: Sequence[str] = (),
    source: str = "",
) -> RankAnalysis:
    """The rank analysis of a factor ``R`` (R^T R = Y^T Y, shape (k, p)) of ``n_rows`` rows."""
    p = R.shape[1]
    tol = float(tolerance)
    norms, zero, Rs = _scaled(R, tol)
    sv = np.linalg.svd(R, compute_uv=False)
    sv = np.concatenate([sv, np.zeros(p - sv.size)])
    svs = np.linalg.svd(Rs, compute_uv=False)
    svs = np.concatenate([svs, np.zeros(p - svs.size)])
    if svs[0] == 0.0:
        raise InputError("the regressor is all zero (or below the tolerance): nothing is excited")
    sel = _select_columns(Rs, svs, tol)
    notes = [*notes, *sel.notes]
    base, null, unidentifiable = _base_parameters(sel, names, norms, zero)
    ind = sel.independent
    cond = _condition(np.linalg.svd(R[:, ind], compute_uv=False))
    cond_s = _condition(np.linalg.svd(Rs[:, ind], compute_uv=False))

    unexcited: list[str] = []
    unexcited_vectors = None
    if structural is not None:
        if list(structural.names) != list(names):
            raise InputError("the structural analysis has other parameter names than these data")
        notes += [f"structural: {n}" for n in structural.notes]
        unexcited, unexcited_vectors, info_eig = _unexcited(R, names, norms, tol, structural)
    else:
        info_eig = np.sort(np.linalg.svd(R[:, ind], compute_uv=False) ** 2)
    return RankAnalysis(
        names=list(names),
        n_parameters=p,
        n_rows=int(n_rows),
        rank=sel.rank,
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
