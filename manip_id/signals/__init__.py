"""Signal processing of measured data: resampling, zero-phase low-pass, differentiation.

The path from a raw log to data fit for identification (:func:`preprocess`)::

    raw (t_k non-uniform) --resample--> uniform grid, rate f_s [Hz]
        --low-pass (zero phase)--> q_f, dq_f, tau_f
        --central differences--> ddq = d(dq_f)/dt
        --trim edge transients--> --decimate by D--> Dataset with ddq

Zero-phase low-pass. A Butterworth filter of order ``n`` and cut-off ``f_c``
[Hz], run forward and backward (``scipy.signal.sosfiltfilt``'s conventions,
:mod:`~manip_id.signals.butterworth`), has no phase
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
whole of :func:`preprocess` on them, in memory O(block + margin) whatever N. The
windows are fixed by the block grid alone, so a stream read from
:func:`read_start` (the block holding a wanted row, less ``M``) gives the very
windows of the whole stream from there on: its rows are the whole pass's, bit for
bit (a worker's part of a file; not for a resampled stream, read from its start).

Modules: :mod:`~manip_id.signals.filters` (the low-pass, parallel filtering),
:mod:`~manip_id.signals.butterworth` (its design in closed form and its zero-phase run),
:mod:`~manip_id.signals.sampling` (grids, resampling, differences, decimation, trimming),
:mod:`~manip_id.signals.preprocess` (the in-memory path) and
:mod:`~manip_id.signals.blocks` (the same path in overlapping blocks).
"""

from __future__ import annotations

from .blocks import (
    DEFAULT_BLOCK,
    SPLINE_MARGIN,
    OverlapWindow,
    StreamStats,
    iter_overlapping,
    overlap_margin,
    preprocess_blocks,
    read_start,
)
from .filters import DEFAULT_CUTOFF, DEFAULT_ORDER, Lowpass, filter_regressor, lowpass
from .preprocess import PreprocessSettings, SignalOptions, preprocess
from .sampling import (
    JITTER_TOLERANCE,
    derivative,
    downsample,
    is_uniform,
    resample,
    resample_dataset,
    sampling_rate,
    trim_samples,
    uniform_grid,
)

__all__ = [
    "DEFAULT_BLOCK",
    "DEFAULT_CUTOFF",
    "DEFAULT_ORDER",
    "JITTER_TOLERANCE",
    "SPLINE_MARGIN",
    "Lowpass",
    "OverlapWindow",
    "PreprocessSettings",
    "SignalOptions",
    "StreamStats",
    "downsample",
    "derivative",
    "filter_regressor",
    "is_uniform",
    "iter_overlapping",
    "lowpass",
    "overlap_margin",
    "preprocess",
    "preprocess_blocks",
    "read_start",
    "resample",
    "resample_dataset",
    "sampling_rate",
    "trim_samples",
    "uniform_grid",
]
