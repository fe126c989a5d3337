"""numba kernels of :mod:`manip_id.signals.butterworth` (imported only when numba is installed).

The recursion of a cascade of second-order sections in transposed direct form II, per
sample ``x`` and section ``[b0, b1, b2, 1, a1, a2]`` with state ``(z0, z1)``::

    y = b0 x + z0;   z0 = b1 x - a1 y + z1;   z1 = b2 x - a2 y;   x <- y

(the operations in ``scipy.signal.sosfilt``'s order), on every column of a (L, m) array
at once, rows in time order. Compiled code is cached on disk (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def run_sections(sos, state, w, backward):
    """Filter each column of ``w`` (L, m) in place, rows forward (or ``backward``).

    ``state``: shape (s, 2, m), the sections' states at the first row run (updated).
    """
    L, m = w.shape
    ns = sos.shape[0]
    for t in range(L):
        k = L - 1 - t if backward else t
        for j in range(m):
            x = w[k, j]
            for s in range(ns):
                y = sos[s, 0] * x + state[s, 0, j]
                state[s, 0, j] = sos[s, 1] * x - sos[s, 4] * y + state[s, 1, j]
                state[s, 1, j] = sos[s, 2] * x - sos[s, 5] * y
                x = y
            w[k, j] = x


@numba.njit(cache=True)
def filtfilt(sos, zi, x, edge, out):
    """Forward-backward filter of each column of ``x`` (n, m) into ``out`` (n, m).

    ``zi`` (s, 2): the step's steady state (:func:`~manip_id.signals.butterworth.sosfilt_zi`);
    ``edge``: rows of odd extension at each end (``n > edge``).
    """
    n, m = x.shape
    ns = sos.shape[0]
    w = np.empty((n + 2 * edge, m))
    for k in range(edge):
        for j in range(m):
            w[k, j] = 2.0 * x[0, j] - x[edge - k, j]
            w[edge + n + k, j] = 2.0 * x[n - 1, j] - x[n - 2 - k, j]
    w[edge : edge + n] = x
    state = np.empty((ns, 2, m))
    for s in range(ns):
        for j in range(m):
            state[s, 0, j] = zi[s, 0] * w[0, j]
            state[s, 1, j] = zi[s, 1] * w[0, j]
    run_sections(sos, state, w, False)
    last = w.shape[0] - 1
    for s in range(ns):
        for j in range(m):
            state[s, 0, j] = zi[s, 0] * w[last, j]
            state[s, 1, j] = zi[s, 1] * w[last, j]
    run_sections(sos, state, w, True)
    out[:, :] = w[edge : edge + n]
