"""Local refinement of a design under a working set of its constraints (SLSQP).

The constraints of :mod:`.constraints` hold on a time grid: thousands of rows (per joint,
per limit kind and sign, per grid time), of which only a few are near their bound at a
time. SLSQP's quadratic subproblem costs about ``m n^2`` for ``m`` rows and ``n``
coefficients, and the clearance and torque rows each cost a distance or an RNEA per grid
time, so the refinement passes SLSQP the rows that can bind: in every block of rows (one
signal of one joint, or the least clearance, over the grid) whose slack ``c`` falls below
:data:`LEVEL` of its room (``c`` at zero motion), the grid times where ``c`` has a local
minimum, with :data:`WIDTH` neighbours on each side (the minimum moves with ``z``), and
every violated local minimum. Each block of linear rows also gives SLSQP one smooth guard
row, ``-log(sum_k exp(-s c_k / room_k)) / s + log(n) / s >= 0`` (a soft minimum: it lets
a row exceed its bound by at most ``log(n) / s`` of its room, :data:`GUARD`), so that a
signal with no row in the set cannot run away. After each SLSQP run every row is
evaluated again; while some row is violated, the near rows at the new point join the set
(the set only grows), the point is pulled back to the last feasible one along the segment
between them (bisection) and SLSQP restarts there, at most :data:`ROUNDS` times; a
feasible iterate at SLSQP's iteration limit is refined once more likewise. The result is
the last feasible point (the start when none is): every row holds there.
"""

from __future__ import annotations

import numpy as np

from ..errors import NumericalError

#: A block of rows enters the working set when its least slack is below this share of its room.
LEVEL = 0.3
#: Grid neighbours kept on each side of a local minimum of the slack.
WIDTH = 2
#: Sharpness ``s`` of the guard rows (a row exceeds its bound by at most ``log(n) / s`` of
#: its room under the guard alone).
GUARD = 40.0
#: SLSQP runs at most (each after a re-screening), ``maxiter`` iterations each: on the
#: 20 s designs, 2 rounds reach -log det F = -296 (ur5) and -524 (panda) against -298 and
#: -571 with 4 rounds, at half the cost or less (-223 and -443 before the working set).
ROUNDS = 2


def near_rows(slack: np.ndarray, room: np.ndarray, level: float = LEVEL, width: int = WIDTH):
    """Rows that can bind soon, shape (blocks, n) of bool, from the slacks ``c >= 0`` of
    ``blocks`` time series on the grid (shape (blocks, n)) and their rooms (broadcast)."""
    rel = np.asarray(slack, float) / np.asarray(room, float)
    pad = np.full((rel.shape[0], 1), np.inf)
    left = np.hstack([pad, rel[:, :-1]])
    right = np.hstack([rel[:, 1:], pad])
    keep = (rel <= left) & (rel <= right) & (rel < level)
    out = keep.copy()
    for s in range(1, width + 1):
        out[:, s:] |= keep[:, :-s]
        out[:, :-s] |= keep[:, s:]
    return out


class WorkingSet:
    """The rows passed to SLSQP: linear rows ``G z <= h`` (in blocks of ``n`` grid times)
    and, per nonlinear constraint, the state its ``screen`` returns (a union over rounds)."""

    def __init__(self, G: np.ndarray, h: np.ndarray, n_times: int, nonlinear: list):
        self.G, self.h, self.n = G, h, int(n_times)
        self.nonlinear = nonlinear
        self.linear = np.zeros(h.shape[0], bool)
        self.masks: list = [None] * len(nonlinear)

    def grow(self, z: np.ndarray) -> None:
        """Add the rows near their bound at ``z`` (module docstring)."""
        slack = (self.h - self.G @ z).reshape(-1, self.n)
        room = self.h.reshape(-1, self.n)
        self.linear |= near_rows(slack, np.maximum(room, 1e-12)).ravel()
        for i, c in enumerate(self.nonlinear):
            mask = c.screen(z, near_rows)
            old = self.masks[i]
            if old is not None:
                mask = tuple(a | b for a, b in zip(old, mask, strict=True))
            self.masks[i] = mask

    def constraints(self) -> list[dict]:
        """SciPy constraint dicts of the working set."""
        G, h = self.G[self.linear], self.h[self.linear]
        cons = [_guard(self.G, self.h, self.n)]
        if h.size:
            cons.append({"type": "ineq", "fun": lambda z: h - G @ z, "jac": lambda _z: -G})
        for c, mask in zip(self.nonlinear, self.masks, strict=True):
            sub = c.restricted(mask)
            if sub is not None:
                cons.append({"type": "ineq", "fun": sub, "jac": sub.jacobian})
        return cons

    def size(self) -> int:
        """Rows in the working set (linear and nonlinear)."""
        pairs = zip(self.nonlinear, self.masks, strict=True)
        return int(self.linear.sum()) + sum(c.rows(m) for c, m in pairs)


