"""Preprocessing in overlapping blocks: a stream of rows of any length in O(block) memory.

The identity that makes a block equal the whole series to round-off, and the margins it
needs, are stated in :mod:`manip_id.signals`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DataError
from .filters import Lowpass
from .preprocess import PreprocessSettings, SignalOptions, preprocess_plan
from .sampling import JITTER_TOLERANCE, derivative, uniform_grid

#: Rows of raw samples on each side of a block for the blocked cubic spline:
#: a knot's influence decays like (2 - sqrt 3)^d, below 1e-36 at d = 64.
SPLINE_MARGIN = 64
#: Default rows per block of :func:`preprocess_blocks`.
DEFAULT_BLOCK = 1 << 15


def overlap_margin(filt: Lowpass, tol: float = 1e-16) -> int:
    """Rows of margin after which a block filter equals the whole-series filter (see top).

    ``ceil(log(tol) / log(r))`` with ``r`` the largest one-way pole radius of
    ``filt``, times 1.25 for the polynomial factors of clustered poles, plus
    the padding of ``sosfiltfilt`` and a few rows for the central differences.
    """
    r = float(np.max(np.abs(filt.poles)))
    decay = math.ceil(math.log(tol) / math.log(r)) if 0 < r < 1 else 0
    return int(1.25 * decay) + 3 * (2 * filt.sos.shape[0] + 1) + 8


@dataclass(frozen=True)
class OverlapWindow:
    """One window of :func:`iter_overlapping`.

    ``rows`` holds series rows ``lo:lo + len(rows)``; the block is ``a:b``
    (global row indices), ``at_end`` tells whether ``b`` is the series' end.
    """

    rows: np.ndarray
    lo: int
    a: int
    b: int
    at_end: bool

    @property
    def centre(self) -> slice:
        """The block's rows within ``rows``."""
        return slice(self.a - self.lo, self.b - self.lo)


def iter_overlapping(chunks, block: int, margin: int, *, start: int = 0, first: int | None = None):
    """Cut a stream of row chunks (2-D arrays) into blocks with ``margin`` rows each side.

    Yields :class:`OverlapWindow` for consecutive blocks ``[a, b)`` covering
    every row once; each window holds rows ``[max(a - margin, 0), min(b +
    margin, N))``. The length N need not be known: the stream is read ahead
    by ``block + margin`` rows at most, so memory is O(block + 2 margin).
    ``start``: a multiple of ``block``, the first block's row; ``first`` (``<= start``,
    default ``max(start - margin, 0)``): the series row of the stream's first row. With the
    default the windows are those of the whole series from that block on (the same rows at
    the same places); a later ``first`` cuts the first windows short at it.
    """
    block, margin = max(int(block), 1), max(int(margin), 0)
    first = max(int(start) - margin, 0) if first is None else int(first)
    if start % block or not 0 <= first <= start:
        raise ValueError(
            f"start must be a multiple of the block ({block}) and first in [0, start], "
            f"got start={start}, first={first}"
        )
    it = iter(chunks)
    parts: list[np.ndarray] = []
    buf_lo = buf_hi = first
    exhausted = False
    a = int(start)
    while True:
        while not exhausted and buf_hi < a + block + margin:
            nxt = next(it, None)
            if nxt is None:
                exhausted = True
            elif nxt.shape[0]:
                parts.append(nxt)
                buf_hi += nxt.shape[0]
        if exhausted:
            b, hi = min(a + block, buf_hi), buf_hi
        else:
            b, hi = a + block, a + block + margin
        if b <= a:
            return
        buf = np.concatenate(parts) if len(parts) > 1 else parts[0]
        parts = [buf]
        lo = max(a - margin, first)
        at_end = exhausted and b == buf_hi
        yield OverlapWindow(buf[lo - buf_lo : hi - buf_lo], lo, a, b, at_end)
        if at_end:
            return
        a = b
        keep = max(a - margin, first)
        if keep > buf_lo:
            parts = [buf[keep - buf_lo :]]
            buf_lo = keep


def resample_windows(windows, cols: slice, t0: float, rate: float, n_grid: int, kind: str):
    """Blocked cubic-spline resampling: grid points ``t0 + k / rate`` in each block's span."""
    from scipy.interpolate import CubicSpline  # heavy (0.13 s): only when resampling

    k_next = 0
    for w in windows:
        t = w.rows[:, 0]
        t_hi = np.inf if w.at_end else w.rows[w.b - w.lo, 0]
        k_stop = n_grid
        if not w.at_end:  # first k with t0 + k / rate >= t_hi
            k_stop = min(int(math.floor((t_hi - t0) * rate)) + 2, n_grid)
            while k_stop > k_next and t0 + (k_stop - 1) / rate >= t_hi:
                k_stop -= 1
        if k_stop <= k_next:
            continue
        t_new = t0 + np.arange(k_next, k_stop) / rate
        x = w.rows[:, cols]
        if kind == "cubic":
            values = CubicSpline(t, x, axis=0)(t_new)
        else:
            values = np.stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])], axis=1)
        yield np.column_stack([t_new, values])
        k_next = k_stop


