"""Results of a rank analysis: the base parametrization and what the data identify.

:class:`BaseParameters` maps standard to base parameters; :class:`RankAnalysis`
holds rank, conditioning, null space and readable directions, with a JSON-ready
``to_dict`` and a text ``report``. The math is in the package docstring.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._checks import as_float_array
from ..errors import InputError, RankDeficiencyError
from ..metrics import finite_or_none


@dataclass(frozen=True)
class BaseParameters:
    """A base (minimal, identifiable) parametrization of ``theta`` (p,).

    Attributes
    ----------
    independent
        indices of the kept columns, shape (r,), ascending.
    dependent
        indices of the regrouped columns, shape (p - r,), ascending.
    K
        regrouping matrix, shape (r, p - r):
        ``theta_base = theta[independent] + K theta[dependent]`` and
        ``Y[:, dependent] = Y[:, independent] K``.
    names
        the standard parameter names, length p.
    base_names
        one name per base parameter: the name of its independent
        parameter, with a trailing ``R`` (regrouped) when other parameters join it.
    expressions
        each base parameter in parameter names, e.g.
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

    def from_base(self, theta_base) -> np.ndarray:
        """A standard vector with these base parameters, zero on the dependent columns.

        (..., r) -> (..., p); ``to_base(from_base(b)) == b``.
        """
        arr = as_float_array(theta_base, "theta_base")
        if arr.ndim == 0 or arr.shape[-1] != self.n_base:
            raise InputError(f"theta_base.shape={arr.shape} but the base has {self.n_base}")
        out = np.zeros((*arr.shape[:-1], len(self.names)))
        out[..., self.independent] = arr
        return out

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
    names
        parameter names, length p.
    n_parameters
        p.
    n_rows
        number of stacked rows M the analysis saw.
    rank
        numerical rank r (= number of base parameters).
    tolerance
        the relative tolerance used (module docstring).
    singular_values
        of the raw regressor Y, shape (p,), descending [units of Y].
    singular_values_scaled
        of the column-scaled regressor, shape (p,), descending.
    condition_number
        sigma_max / sigma_min of the base regressor Y[:, independent].
    condition_number_scaled
        the same with unit-norm columns.
    base
        the base parameters.
    null_space
        shape (p, p - r), one unidentifiable direction per column
        (``Y @ null_space == 0``), unit coefficient on its dependent parameter.
    unidentifiable
        each null-space column as an expression in parameter names.
    unexcited
        directions these data fail to excite although they are structurally
        identifiable (only when a structural analysis was given), each a vector that
        is zero on the structurally dependent parameters.
    unexcited_vectors
        those directions, shape (p, n_unexcited).
    information_eigenvalues
        eigenvalues of the information matrix of the base
        regressor, ``Y_1^T Y_1`` with ``Y_1 = Y[:, independent]``, ascending, shape (r,)
        [units of Y squared]; with a structural analysis given, its independent
        columns are used, so that only what the data fail to excite shows.
    notes
        explanations (why some parameters never enter the dynamics, fallbacks).
    source
        where the regressor came from.
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
            raise RankDeficiencyError(
                self.rank,
                self.n_parameters,
                directions,
                subject=f"the rows of {self.source}" if self.source else "the regressor's rows",
            )

    def to_dict(self) -> dict:
        """A JSON-ready summary."""
        return {
            "source": self.source,
            "n_parameters": self.n_parameters,
            "n_rows": self.n_rows,
            "rank": self.rank,
            "tolerance": self.tolerance,
            "condition_number": finite_or_none(self.condition_number),
            "condition_number_scaled": finite_or_none(self.condition_number_scaled),
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
