"""Packed rows: the columns of a dataset side by side, the unit of every streamed reader.

A streamed reader yields float64 blocks of shape (k, width) whose columns are::

    t | q (nq) | dq (nv) | tau (nv) | ddq (nv, when present) | temp (1 or nv, when present)

so one buffer holds a block of every field, and overlapping blocks (filters,
splines, differences) slice rows of one array. ``temp`` is the measured temperature
[degC or K] of the ``temperature`` friction law (:mod:`manip_id.robot.friction`): one column per
joint, or one for every joint.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

#: The fields of a dataset, in packed column order.
FIELDS: tuple[str, ...] = ("t", "q", "dq", "tau", "ddq", "temp")


@dataclass(frozen=True)
class Layout:
    """Column slices of packed rows for ``nq`` positions and ``nv`` velocities (``n_temp``:
    temperature columns, 0, 1 or nv)."""

    nq: int
    nv: int
    has_ddq: bool = False
    n_temp: int = 0

    @classmethod
    def processed(cls, nq: int, nv: int, width: int) -> Layout:
        """The layout of preprocessed rows (ddq always there) ``width`` columns wide."""
        return cls(nq, nv, True, width - (1 + nq + 3 * nv))

    @cached_property
    def slices(self) -> dict[str, slice]:
        """Field name -> column slice."""
        nq, nv = self.nq, self.nv
        out = {
            "t": slice(0, 1),
            "q": slice(1, 1 + nq),
            "dq": slice(1 + nq, 1 + nq + nv),
            "tau": slice(1 + nq + nv, 1 + nq + 2 * nv),
        }
        end = 1 + nq + 2 * nv
        if self.has_ddq:
            out["ddq"] = slice(end, end + nv)
            end += nv
        if self.n_temp:
            out["temp"] = slice(end, end + self.n_temp)
        return out

    @property
    def fields(self) -> tuple[str, ...]:
        """The fields present, in column order."""
        return tuple(self.slices)

    @property
    def width(self) -> int:
        """Number of packed columns."""
        return 1 + self.nq + (3 if self.has_ddq else 2) * self.nv + self.n_temp

    def with_ddq(self, has_ddq: bool = True) -> Layout:
        """The same layout with (or without) ddq columns."""
        return Layout(self.nq, self.nv, has_ddq, self.n_temp)

    def pack(self, t, q, dq, tau, ddq=None, temp=None) -> np.ndarray:
        """Packed rows from field arrays (ddq, temp only when the layout has them)."""
        parts = [np.asarray(t, dtype=float).reshape(-1, 1), q, dq, tau]
        if self.has_ddq:
            parts.append(ddq)
        if self.n_temp:
            parts.append(temp)
        return np.hstack([np.asarray(p, dtype=float).reshape(len(parts[0]), -1) for p in parts])

    def unpack(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """Field name -> view of ``rows`` (t as shape (k,))."""
        out = {name: rows[:, s] for name, s in self.slices.items()}
        out["t"] = rows[:, 0]
        return out
