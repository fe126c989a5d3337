"""The zero-phase Butterworth low-pass and parallel filtering of a regressor.

See :mod:`manip_id.signals` for the filter's magnitude and why filtering the torques and
the regressor columns with one filter leaves ``theta`` unbiased.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import InputError
from .butterworth import butterworth_poles, butterworth_sos, impulse_response, zero_phase

#: Default cut-off [Hz] of :func:`preprocess` (chosen on the real Panda log, see its docstring).
DEFAULT_CUTOFF = 3.0
#: Default Butterworth order of :func:`preprocess`.
DEFAULT_ORDER = 4


@dataclass(frozen=True)
class Lowpass:
    """A zero-phase Butterworth low-pass filter (forward-backward, second-order sections).

    Attributes
    ----------
    cutoff : float
        cut-off frequency f_c [Hz], 0 < f_c < rate / 2; the forward-backward
        gain there is 1/2.
    rate : float
        sampling rate f_s [Hz].
    order : int
        order n of the one-way Butterworth filter (the forward-backward
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
        """Second-order sections of the one-way filter, shape (ceil(n/2), 6)
        (:func:`~manip_id.signals.butterworth.butterworth_sos`)."""
        return butterworth_sos(self.order, self.cutoff, self.rate)

    @cached_property
    def poles(self) -> np.ndarray:
        """The one-way filter's poles, shape (n,) complex, all inside the unit circle."""
        return butterworth_poles(self.order, self.cutoff, self.rate)[0]

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
        h = np.abs(impulse_response(self.sos, n))
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
        return zero_phase(self.sos, x, axis=axis)


def lowpass(x, cutoff: float, rate: float, order: int = DEFAULT_ORDER, axis: int = 0) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` along ``axis`` (time).

    Parameters
    ----------
    x : array_like
        signal sampled at ``rate``, any shape with time along ``axis``
    cutoff : float
        cut-off frequency [Hz] (forward-backward gain 1/2 there)
    rate : float
        sampling rate [Hz]
    order : int
        Butterworth order of the one-way filter
    """
    return Lowpass(cutoff, rate, order)(x, axis=axis)


def filter_regressor(
    Y: np.ndarray, filt: Lowpass, *, block: int = 16, out: np.ndarray | None = None
) -> np.ndarray:
    """Parallel filtering: the low-pass ``filt`` applied to every column of a regressor, along time.

    Parameters
    ----------
    Y : numpy.ndarray
        stacked regressor, shape (N, nv, p), sample-major (as
        :func:`manip_id.robot.regressor.regressor`
        returns it); time runs along axis 0.
    filt : Lowpass
        the same :class:`Lowpass` applied to the torques (``filt(tau)``).
    block : int
        number of parameter columns filtered at once; bounds the temporaries
        of ``sosfiltfilt`` to O(N * nv * block) besides the output.
    out : numpy.ndarray, optional
        array of Y's shape to write into (may be ``Y`` itself, filtering in place).

    Returns
    -------
    numpy.ndarray
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
