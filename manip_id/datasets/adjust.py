"""Adjustments of a file's streams stated by the user: the unit of its time stamps, the
delay of its torque stream, and the plausible range of its sampling rate.

Time unit (``FileSpec.time_unit``, ``--time-unit s|ms|us|ns``): the stamps are
multiplied by the unit's factor :data:`TIME_UNITS` before anything else reads them,
so windows ``FILE@START:STOP`` are in seconds of the converted time.

Delay (``FileSpec.delay``, ``--delay SECONDS`` or one value per joint): the torque
stream lags the motion stream by ``d_j`` [s], i.e. the row stamped ``t_k`` holds the
torque of ``t_k - d_j``. The adjusted rows pair the motion of ``t_k`` with the torque
read at ``t_k + d_j``, linearly interpolated between the finite rows::

    tau_j'(t_k) = tau_j(t_k + d_j)

Rows whose shifted stamp leaves the file (the last ``d_j`` seconds for ``d_j > 0``, the
first ``|d_j|`` for ``d_j < 0``) have no torque and are left out; row indices (windows
``@#A:#B``) keep counting the file's rows. A delay that is a whole number of steps on a
uniform grid moves the torques by whole rows (exact to round-off of the stamps).

Rate (:func:`check_rate`): a median step giving a rate below :data:`RATE_MIN` or above
:data:`RATE_MAX` is refused, naming the unit that would make it plausible.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from ..errors import DataError, InputError

#: Seconds per unit of the time stamps.
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
#: Plausible sampling rates [Hz] of a robot log.
RATE_MIN, RATE_MAX = 1.0, 1e5


def check_time_unit(unit) -> str | None:
    """``unit`` if one of :data:`TIME_UNITS` (or None), else :class:`InputError`."""
    if unit is None:
        return None
    unit = str(unit).strip().lower()
    if unit not in TIME_UNITS:
        raise InputError(f"time unit must be one of {', '.join(TIME_UNITS)}, got {unit!r}")
    return unit


#: The largest magnitude of a signal delay [s] (``--delay``): a sensor's lag, not a shift
#: of the record.
MAX_DELAY = 60.0


def delay_vector(delay, nv: int, what: str = "--delay") -> np.ndarray | None:
    """Per-joint delays [s], shape (nv,), from one value or nv values (None: no delay)."""
    if delay is None:
        return None
    arr = np.atleast_1d(np.asarray(delay, dtype=float))
    if arr.ndim != 1 or arr.size not in (1, nv):
        raise InputError(f"{what} takes one value or one per joint ({nv}), got {arr.size} values")
    if not np.isfinite(arr).all() or np.abs(arr).max() > MAX_DELAY:
        raise InputError(
            f"{what} must be finite seconds of magnitude <= {MAX_DELAY:g} (a sensor's delay), "
            f"got {arr.tolist()}"
        )
    return np.broadcast_to(arr, (nv,)).copy()


def likely_time_unit(step: float) -> str | None:
    """The unit of :data:`TIME_UNITS` that makes a median step ``step`` a plausible rate,
    nearest to 1 kHz, or None when none does."""
    best, best_dist = None, math.inf
    for unit, factor in TIME_UNITS.items():
        if not step > 0:
            break
        rate = 1.0 / (step * factor)
        if RATE_MIN <= rate <= RATE_MAX and abs(math.log10(rate) - 3.0) < best_dist:
            best, best_dist = unit, abs(math.log10(rate) - 3.0)
    return best


def check_rate(step: float, label: str, unit: str | None = None) -> float:
    """The rate ``1 / step`` [Hz] of a median step [s], refused outside [RATE_MIN, RATE_MAX].

    ``unit``: the unit the user stated (None: seconds assumed). The message names the
    unit that would make the rate plausible (``--time-unit ns``).
    """
    rate = 1.0 / step if step > 0 else math.inf
    if RATE_MIN <= rate <= RATE_MAX:
        return rate
    stated = unit or "s"
    raw_step = step / TIME_UNITS[stated]
    guess = likely_time_unit(raw_step)
    hint = (
        f"stamps in {guess}? pass --time-unit {guess}"
        if guess is not None and guess != stated
        else "stamps in other units, or sample indices instead of times?"
    )
    raise DataError(
        f"{label}: the median time step {raw_step:.6g} [{stated}] gives a sampling rate of "
        f"{rate:.3g} Hz, outside the plausible {RATE_MIN:g} Hz .. {RATE_MAX:g} Hz: {hint}"
    )


class AdjustedSource:
    """A source (see :mod:`~.stream`) with its stamps converted and its torques shifted.

    ``factor``: seconds per stamp unit; ``delay``: per-joint delays [s], shape (nv,), or
    None. Same attributes as the wrapped source; ``n_rows`` is None with a delay.
    """

    def __init__(self, inner, factor: float = 1.0, delay: np.ndarray | None = None):
        self.inner = inner
        self.path = inner.path
        self.format = inner.format
        self.layout = inner.layout
        self.joint_names = inner.joint_names
        self.factor = float(factor)
        self.delay = None if delay is None or not np.any(delay) else np.asarray(delay, float)
        self.n_rows = inner.n_rows if self.delay is None else None
        self.malformed = getattr(inner, "malformed", {})

    def chunks(self, chunk: int, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        if self.delay is None:
            for block in self.inner.chunks(chunk, start, stop):
                yield self._convert(block)
            return
        for raw, block in _shifted(self._blocks(chunk), self.layout, self.delay):
            keep = raw >= start
            if stop is not None:
                keep &= raw < stop
            if keep.any():
                yield block[keep]
            if stop is not None and raw.size and raw[-1] >= stop - 1:
                return

    def _convert(self, block: np.ndarray) -> np.ndarray:
        if self.factor == 1.0:
            return block
        block = block.copy()
        block[:, 0] *= self.factor
        return block

    def _blocks(self, chunk: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        row = 0
        for block in self.inner.chunks(chunk, 0, None):
            yield np.arange(row, row + block.shape[0]), self._convert(block)
            row += block.shape[0]


def _shifted(blocks, layout, delay: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``(raw_rows, rows)`` with ``tau_j(t_k + d_j)`` (see the module docstring).

    A buffer holds the rows not yet emitted and those the interpolation still needs
    (``|min(d, 0)|`` seconds back); a row is emitted once ``t_k + max(d, 0)`` has been read.
    """
    s_tau = layout.slices["tau"]
    d_hi, d_lo = max(float(delay.max()), 0.0), min(float(delay.min()), 0.0)
    buf = np.empty((0, layout.width))
    rows = np.empty(0, dtype=np.int64)
    done = 0  # buffer index of the first row not yet emitted
    t_first = None
    for raw, block in blocks:
        buf, rows = np.vstack([buf, block]), np.concatenate([rows, raw])
        good = np.isfinite(buf).all(axis=1)
        if not good.any():
            continue
        tg = buf[good, 0]
        if t_first is None:
            t_first = float(tg[0])
        t_end = float(tg[-1])
        t = buf[:, 0]
        ready = np.arange(done, buf.shape[0])
        late = ~((t[ready] + d_hi <= t_end) | ~np.isfinite(t[ready]))
        ready = ready[: int(np.argmax(late)) if late.any() else ready.size]  # a prefix
        if ready.size:
            out = buf[ready].copy()
            ok = good[ready] & (t[ready] + d_lo >= t_first)
            for j, d in enumerate(delay):
                col = s_tau.start + j
                out[ok, col] = np.interp(t[ready][ok] + d, tg, buf[good, col])
            keep = ok | ~good[ready]  # a bad row passes as it is (refused or dropped later)
            if keep.any():
                yield rows[ready][keep], out[keep]
            done = int(ready[-1]) + 1
        if done < buf.shape[0]:
            need = float(t[done]) + d_lo
        else:
            need = t_end + d_lo
        gi = np.flatnonzero(good)
        k = int(np.searchsorted(t[gi], need, side="right")) - 2  # one finite row before
        lo = min(int(gi[k]) if k >= 0 else 0, done)
        if lo > 0:
            buf, rows, done = buf[lo:], rows[lo:], done - lo
