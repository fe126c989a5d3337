"""The digital Butterworth low-pass in closed form, and its zero-phase (forward-backward) run.

Design (the same filter as ``scipy.signal.butter(n, f_c, fs=f_s, output="sos")``). The
analog prototype of order ``n`` has its poles on the unit circle's left half,
``s_m = -exp(i pi m / (2 n))`` for ``m = -n+1, -n+3, ..., n-1``, and no zeros. With the
prewarped cut-off ``w_c = 2 f_s tan(pi f_c / f_s)`` [rad/s] scaled onto it (``p = w_c
s_m``, gain ``w_c^n``), the bilinear transform ``z = (2 f_s + p) / (2 f_s - p)`` maps
the poles inside the unit circle, sends the ``n`` zeros at infinity to ``z = -1`` and
multiplies the gain by ``prod 1 / (2 f_s - p)``, so that ``|H(e^{i 2 pi f / f_s})|^2 = 1 /
(1 + (tan(pi f / f_s) / tan(pi f_c / f_s))^(2 n))`` exactly. The sections pair each pole
with its conjugate (an odd order's real pole with a pole at 0), from the poles nearest
the unit circle down, each taking the two zeros nearest it of the n at -1 (and, for an
odd order, one at 0); the cascade runs them in the reverse order, the whole gain on its
first section (scipy's ``zpk2sos`` with ``pairing="nearest"``).

Zero-phase run (``scipy.signal.sosfiltfilt``'s conventions, so the two agree to
round-off): the series is extended at both ends by ``L = 3 (2 s + 1 - z)`` samples
(``s`` sections, ``z`` of them with a zero last coefficient) by odd reflection,
``x[-k] = 2 x[0] - x[k]``; each direction starts from the steady state of a step of the
first sample's height (``sosfilt_zi``: per section ``(I - A) z_i = B``, scaled by the
DC gains of the sections before it); the extension is cut off at the end. The recursion
(transposed direct form II, section by section) runs compiled by numba when numba is
installed, else in ``scipy.signal``.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import note_compile, note_numba_warm, numba_available


def butterworth_poles(order: int, cutoff: float, rate: float) -> tuple[np.ndarray, float]:
    """``(poles, gain)`` of the digital Butterworth low-pass (see the module docstring).

    Parameters
    ----------
    order : int
        Butterworth order n >= 1.
    cutoff : float
        cut-off f_c [Hz], 0 < f_c < rate / 2.
    rate : float
        sampling rate f_s [Hz].

    Returns
    -------
    tuple
        the n digital poles, shape (n,) complex, and the gain ``k`` of ``H(z) = k (z +
        1)^n / prod (z - p)``.
    """
    fs = 2.0  # the frequencies normalized to Nyquist, as scipy does: f_c -> 2 f_c / f_s
    warped = 2.0 * fs * math.tan(math.pi * (2.0 * cutoff / rate) / fs)  # [rad/s]
    m = np.arange(-order + 1, order, 2)
    analog = -np.exp(1j * np.pi * m / (2 * order)) * warped
    poles = (2 * fs + analog) / (2 * fs - analog)
    gain = warped**order * float(np.real(1.0 / np.prod(2 * fs - analog)))
    return poles, gain


def butterworth_sos(order: int, cutoff: float, rate: float) -> np.ndarray:
    """Second-order sections ``[b0, b1, b2, 1, a1, a2]`` of the digital Butterworth low-pass.

    Same parameters as :func:`butterworth_poles`; returns shape (ceil(n / 2), 6), the
    sections ordered by increasing pole radius, the gain on the first one.
    """
    poles, gain = butterworth_poles(order, cutoff, rate)
    sections = [(complex(p), True) for p in poles[poles.imag > 0]]  # one of each pair
    if order % 2:
        sections.append((complex(poles[np.argmin(np.abs(poles.imag))].real), False))
    sections.sort(key=lambda sec: -abs(sec[0]))  # the poles nearest the unit circle first
    zeros = [-1.0] * order + [0.0] * (order % 2)  # an odd order's real pole pairs with z = 0
    rows = []
    for p, pair in sections:
        z1 = _take_nearest(zeros, p)
        z2 = _take_nearest(zeros, p if pair else 0.0)
        a1, a2 = (-2.0 * p.real, p.real**2 + p.imag**2) if pair else (-p.real, 0.0)
        rows.append([1.0, -(z1 + z2), z1 * z2, 1.0, a1, a2])
    sos = np.array(rows[::-1], dtype=float)  # ... and last in the cascade
    sos[0, :3] *= gain
    return sos


def _take_nearest(zeros: list[float], p: complex) -> float:
    """Remove from ``zeros`` the one nearest ``p`` (the first of equals) and return it."""
    i = min(range(len(zeros)), key=lambda k: abs(p - zeros[k]))
    return zeros.pop(i)


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """Initial states, shape (s, 2), of a unit step's steady state through the sections.

    Per section ``b, a`` of the transposed direct form II, ``z = (I - A)^-1 (b[1:] -
    a[1:] b0)`` with ``A`` the transposed companion matrix of ``a``, scaled by the DC
    gain ``sum b / sum a`` of the sections before it (as ``scipy.signal.sosfilt_zi``).
    """
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for s, section in enumerate(sos):
        b, a = section[:3], section[3:]
        i_minus_a = np.array([[1.0 + a[1], -1.0], [a[2], 1.0]])  # I - companion(a)^T
        zi[s] = scale * np.linalg.solve(i_minus_a, b[1:] - a[1:] * b[0])
        scale *= b.sum() / a.sum()
    return zi


def pad_length(sos: np.ndarray) -> int:
    """The odd extension's length at each end, ``3 (2 s + 1 - z)`` samples (module docstring)."""
    zero_last = min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return 3 * (2 * sos.shape[0] + 1 - zero_last)


