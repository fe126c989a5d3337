"""One pass over a file's rows for the audit: whole-file figures, and the central rows.

The audit's whole-file figures need the time stamps and positions of every row
(encoder resolution, position findings, the rest at the edges, the rate) and, per
joint, only the count of rows at rest ``|dq_j| < eps``; its torque fits need all the
fields of the central :data:`FIT_ROWS` rows. :func:`read_pass` reads the rows once, as
the fit sees them, and keeps ``t`` and ``q`` of all rows, the standstill counts, the
first and last moving row, the sums of the torques, and the other fields only of the
rows that can still be central: after ``n`` rows the central window of the file (of
``N >= n`` rows) starts at ``(N - FIT_ROWS) // 2 >= (n - FIT_ROWS) // 2``, so the rows
before that are let go. The fields held are about a quarter of the whole file's.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..datasets import Dataset

#: Rows of the torque fits (scale, offset, delay): a longer moving file is fitted on its
#: central rows. These are constants of the setup along a log, and the fits' cost
#: (filtering, ``rnea`` per row, robust fits, the delay search) grows with the rows: on
#: 10^6 rows of a simulated ur10 log (experiments/bench_identify.py --user) all rows took
#: 10 s and 0.6 GB, 2e5 rows 2.6 s, 5e4 rows 0.8 s, with the same findings (none), the
#: scales within 3e-4 of each other and the delays within one sample.
FIT_ROWS = 50_000


@dataclass
class AuditRows:
    """What the audit keeps of one file's rows (:func:`read_pass`).

    Attributes
    ----------
    t : np.ndarray
        Time stamps of all rows [s], shape (N,).
    q : np.ndarray
        Positions of all rows, shape (N, nq).
    still : np.ndarray
        Per joint, the share of the rows with ``|dq_j| < eps``, shape (nv,).
    moving : tuple[int, int] | None
        First and last row where some joint moves (None: none moves).
    tau_mean : np.ndarray
        Mean measured torque of all rows, shape (nv,).
    central : Dataset
        The central :data:`FIT_ROWS` rows (all rows of a shorter file).
    """

    t: np.ndarray
    q: np.ndarray
    still: np.ndarray
    moving: tuple[int, int] | None
    tau_mean: np.ndarray
    central: Dataset

    @property
    def n_samples(self) -> int:
        """Number of rows N."""
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """``t[-1] - t[0]`` [s]."""
        return float(self.t[-1] - self.t[0])


def read_pass(rows, layout, joint_names, eps: float, capacity: int | None = None) -> AuditRows:
    """:class:`AuditRows` of the packed row blocks ``rows`` (one pass; see the module
    docstring); ``eps`` is the standstill speed [rad/s or m/s]. ``capacity``: at most that
    many rows come (the source's row count, when known): ``t`` and ``q`` are then filled in
    place without growing."""
    held: list = []  # (first row, fields) of the blocks that may be central
    buf = _Positions(capacity or 0, layout.nq)
    n, still, tau_sum = 0, np.zeros(layout.nv), np.zeros(layout.nv)
    first = last = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # degrees: a finding of the audit
        for block in rows:
            f = layout.unpack(block)
            k = block.shape[0]
            buf.add(f["t"], f["q"])
            rest = np.abs(f["dq"]) < eps
            still += rest.sum(axis=0)
            tau_sum += f["tau"].sum(axis=0)
            moves = np.flatnonzero(~rest.all(axis=1))
            if moves.size:
                first = n + int(moves[0]) if first is None else first
                last = n + int(moves[-1])
            keep = {
                m: np.array(f[m], dtype=float, order="C") for m in ("dq", "tau", "ddq") if m in f
            }
            held.append((n, keep))
            n += k
            bound = (n - FIT_ROWS) // 2
            while held and held[0][0] + next(iter(held[0][1].values())).shape[0] <= bound:
                held.pop(0)
    t = buf.t[: buf.n]
    start = (n - FIT_ROWS) // 2 if n > FIT_ROWS else 0
    stop = min(n, start + FIT_ROWS)
    fields, parts = {}, []
    for m in ("dq", "tau", "ddq"):
        parts = [v[m][max(0, start - s) : max(0, stop - s)] for s, v in held if m in v]
        if parts:
            fields[m] = np.concatenate(parts, axis=0)
    del held, parts  # before the positions are joined: the peak is about two copies of q
    if "dq" not in fields:
        fields = {m: np.empty((0, layout.nv)) for m in ("dq", "tau")}
    q = buf.q[: buf.n]
    del buf
    central = Dataset(
        t=t[start:stop],
        q=q[start:stop].copy(),  # its own rows: the whole q can be freed
        dq=fields["dq"],
        tau=fields["tau"],
        ddq=fields.get("ddq"),
        joint_names=joint_names,
    )
    moving = None if first is None or last is None else (first, last)
    return AuditRows(t, q, still / max(n, 1), moving, tau_sum / max(n, 1), central)


class _Positions:
    """``t`` and ``q`` of a pass, filled in place: the arrays grow by doubling when a block
    does not fit (``capacity``: the rows expected, e.g. the source's count; 0: unknown).
    Their pages are touched only as rows come, so the resident memory is about one copy of
    the rows, not the blocks and their concatenation."""

    def __init__(self, capacity: int, nq: int):
        self.t = np.empty(max(int(capacity), 0))
        self.q = np.empty((max(int(capacity), 0), nq))
        self.n = 0

    def add(self, t, q) -> None:
        k = len(t)
        if self.n + k > self.t.shape[0]:
            size = max(2 * self.t.shape[0], self.n + k, 4096)
            t_new, q_new = np.empty(size), np.empty((size, self.q.shape[1]))
            t_new[: self.n], q_new[: self.n] = self.t[: self.n], self.q[: self.n]
            self.t, self.q = t_new, q_new
        self.t[self.n : self.n + k] = t
        self.q[self.n : self.n + k] = q
        self.n += k
