"""Signal processing of measured data: resampling, zero-phase low-pass, differentiation.

The path from a raw log to data fit for identification (:func:`preprocess`)::

    raw (t_k non-uniform) --resample--> uniform grid, rate f_s [Hz]
        --low-pass (zero phase)--> q_f, dq_f, tau_f
        --central differences--> ddq = d(dq_f)/dt
        --trim edge transients--> --decimate by D--> Dataset with ddq

Zero-phase low-pass. A Butterworth filter of order ``n`` and cut-off ``f_c``
[Hz], run forward and backward (``scipy.signal.sosfiltfilt``), has no phase
lag and the squared magnitude of the one-way filter::

    |H_ff(f)| = |H(f)|^2 = 1 / (1 + (tan(pi f / f_s) / tan(pi f_c / f_s))^(2 n))

so a component at ``f_c`` keeps half its amplitude (-6 dB), one at ``f << f_c``
passes with unit gain, and above ``f_c`` the attenuation grows by
``40 n`` dB per decade (twice the one-way ``20 n``).

Differentiation. Central differences ``x'(t_k) ~ (x_{k+1} - x_{k-1}) /
(t_{k+1} - t_{k-1})`` (second order, also on non-uniform stamps, one-sided
second-order at the ends: ``numpy.gradient``). Differencing amplifies noise
by ``~ 2 pi f`` at frequency ``f``: differentiate filtered signals only.

Parallel filtering. A linear time-invariant filter ``F`` commutes with the
linear model: ``F[tau] = F[Y theta] = F[Y] theta``. Filtering the torques and
every regressor column with the same low-pass (:func:`filter_regressor`)
therefore removes torque noise above ``f_c`` without biasing ``theta``, and
makes decimation after it alias-free. Use it when the torques must be filtered
more heavily than the states (noisy torque sensors, decimation of a long log)
or when the regressor has terms that are not smooth in the states, such as
Coulomb friction ``sign(dq)``: filtering ``tau`` alone smooths the friction
steps while the ``sign(dq)`` column stays sharp, and the fit is biased;
filtering both keeps them consistent. :func:`preprocess` filters the states and
torques with one low-pass, which is the right choice whenever its cut-off is
well above the motion's bandwidth.

Overlapping blocks (streamed logs). Let ``F`` be the forward-backward filter of
one-way poles ``p_i`` and ``r = max |p_i| < 1``. For a series ``x`` of N samples
and a block of rows ``[a, b)`` read with ``M`` rows of margin on both sides,
``W = [max(a - M, 0), min(b + M, N))``, the identity this module relies on is::

    | F[x_W](k) - F[x](k) |  <=  C r^M max|x|        for a <= k < b

because the two filtered series differ only by the responses to their edge
conditions (start-up state and end padding), which decay like ``r^d`` over
``d`` samples, and a block that touches an end of the series is padded there
exactly as the whole series is. With ``M = ceil(log(1e-16) / log(r))`` plus
safety (:func:`overlap_margin`) the block filter equals the whole-series filter
at its centre to round-off; central differences and the not-a-knot cubic
spline of :func:`resample` (whose dependence on a knot ``d`` samples away decays
like ``(2 - sqrt 3)^d``) are blocked the same way. :func:`iter_overlapping`
cuts a stream of rows into such windows and :func:`preprocess_blocks` runs the
whole of :func:`preprocess` on them, in memory O(block + margin) whatever N.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ._checks import as_float_array
from .datasets import Dataset
from .errors import DataError, InputError

#: Default cut-off [Hz] of :func:`preprocess` (chosen on the real Panda log, see its docstring).
DEFAULT_CUTOFF = 3.0
#: Default Butterworth order of :func:`preprocess`.
DEFAULT_ORDER = 4
#: Relative jitter of the sampling period above which :func:`preprocess` resamples.
JITTER_TOLERANCE = 1e-6


# --------------------------------------------------------------- the low-pass
@dataclass(frozen=True)
class Lowpass:
    """A zero-phase Butterworth low-pass filter (forward-backward, second-order sections).

    Attributes
    ----------
    cutoff: cut-off frequency f_c [Hz], 0 < f_c < rate / 2; the forward-backward
        gain there is 1/2.
    rate: sampling rate f_s [Hz].
    order: order n of the one-way Butterworth filter (the forward-backward
        filter has twice its attenuation in dB).
    """

    cutoff: float
    rate: float
    order: int = DEFAULT_ORDER

    def __post_init__(self):
        rate = float(self.rate)
        cutoff = float(self.cutoff)
        if not (math.isfinite(rate) and rate > 0):
            raise InputError(f"sampling rate must be positive [Hz], got {self.rate}")
        if not (math.isfinite(cutoff) and 0 < cutoff < rate / 2):
            raise InputError(
                f"cut-off must be in (0, rate/2) = (0, {rate / 2:g}) Hz, got {self.cutoff}"
            )
        if int(self.order) != self.order or not 1 <= int(self.order) <= 20:
            raise InputError(f"Butterworth order must be an integer in [1, 20], got {self.order}")
        object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "cutoff", cutoff)
        object.__setattr__(self, "order", int(self.order))

    @cached_property
    def sos(self) -> np.ndarray:
        """Second-order sections of the one-way filter, shape (ceil(n/2), 6)."""
        from scipy import signal as _signal

        return _signal.butter(self.order, self.cutoff, btype="low", fs=self.rate, output="sos")

    def gain(self, frequency) -> np.ndarray:
        """Forward-backward magnitude ``|H(f)|^2`` at ``frequency`` [Hz] (see module docstring)."""
        f = np.asarray(frequency, dtype=float)
        ratio = np.tan(np.pi * f / self.rate) / np.tan(np.pi * self.cutoff / self.rate)
        return 1.0 / (1.0 + ratio ** (2 * self.order))

    def transient_samples(self, tol: float = 1e-3) -> int:
        """Length of the edge transient in samples.

        The number of samples after which the one-way impulse response stays
        below ``tol`` times its peak: beyond it, the start-up (and, backward,
        the end) of the forward-backward filter no longer depends on how the
        signal was padded.
        """
        n = int(20 * self.rate / self.cutoff) + 64
        impulse = np.zeros(n)
        impulse[0] = 1.0
        from scipy import signal as _signal

        h = np.abs(_signal.sosfilt(self.sos, impulse))
        above = np.nonzero(h > tol * h.max())[0]
        return int(above[-1]) + 1

    def __call__(self, x, axis: int = 0) -> np.ndarray:
        """Filter ``x`` along ``axis`` (time), zero phase; returns a new array of x's shape."""
        x = np.asarray(x, dtype=float)
        if x.shape[axis] <= 3 * (2 * self.sos.shape[0] + 1):
            raise InputError(
                f"{x.shape[axis]} samples are too few to filter with order {self.order}: "
                f"need more than {3 * (2 * self.sos.shape[0] + 1)}"
            )
        from scipy import signal as _signal

        return _signal.sosfiltfilt(self.sos, x, axis=axis)