def load_kernels() -> bool:
    """Load the compiled filter now (numba imported, its code read from the cache), not at
    the first filtering; whether it is compiled (numba installed).

    A reader of a long log calls it before the rows are read: numba's code generation
    (about 60 MB) then takes its memory before the read's transients are freed rather
    than on top of what they leave (10^6 ur10 rows audited: peak 437 -> 401 MB)."""
    if not numba_available():
        return False
    sos = butterworth_sos(2, 0.1, 1.0)
    zero_phase(sos, np.zeros((pad_length(sos) + 1, 1)))
    impulse_response(sos, 2)
    return True


def impulse_response(sos: np.ndarray, n: int) -> np.ndarray:
    """The one-way filter's first ``n`` samples of impulse response, shape (n,)."""
    x = np.zeros((n, 1))
    x[0] = 1.0
    if numba_available():
        from ._filter_kernel import run_sections  # numba kernels (optional heavy library)

        note_compile(run_sections)
        run_sections(sos, np.zeros((sos.shape[0], 2, 1)), x, False)
        note_numba_warm()
        return x[:, 0]
    import scipy.signal as _signal  # heavy (0.4 s): the fallback without numba

    return _signal.sosfilt(sos, x[:, 0])


def zero_phase(sos: np.ndarray, x: np.ndarray, axis: int = 0) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, x, axis=axis)`` (odd padding); a new array.

    ``x`` must have more than :func:`pad_length` samples along ``axis``.
    """
    if not numba_available():
        import scipy.signal as _signal  # heavy (0.4 s): the fallback without numba

        return _signal.sosfiltfilt(sos, x, axis=axis)
    from ._filter_kernel import filtfilt  # numba kernels (optional heavy library)

    note_compile(filtfilt)

    moved = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    flat = np.ascontiguousarray(moved.reshape(moved.shape[0], -1))
    out = np.empty_like(flat)
    filtfilt(sos, sosfilt_zi(sos), flat, pad_length(sos), out)
    note_numba_warm()
    return np.moveaxis(out.reshape(moved.shape), 0, axis)