def _guard(G: np.ndarray, h: np.ndarray, n: int) -> dict:
    """One soft-minimum row per block of ``n`` linear rows (module docstring)."""
    room = np.maximum(h, 1e-12).reshape(-1, n)
    Gs = (G / np.maximum(h, 1e-12)[:, None]).reshape(room.shape[0], n, -1)
    shift = np.log(n) / GUARD

    def weights(z):
        c = 1.0 - Gs @ z  # (blocks, n) slack / room
        m = c.min(axis=1, keepdims=True)
        e = np.exp(-GUARD * (c - m))
        return c, m[:, 0], e, e.sum(axis=1)

    def fun(z):
        _, m, _, total = weights(z)
        return m - np.log(total) / GUARD + shift

    def jac(z):
        _, _, e, total = weights(z)
        return -np.einsum("bk,bkz->bz", e / total[:, None], Gs)

    return {"type": "ineq", "fun": fun, "jac": jac}


def feasible(z, G, h, nonlinear, tol: float = 1e-9) -> bool:
    """Every row of every constraint holds at ``z`` (within ``tol``)."""
    return bool(np.all(G @ z <= h + tol)) and all(np.all(c(z) >= -tol) for c in nonlinear)


def refine(objective, z0, G, h, n_times: int, nonlinear: list, maxiter: int):
    """SLSQP from ``z0`` on ``objective.value_and_gradient`` under the working set of
    the constraints (module docstring); returns ``(z, rows)``: the last feasible point
    (None when ``z0`` is not feasible and no iterate was) and the working set's size."""
    import scipy.optimize  # heavy: only when a design runs

    ws = WorkingSet(G, h, n_times, nonlinear)
    z = np.asarray(z0, float)
    best = z if feasible(z, G, h, nonlinear) else None
    for _ in range(ROUNDS):
        ws.grow(z)
        try:
            res = scipy.optimize.minimize(
                objective.value_and_gradient,
                z,
                jac=True,
                method="SLSQP",
                constraints=ws.constraints(),
                options={"maxiter": int(maxiter), "ftol": 1e-7},
            )
        except ValueError as exc:  # pragma: no cover - SLSQP breaking down on its own iterates
            raise NumericalError("excitation design (SLSQP)", str(exc)) from exc
        if not np.all(np.isfinite(res.x)):
            break
        if feasible(res.x, G, h, nonlinear):
            best = res.x
            if res.success:
                break
            z = res.x
            continue
        ws.grow(res.x)  # the rows it broke join the set
        if best is None:
            break
        z = best = _repaired(best, res.x, G, h, nonlinear)
    return best, ws.size()


#: Bisection steps of :func:`_repaired`.
REPAIR_STEPS = 12


def _repaired(good, bad, G, h, nonlinear):
    """The feasible point furthest along the segment from ``good`` (feasible) to ``bad``
    (an SLSQP iterate that broke a row), by bisection: SLSQP's last iterate may stop at
    its iteration limit outside the rows it had not seen, the segment keeps most of its
    gain."""
    lo, hi = 0.0, 1.0
    for _ in range(REPAIR_STEPS):
        mid = 0.5 * (lo + hi)
        if feasible(good + mid * (bad - good), G, h, nonlinear):
            lo = mid
        else:
            hi = mid
    return good + lo * (bad - good)