def lowpass(x, cutoff: float, rate: float, order: int = DEFAULT_ORDER, axis: int = 0) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` along ``axis`` (time).

    Parameters
    ----------
    x: signal sampled at ``rate``, any shape with time along ``axis``
    cutoff: cut-off frequency [Hz] (forward-backward gain 1/2 there)
    rate: sampling rate [Hz]
    order: Butterworth order of the one-way filter
    """
    return Lowpass(cutoff, rate, order)(x, axis=axis)


def filter_regressor(
    Y: np.ndarray, filt: Lowpass, *, block: int = 16, out: np.ndarray | None = None
) -> np.ndarray:
    """Parallel filtering: the low-pass ``filt`` applied to every column of a regressor, along time.

    Parameters
    ----------
    Y: stacked regressor, shape (N, nv, p), sample-major (as :func:`manip_id.regressor.regressor`
        returns it); time runs along axis 0.
    filt: the same :class:`Lowpass` applied to the torques (``filt(tau)``).
    block: number of parameter columns filtered at once; bounds the temporaries
        of ``sosfiltfilt`` to O(N * nv * block) besides the output.
    out: array of Y's shape to write into (may be ``Y`` itself, filtering in place).

    Returns
    -------
    F[Y], shape (N, nv, p), with ``F[Y] @ theta == filt(Y @ theta)`` up to rounding.
    The whole time series is needed (the filter runs backward), so N must fit in
    memory; for very long logs filter and decimate the log in overlapping windows.
    """
    Y = np.asarray(Y, dtype=float)
    if Y.ndim != 3:
        raise InputError(f"expected a stacked regressor of shape (N, nv, p), got Y.shape={Y.shape}")
    if out is None:
        out = np.empty_like(Y)
    elif out.shape != Y.shape:
        raise InputError(f"out.shape={out.shape} but Y.shape={Y.shape}")
    p = Y.shape[2]
    for c in range(0, p, max(int(block), 1)):
        s = slice(c, min(c + max(int(block), 1), p))
        out[:, :, s] = filt(Y[:, :, s], axis=0)
    return out


# ------------------------------------------------------- grids and derivatives
def sampling_rate(t) -> float:
    """Mean sampling rate ``(N - 1) / (t[-1] - t[0])`` [Hz] of time stamps ``t`` [s], shape (N,).

    On jittery stamps this keeps the number of samples when resampling (the
    median step of the real Panda log, 0.99 ms, would upsample its 1.02 ms mean).
    """
    t = as_float_array(t, "t", ndim=1)
    if t.shape[0] < 2:
        raise InputError(f"need at least 2 time stamps, got t.shape={t.shape}")
    if np.any(np.diff(t) <= 0):
        raise InputError("time stamps must increase strictly")
    return float((t.shape[0] - 1) / (t[-1] - t[0]))


def is_uniform(t, tol: float = JITTER_TOLERANCE) -> bool:
    """Whether the steps of ``t`` [s] agree with their mean within ``tol`` (relative)."""
    dt = np.diff(np.asarray(t, dtype=float))
    return bool(np.max(np.abs(dt - dt.mean())) <= tol * abs(dt.mean()))


def uniform_grid(t0: float, t1: float, rate: float) -> np.ndarray:
    """Time stamps ``t0 + k / rate`` [s] for k = 0.. while <= t1, shape (M,)."""
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"sampling rate must be positive [Hz], got {rate}")
    n = int(math.floor((t1 - t0) * rate * (1 + 1e-12))) + 1
    return t0 + np.arange(n) / rate


def resample(t, x, t_new, kind: str = "cubic") -> np.ndarray:
    """Values of ``x`` sampled at ``t`` interpolated at ``t_new`` (within [t[0], t[-1]]).

    Parameters
    ----------
    t: original time stamps [s], shape (N,), strictly increasing, possibly non-uniform
    x: samples, shape (N,) or (N, m)
    t_new: target time stamps [s], shape (M,)
    kind: ``"cubic"`` (not-a-knot cubic spline, exact on cubics) or ``"linear"``

    Returns
    -------
    shape (M,) or (M, m).
    """
    from scipy.interpolate import CubicSpline

    t = as_float_array(t, "t", ndim=1)
    x = as_float_array(x, "x", ndim=(1, 2))
    t_new = as_float_array(t_new, "t_new", ndim=1)
    if x.shape[0] != t.shape[0]:
        raise InputError(f"t.shape={t.shape} but x.shape={x.shape}")
    if t_new.size and (t_new[0] < t[0] - 1e-12 or t_new[-1] > t[-1] + 1e-12):
        raise InputError(f"t_new spans [{t_new[0]}, {t_new[-1]}] outside t's [{t[0]}, {t[-1]}]")
    if kind == "cubic":
        return CubicSpline(t, x, axis=0)(t_new)
    if kind == "linear":
        if x.ndim == 1:
            return np.interp(t_new, t, x)
        return np.stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])], axis=1)
    raise InputError(f"unknown interpolation kind {kind!r}; expected 'cubic' or 'linear'")


def derivative(t, x) -> np.ndarray:
    """Central-difference derivative dx/dt along axis 0.

    Parameters
    ----------
    t: time stamps [s], shape (N,) (uniform or not), or a scalar step dt [s]
    x: samples, shape (N,) or (N, m)

    Returns
    -------
    dx/dt of x's shape: second-order central differences inside, second-order
    one-sided differences at both ends (``numpy.gradient``, ``edge_order=2``).
    """
    x = np.asarray(x, dtype=float)
    if x.shape[0] < 3:
        raise InputError(f"need at least 3 samples to differentiate, got x.shape={x.shape}")
    spacing = np.asarray(t, dtype=float)
    if spacing.ndim == 1 and spacing.shape[0] != x.shape[0]:
        raise InputError(f"t.shape={spacing.shape} but x.shape={x.shape}")
    return np.gradient(x, spacing, axis=0, edge_order=2)


# --------------------------------------------------------------- on datasets
def resample_dataset(dataset: Dataset, rate: float | None = None, kind: str = "cubic") -> Dataset:
    """The dataset interpolated on the grid ``t[0] + k / rate`` (rate default: the mean rate)."""
    rate = sampling_rate(dataset.t) if rate is None else float(rate)
    t_new = uniform_grid(dataset.t[0], dataset.t[-1], rate)
    fields: dict = {
        name: resample(dataset.t, getattr(dataset, name), t_new, kind)
        for name in ("q", "dq", "tau", "ddq")
        if getattr(dataset, name) is not None
    }
    return replace(dataset, t=t_new, **fields, meta={**dataset.meta, "rate": rate})


def downsample(dataset: Dataset, factor: int) -> Dataset:
    """Every ``factor``-th sample. Only alias-free after a low-pass below ``rate / (2 factor)``."""
    if int(factor) != factor or factor < 1:
        raise InputError(f"decimation factor must be a positive integer, got {factor}")
    factor = int(factor)
    if factor == 1:
        return dataset
    s = slice(None, None, factor)
    return replace(
        dataset,
        t=dataset.t[s],
        q=dataset.q[s],
        dq=dataset.dq[s],
        tau=dataset.tau[s],
        ddq=None if dataset.ddq is None else dataset.ddq[s],
    )


def trim_samples(dataset: Dataset, start: int, stop: int | None = None) -> Dataset:
    """Drop ``start`` samples at the beginning and ``stop`` (default ``start``) at the end."""
    stop = start if stop is None else stop
    if start < 0 or stop < 0:
        raise InputError(f"trim counts must be >= 0, got {start}, {stop}")
    n = dataset.n_samples
    if start + stop > n - 2:
        raise DataError(f"trimming {start} + {stop} samples leaves fewer than 2 of {n}")
    return dataset.slice(start, n - stop)


@dataclass(frozen=True)
class PreprocessSettings:
    """What :func:`preprocess` did, kept in ``dataset.meta["preprocess"]``."""

    cutoff: float
    order: int
    rate: float
    resampled: bool
    velocity: str
    filter_torque: bool
    trim: int
    decimate: int


def _plan(
    fs: float,
    *,
    resampled: bool,
    cutoff: float,
    order: int,
    decimate: int,
    trim: float | None,
    velocity: str,
    filter_torque: bool,
) -> tuple[Lowpass, PreprocessSettings]:
    """The checked decimation, the filter and the settings of :func:`preprocess` and
    :func:`preprocess_blocks` at the rate ``fs`` [Hz] of the (resampled) data."""
    if int(decimate) != decimate or decimate < 1:
        raise InputError(f"decimation factor must be a positive integer, got {decimate}")
    if decimate > 1 and cutoff >= fs / (2 * decimate):
        raise InputError(
            f"cut-off {cutoff} Hz is not below the Nyquist frequency {fs / (2 * decimate):g} Hz "
            f"after decimating {fs:g} Hz by {decimate}: the result would alias"
        )
    filt = Lowpass(cutoff, fs, order)
    n_trim = filt.transient_samples() if trim is None else int(round(float(trim) * fs))
    settings = PreprocessSettings(
        cutoff=filt.cutoff,
        order=filt.order,
        rate=fs,
        resampled=resampled,
        velocity=velocity,
        filter_torque=filter_torque,
        trim=n_trim,
        decimate=int(decimate),
    )
    return filt, settings


def preprocess(
    dataset: Dataset,
    *,
    cutoff: float = DEFAULT_CUTOFF,
    order: int = DEFAULT_ORDER,
    rate: float | None = None,
    decimate: int = 1,
    trim: float | None = None,
    velocity: str = "measured",
    filter_torque: bool = True,
) -> Dataset:
    """Clean a measured dataset for identification; the result has ``ddq`` filled.

    Steps: (1) when the time stamps are not uniform (or ``rate`` is given),
    cubic-spline resampling on the grid ``t[0] + k / rate``
    (default rate: the mean one); (2) zero-phase
    Butterworth low-pass (``cutoff`` [Hz], ``order``) of q, dq and, with
    ``filter_torque``, tau; (3) ``ddq`` by central differences of the filtered
    dq; (4) removal of the filter's edge transients, ``trim`` seconds at each
    end; (5) keeping every ``decimate``-th sample.

    Parameters
    ----------
    dataset: measurements (ddq, if present, is replaced)
    cutoff: low-pass cut-off [Hz]. The default 3 Hz was chosen on the real
        Panda log (Fourier excitation up to 0.375 Hz, about 1 kHz): with 64 base
        parameters identified on its first 70 % (each part preprocessed alone,
        1 s trimmed at each end), the validation torque error is flat from 2 to
        5 Hz (0.75, 0.74, 0.76 %) and grows outside: 1.68 % at 1 Hz (the filter
        bites the motion's harmonics and velocity ramps), 1.07 % at 10 Hz and
        2.60 % at 20 Hz (differentiated noise in ddq, torque noise in the
        reference). See ``experiments/panda_real.py``.
    order: Butterworth order (forward-backward: twice the attenuation).
    rate: sampling rate of the uniform grid [Hz]; default the mean rate
        (:func:`sampling_rate`).
    decimate: keep every ``decimate``-th sample after filtering; needs
        ``cutoff < rate / (2 decimate)``.
    trim: seconds removed at each end; default the edge transient of the
        filter (:meth:`Lowpass.transient_samples`).
    velocity: ``"measured"`` filters the logged dq; ``"differentiate"``
        replaces it by the central-difference derivative of the filtered q.
    filter_torque: low-pass the torques with the same filter (default). Turn
        it off to parallel-filter them with the regressor instead
        (:func:`filter_regressor`).

    Returns
    -------
    A new :class:`Dataset` on the uniform grid with ``ddq`` [rad/s^2]; its
    ``meta["preprocess"]`` holds the :class:`PreprocessSettings` used.
    """
    if velocity not in ("measured", "differentiate"):
        raise InputError(f"velocity must be 'measured' or 'differentiate', got {velocity!r}")
    uniform = is_uniform(dataset.t)
    resampled = rate is not None or not uniform
    data = resample_dataset(dataset, rate) if resampled else dataset
    fs = sampling_rate(data.t) if not resampled else float(data.meta["rate"])
    filt, settings = _plan(
        fs,
        resampled=resampled,
        cutoff=cutoff,
        order=order,
        decimate=decimate,
        trim=trim,
        velocity=velocity,
        filter_torque=filter_torque,
    )
    n_trim = settings.trim
    q = filt(data.q)
    if velocity == "differentiate":
        dq = derivative(data.t, q)
    else:
        dq = filt(data.dq)
    ddq = derivative(data.t, dq)
    tau = filt(data.tau) if filter_torque else data.tau
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the degrees check already ran on the input
        out = replace(data, q=q, dq=dq, ddq=ddq, tau=tau)
    out = trim_samples(out, n_trim)
    out = downsample(out, decimate)
    return replace(out, meta={**dataset.meta, "preprocess": settings})


# ------------------------------------------------------- overlapping blocks
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
    from scipy import signal as _signal

    _, poles, _ = _signal.sos2zpk(filt.sos)
    r = float(np.max(np.abs(poles)))
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


def iter_overlapping(chunks, block: int, margin: int):
    """Cut a stream of row chunks (2-D arrays) into blocks with ``margin`` rows each side.

    Yields :class:`OverlapWindow` for consecutive blocks ``[a, b)`` covering
    every row once; each window holds rows ``[max(a - margin, 0), min(b +
    margin, N))``. The length N need not be known: the stream is read ahead
    by ``block + margin`` rows at most, so memory is O(block + 2 margin).
    """
    block, margin = max(int(block), 1), max(int(margin), 0)
    it = iter(chunks)
    parts: list[np.ndarray] = []
    buf_lo = buf_hi = 0
    exhausted = False
    a = 0
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
        lo = max(a - margin, 0)
        at_end = exhausted and b == buf_hi
        yield OverlapWindow(buf[lo - buf_lo : hi - buf_lo], lo, a, b, at_end)
        if at_end:
            return
        a = b
        keep = max(a - margin, 0)
        if keep > buf_lo:
            parts = [buf[keep - buf_lo :]]
            buf_lo = keep


def _resample_windows(windows, cols: slice, t0: float, rate: float, n_grid: int, kind: str):
    """Blocked cubic-spline resampling: grid points ``t0 + k / rate`` in each block's span."""
    from scipy.interpolate import CubicSpline

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


def preprocess_blocks(
    chunks,
    nq: int,
    nv: int,
    *,
    n: int,
    t_first: float,
    t_last: float,
    dt_min: float,
    dt_max: float,
    cutoff: float = DEFAULT_CUTOFF,
    order: int = DEFAULT_ORDER,
    rate: float | None = None,
    decimate: int = 1,
    trim: float | None = None,
    velocity: str = "measured",
    filter_torque: bool = True,
    block: int = DEFAULT_BLOCK,
):
    """:func:`preprocess` on a stream of packed rows, block by block; equal to it to round-off.

    Parameters
    ----------
    chunks: iterable of packed rows ``t | q (nq) | dq (nv) | tau (nv) [| ddq]``
        (:class:`manip_id.datasets.Layout`); a ddq column block is ignored.
    n, t_first, t_last, dt_min, dt_max: number of rows, first and last stamp
        [s], smallest and largest step [s] of the whole stream (one pass of
        statistics before this one decides the grid, as :func:`preprocess`
        decides it from the whole array).
    cutoff, order, rate, decimate, trim, velocity, filter_torque: as :func:`preprocess`.
    block: rows per block (memory is O((block + 2 margin) * width)).

    Returns
    -------
    ``(settings, blocks)``: the :class:`PreprocessSettings` (known before any
    row is read) and an iterator of packed rows ``t | q | dq | tau | ddq``
    after filtering, differentiation, trimming and decimation. Each block is
    computed on rows with :func:`overlap_margin` rows of margin on both sides
    (the identity at the top of this module), so the concatenated output equals
    ``preprocess`` of the whole series to round-off.
    """
    if velocity not in ("measured", "differentiate"):
        raise InputError(f"velocity must be 'measured' or 'differentiate', got {velocity!r}")
    if n < 2:
        raise DataError(f"need at least 2 samples to preprocess, got {n}")
    mean_dt = (t_last - t_first) / (n - 1)
    uniform = max(dt_max - mean_dt, mean_dt - dt_min) <= JITTER_TOLERANCE * abs(mean_dt)
    resampled = rate is not None or not uniform
    fs = float((n - 1) / (t_last - t_first)) if rate is None else float(rate)
    filt, settings = _plan(
        fs,
        resampled=resampled,
        cutoff=cutoff,
        order=order,
        decimate=decimate,
        trim=trim,
        velocity=velocity,
        filter_torque=filter_torque,
    )
    n_trim = settings.trim
    width_in = 1 + nq + 2 * nv
    if resampled:
        grid = uniform_grid(t_first, t_last, fs)
        n_uniform = grid.shape[0]
        cols = slice(1, width_in)
        stream = (c[:, :width_in] for c in chunks)
        uniform_rows = _resample_windows(
            iter_overlapping(stream, block, SPLINE_MARGIN), cols, t_first, fs, n_uniform, "cubic"
        )
    else:
        n_uniform = n
        uniform_rows = (c[:, :width_in] for c in chunks)
    if n_trim < 0 or 2 * n_trim > n_uniform - 2:
        raise DataError(f"trimming {n_trim} + {n_trim} samples leaves fewer than 2 of {n_uniform}")
    margin = overlap_margin(filt)
    sq, sdq, stau = slice(1, 1 + nq), slice(1 + nq, 1 + nq + nv), slice(1 + nq + nv, width_in)
    stop = n_uniform - n_trim
    D = int(decimate)
    # the filtered columns in one contiguous run: q, dq (when measured, or to reach tau), tau
    # (when filtered); a column filtered but unused costs less than a second filter call
    hi_f = stau.stop if filter_torque else (sdq.stop if velocity == "measured" else sq.stop)
    fq, fdq, ftau = (slice(s.start - sq.start, s.stop - sq.start) for s in (sq, sdq, stau))

    def blocks():
        for w in iter_overlapping(uniform_rows, block, margin):
            lo_keep, hi_keep = max(w.a, n_trim), min(w.b, stop)
            if hi_keep <= lo_keep:
                continue
            rows = w.rows
            t = rows[:, 0]
            # one filter call on every filtered column (each column is filtered on its own)
            y = filt(rows[:, sq.start : hi_f])
            q = y[:, fq]
            dq = derivative(t, q) if velocity == "differentiate" else y[:, fdq]
            tau = y[:, ftau] if filter_torque else rows[:, stau]
            ddq = derivative(t, dq)
            first = lo_keep + (-(lo_keep - n_trim)) % D  # first kept global index >= lo_keep
            idx = np.arange(first, hi_keep, D) - w.lo
            if idx.size:
                yield np.column_stack([t[idx], q[idx], dq[idx], tau[idx], ddq[idx]])

    return settings, blocks()


__all__ = [
    "DEFAULT_BLOCK",
    "DEFAULT_CUTOFF",
    "DEFAULT_ORDER",
    "Lowpass",
    "OverlapWindow",
    "PreprocessSettings",
    "downsample",
    "derivative",
    "filter_regressor",
    "is_uniform",
    "iter_overlapping",
    "lowpass",
    "overlap_margin",
    "preprocess",
    "preprocess_blocks",
    "resample",
    "resample_dataset",
    "sampling_rate",
    "trim_samples",
    "uniform_grid",
]
