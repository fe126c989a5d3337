"""The streamed R factor: ``R^T R = Y^T Y`` accumulated chunk by chunk, O(p^2) memory.

Each chunk is appended below the current factor and re-triangularized,
``R <- qr([R; Y_chunk])``: the Gram matrix of the stacked rows is kept exactly
(up to round-off), never the rows themselves.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla

from .._checks import as_float_array
from ..errors import InputError


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
