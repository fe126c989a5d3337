"""Where each standard parameter's value comes from: the data, the prior or a bound.

The data determine only the base parameters ``beta = P theta`` (``P`` the (r, p) base
map). Standard parameter ``theta_i``

- comes from the **bound** when the active linear constraints of the consistent solve
  fix it: ``e_i`` lies in the span of their gradients ``a`` (a mass on its mass range,
  every mass held by mass ranges and the total mass, a friction term at 0); the data can
  no longer move it (its linearised std is 0: "at bound", not a measurement);
- comes from the **prior** when it never enters the dynamics (``P[:, i] = 0``, e.g. the
  mass of a first link turning about the vertical): its value is the prior's, it has no
  data std. Without a prior (plain least squares' minimum-norm vector, ``prior="none"``)
  such a value is the solver's choice and is "not determined";
- comes from the **data** otherwise (alone, or through the base parameters it enters,
  with the prior choosing along the directions the data do not see).
"""

from __future__ import annotations

import numpy as np

#: The sources a standard parameter can have, in the JSON's ``source`` field.
SOURCES: tuple[str, ...] = ("data", "prior", "bound", "not determined")


def parameter_sources(P, active_rows=None, *, prior: bool = True, tol: float = 1e-9) -> list[str]:
    """The source (one of :data:`SOURCES`) of each standard parameter.

    Parameters
    ----------
    P : array_like
        the base map, shape (r, p) (``beta = P theta``).
    active_rows : array_like or None
        gradients of the active linear constraints, shape (c, p).
    prior : bool
        whether a prior chose the values the data do not see.
    tol : float
        relative tolerance of "does not enter" and "fixed by the constraints".
    """
    P = np.asarray(P, dtype=float)
    p = P.shape[1]
    scale = float(np.abs(P).max()) if P.size else 1.0
    enters = np.abs(P).max(axis=0) > tol * max(scale, 1e-300) if P.size else np.zeros(p, bool)
    fixed = np.zeros(p, dtype=bool)
    if active_rows is not None and np.size(active_rows):
        rows = np.asarray(active_rows, dtype=float).reshape(-1, p)
        _, s, Vt = np.linalg.svd(rows, full_matrices=False)
        basis = Vt[s > 1e-10 * s[0]] if s.size and s[0] > 0 else Vt[:0]
        fixed = np.einsum("kp,kp->p", basis, basis) > 1.0 - 1e-6  # ||proj e_i||^2 = 1
    out = []
    for i in range(p):
        if fixed[i]:
            out.append("bound")
        elif enters[i]:
            out.append("data")
        else:
            out.append("prior" if prior else "not determined")
    return out


__all__ = ["SOURCES", "parameter_sources"]