@dataclass(frozen=True)
class StreamStats:
    """The time statistics of a whole stream, from a pass before the blocked one.

    Attributes
    ----------
    n : int
        Number of rows.
    t_first, t_last : float
        First and last stamp [s].
    dt_min, dt_max : float
        Smallest and largest step [s].
    """

    n: int
    t_first: float
    t_last: float
    dt_min: float
    dt_max: float

    @classmethod
    def of(cls, t) -> StreamStats:
        """The statistics of stamps ``t`` [s], shape (N,), N >= 2."""
        t = np.asarray(t, dtype=float)
        d = np.diff(t)
        return cls(int(t.shape[0]), float(t[0]), float(t[-1]), float(d.min()), float(d.max()))

    def plan(self, options: SignalOptions) -> tuple[Lowpass, PreprocessSettings]:
        """Whether the stream is resampled, its filter and settings, as :func:`preprocess`
        decides them from the whole array."""
        n, t_first, t_last = self.n, self.t_first, self.t_last
        if n < 2:
            raise DataError(f"need at least 2 samples to preprocess, got {n}")
        mean_dt = (t_last - t_first) / (n - 1)
        jitter = max(self.dt_max - mean_dt, mean_dt - self.dt_min)
        uniform = jitter <= JITTER_TOLERANCE * abs(mean_dt)
        resampled = options.rate is not None or not uniform
        rate = options.rate
        fs = float((n - 1) / (t_last - t_first)) if rate is None else float(rate)
        return preprocess_plan(fs, resampled, options)


def preprocess_blocks(
    chunks,
    nq: int,
    nv: int,
    stats: StreamStats,
    *,
    options: SignalOptions | None = None,
    block: int = DEFAULT_BLOCK,
    n_temp: int = 0,
    start: int = 0,
    first_row: int | None = None,
):
    """:func:`preprocess` on a stream of packed rows, block by block; equal to it to round-off.

    Parameters
    ----------
    chunks : iterable of numpy.ndarray
        Packed rows ``t | q (nq) | dq (nv) | tau (nv) [| ddq] [| temp (n_temp)]``
        (:class:`manip_id.datasets.Layout`); a ddq column block is ignored.
    nq, nv : int
        Sizes of the q and dq column blocks.
    stats : StreamStats
        Number of rows, first and last stamp, smallest and largest step of the whole
        stream (one pass of statistics before this one decides the grid, as
        :func:`preprocess` decides it from the whole array).
    options : SignalOptions, optional
        Cut-off, order, rate, decimation, trim, velocity and torque filtering, as
        :func:`preprocess`; default ``SignalOptions()``.
    block : int
        Rows per block (memory is O((block + 2 margin) * width)).
    n_temp : int
        Temperature columns, the last ``n_temp`` of each row (0: none): resampled and
        low-pass filtered as q, carried after ddq.
    start : int
        The first output row wanted; ``chunks`` then begin at input row
        :func:`read_start` ``(stats, options, block, start)``, and the rows yielded are
        the whole stream's from row ``start`` on, bit for bit.
    first_row : int or None
        The input row of the chunks' first row (default :func:`read_start`; a later one
        gives the first rows without their full filter margin).

    Returns
    -------
    tuple
        ``(settings, blocks)``: the :class:`PreprocessSettings` (known before any row
        is read) and an iterator of packed rows ``t | q | dq | tau | ddq [| temp]`` after
        filtering, differentiation, trimming and decimation. Each block is computed on
        rows with :func:`overlap_margin` rows of margin on both sides (the identity of
        :mod:`manip_id.signals`), so the concatenated output equals ``preprocess`` of
        the whole series to round-off.
    """
    options = SignalOptions() if options is None else options
    filt, settings = stats.plan(options)
    width_in, n_temp = 1 + nq + 2 * nv, int(n_temp)

    def fields(c: np.ndarray) -> np.ndarray:  # t | q | dq | tau [| temp]
        return (
            np.hstack([c[:, :width_in], c[:, c.shape[1] - n_temp :]]) if n_temp else c[:, :width_in]
        )

    if settings.resampled:
        n_uniform = uniform_grid(stats.t_first, stats.t_last, settings.rate).shape[0]
        stream = (fields(c) for c in chunks)
        windows = iter_overlapping(stream, block, SPLINE_MARGIN)
        cols = slice(1, width_in + n_temp)
        uniform_rows = resample_windows(
            windows, cols, stats.t_first, settings.rate, n_uniform, "cubic"
        )
    else:
        n_uniform = stats.n
        uniform_rows = (fields(c) for c in chunks)
    n_trim = settings.trim
    if n_trim < 0 or 2 * n_trim > n_uniform - 2:
        raise DataError(
            f"trimming {float(n_trim):.4g} + {float(n_trim):.4g} samples leaves fewer than 2 of "
            f"{n_uniform}"
        )
    D, margin = int(options.decimate), overlap_margin(filt)
    cut = _Cut(nq, nv, n_trim + int(start) * D, n_uniform - n_trim, D, margin, n_temp)
    a0 = _first_block(stats, options, block, start)
    first = max(a0 - margin, 0) if first_row is None else int(first_row)
    if settings.resampled and first:
        raise DataError(f"a resampled stream is read from its first row, not row {first}")
    return settings, cut.blocks(uniform_rows, filt, options, block, (a0, first))


