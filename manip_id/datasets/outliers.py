"""Isolated bad rows: corrupted time stamps and position spikes, found robustly.

A 5-point running median (edges padded with the nearest value) follows a smooth or
steadily increasing signal to within one sample-to-sample step, and is not moved by
one or two wild rows. A time stamp, or a position of joint ``j``, is bad when it leaves
its running median by more than

    max(SPIKE_FACTOR s, floor),    s = median|d| + 1.4826 MAD(d)

with ``d`` the differences of the column along the block: a robust scale of the steps
(``t = 2.68e154`` among 5 ms steps, a position of 253 rad among 1e-3 rad steps). The
floor is 0 for time and :data:`SPIKE_FLOOR` for positions (quantised encoders at rest).
A median of 5 removes runs of up to two bad rows; at the two first and last rows of a
block the padding hides a spike (the reader's blocks hold 32768 rows), except that a
block's first stamps must come after the last kept one.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

#: Rows of the running median.
WINDOW = 5
#: A position spike leaves its running median by this many robust motion scales ...
SPIKE_FACTOR = 20.0
#: ... and by at least this much [rad or m] (quantised encoders at rest).
SPIKE_FLOOR = 0.01


def _off_median(x: np.ndarray, floor: float) -> np.ndarray:
    """Cells of ``x`` (k, m) farther from their running median than their limit."""
    d = np.diff(x, axis=0)
    med = np.median(d, axis=0)
    scale = np.median(np.abs(d), axis=0) + 1.4826 * np.median(np.abs(d - med), axis=0)
    limit = np.maximum(SPIKE_FACTOR * scale, floor)
    return np.abs(x - median_filter(x, size=(WINDOW, 1), mode="nearest")) > limit


def bad_time_stamps(t, previous: float | None = None) -> np.ndarray:
    """Rows whose time stamp is corrupted (module docstring), shape (k,); with
    ``previous`` (the last kept stamp before this block [s]) also the first rows that do
    not come after it."""
    t = np.asarray(t, dtype=float)
    if t.size < WINDOW:
        return np.zeros(t.shape, dtype=bool)
    bad = _off_median(t[:, None], 0.0)[:, 0]
    if previous is not None:
        head = WINDOW // 2
        bad[:head] |= t[:head] <= previous
    return bad


def position_spikes(q) -> np.ndarray:
    """Rows holding a position spike in some joint (module docstring), shape (k,)."""
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[0] < WINDOW:
        return np.zeros(q.shape[:1], dtype=bool)
    return np.asarray(_off_median(q, SPIKE_FLOOR).any(axis=1))


__all__ = ["SPIKE_FACTOR", "SPIKE_FLOOR", "WINDOW", "bad_time_stamps", "position_spikes"]