def read_start(stats: StreamStats, options: SignalOptions, block: int, start: int) -> int:
    """The first input row :func:`preprocess_blocks` needs for its output from row ``start``.

    Output row ``s`` is uniform row ``u = trim + s D`` (``D`` the decimation), computed in
    the block ``a = block floor(u / block)`` on rows ``[a - m, a + block + m)`` (``m``:
    :func:`overlap_margin`, the filter's transient and padding plus the difference
    stencil). Reading from ``max(a - m, 0)`` gives the same windows as the whole stream,
    hence the same rows bit for bit. A resampled stream (non-uniform stamps or a rate)
    starts at 0: its spline windows are laid on the input rows, which do not map to grid
    rows without reading them.
    """
    filt, _ = stats.plan(options)
    return max(_first_block(stats, options, block, start) - overlap_margin(filt), 0)


def _first_block(stats: StreamStats, options: SignalOptions, block: int, start: int) -> int:
    """The uniform row of the block holding output row ``start`` (0 when resampled)."""
    _, settings = stats.plan(options)
    if start <= 0 or settings.resampled:
        return 0
    block = max(int(block), 1)
    u = settings.trim + int(start) * int(options.decimate)
    return (u // block) * block


@dataclass(frozen=True)
class _Cut:
    """Where the columns are and which rows are kept (trim, decimation)."""

    nq: int
    nv: int
    start: int  # first kept row of the uniform stream (the trim, or the first row wanted)
    stop: int  # one past the last kept row
    step: int  # decimation
    margin: int  # rows of margin on each side of a block (:func:`overlap_margin`)
    n_temp: int = 0  # temperature columns after tau (filtered as q, carried after ddq)

    def blocks(self, uniform_rows, filt: Lowpass, options: SignalOptions, block: int, at):
        """Filtered, differentiated, trimmed and decimated rows ``t | q | dq | tau | ddq``
        (``at = (a0, first)``: ``uniform_rows`` from row ``first``, the first block at ``a0``)."""
        nq, nv, D = self.nq, self.nv, self.step
        sq, sdq = slice(1, 1 + nq), slice(1 + nq, 1 + nq + nv)
        stau = slice(1 + nq + nv, 1 + nq + 2 * nv)
        differentiate = options.velocity == "differentiate"
        # the filtered columns in one contiguous run: q, dq (when measured, or to reach tau),
        # tau (when filtered); a column filtered but unused costs less than a second call
        hi_f = stau.stop if options.filter_torque else (sq.stop if differentiate else sdq.stop)
        fq, fdq, ftau = (slice(s.start - sq.start, s.stop - sq.start) for s in (sq, sdq, stau))
        a0, first_row = at
        for w in iter_overlapping(uniform_rows, block, self.margin, start=a0, first=first_row):
            lo_keep, hi_keep = max(w.a, self.start), min(w.b, self.stop)
            if hi_keep <= lo_keep:
                continue
            rows = w.rows
            t = rows[:, 0]
            # one filter call on every filtered column (each column is filtered on its own)
            y = filt(rows[:, sq.start : hi_f])
            q = y[:, fq]
            dq = derivative(t, q) if differentiate else y[:, fdq]
            tau = y[:, ftau] if options.filter_torque else rows[:, stau]
            ddq = derivative(t, dq)
            first = lo_keep + (-(lo_keep - self.start)) % D  # first kept global index >= lo_keep
            idx = slice(first - w.lo, hi_keep - w.lo, D)  # views: one copy, by the stack
            if hi_keep > first:
                out = [t[idx], q[idx], dq[idx], tau[idx], ddq[idx]]
                if self.n_temp:  # slow: the same zero-phase filter as q
                    out.append(filt(rows[:, stau.stop : stau.stop + self.n_temp])[idx])
                yield np.column_stack(out)
